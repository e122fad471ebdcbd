#!/usr/bin/env bash
# The paper's scenario in HIL (release ugv-sim with the release controller on vcan0)
# TRIALS times, at real-time priority PRIORITY (0: ordinary scheduling) for the
# simulator's tick loop and the controller's command loop; a line per trial (passed,
# outcome, tick lateness p99 and max, the controller's skipped ticks) and the pass
# count. Where the kernel has no CAN, run it through the VM, with a CPU hog on the
# host to measure it under load (README, "Real time on a busy machine"):
#
#   target/debug/vcan-setup vm [--host-nice N] -- bash scripts/lab/hil-trials.sh [TRIALS] [PRIORITY]
#
# Results under target/hil-trials/<priority>-<trial>/.
set -uo pipefail
cd "$(dirname "$0")/../.."

trials=${1:-10}
priority=${2:-40}
bin=${UGV_BIN_DIR:-target/release}
passed=0
for i in $(seq 1 "$trials"); do
    out=target/hil-trials/$priority-$i
    rm -rf "$out"
    mkdir -p "$out"
    "$bin/ugv-sim" run --can vcan0 --controller "$bin/ugv-controller" \
        --controller-arg=--rt-priority --controller-arg="$priority" \
        --rt-priority "$priority" --run-id "trial-$priority-$i" \
        --gps-link "/tmp/ugv-trial-gps-$i" --results "$out" --status-every 5 \
        >"$out/verdict.out" 2>"$out/stderr.log"
    code=$?
    line=$(python3 - "$out" "$code" <<'EOF'
import json, re, sys
out, code = sys.argv[1], sys.argv[2]
try:
    v = json.load(open(f"{out}/verdict.json"))
except Exception as e:
    print(f"exit {code}, no verdict ({e})")
    sys.exit()
lat = v.get("tick_lateness") or {}
log = open(f"{out}/stderr.log", errors="replace").read()
skipped = re.findall(r"ticks skipped late (\d+)", log)
print(f"exit {code} passed={v['passed']} outcome={v['outcome']} "
      f"lateness p99={lat.get('p99_ms', float('nan')):.1f} ms max={lat.get('max_ms', float('nan')):.1f} ms "
      f"controller skipped={skipped[-1] if skipped else '?'} failures={v.get('failures')}")
EOF
)
    echo "trial $i (priority $priority): $line"
    [[ $code -eq 0 ]] && passed=$((passed + 1))
done
echo "priority $priority: $passed of $trials passed"
