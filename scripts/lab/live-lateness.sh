#!/usr/bin/env bash
# The live view's cost in HIL (issue 13): the paper's HIL run twice, without `--live`
# and with it and a Foxglove WebSocket client (sim/tests/live_client.py) subscribed to
# the laser for the whole drive; the simulator's tick lateness (p50, p99, max) of both,
# and the scans the client received against the laser's 50 Hz. Needs vcan0, so run it
# where the tests' vcan runs (natively, or in the VM):
#
#   target/debug/vcan-setup vm -- bash scripts/lab/live-lateness.sh
#
# Uses the release binaries ($UGV_BIN_DIR, default target/release); leaves both runs
# (verdicts, recordings) and the client's report in results/live-lateness/. CLIENT_NICE
# runs the client at that niceness (default 0), CLIENT_WINDOW its count over that many
# seconds (default 8: the drive lasts about 20).
set -euo pipefail
cd "$(dirname "$0")/../.."
bin=${UGV_BIN_DIR:-$PWD/target/release}
out=results/live-lateness
rm -rf "$out"
mkdir -p "$out"
run() {
    local name=$1
    shift
    "$bin/ugv-sim" run --controller "$bin/ugv-controller" --results "$out/$name" \
        --run-id "live-$name-$$" "$@" >"$out/$name.verdict" 2>"$out/$name.log" || true
}
run off
nice -n "${CLIENT_NICE:-0}" python3 sim/tests/live_client.py ws://127.0.0.1:8765 --window "${CLIENT_WINDOW:-8}" --connect-timeout 60 \
    >"$out/client.json" 2>"$out/client.log" &
client=$!
run on --live 127.0.0.1:8765
wait "$client" || echo "the client exited $?" >>"$out/client.log"
python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
for name in ("off", "on"):
    v = json.load(open(f"{out}/{name}/verdict.json"))
    t = v["tick_lateness"]
    print(f"--live {name}: passed {v['passed']}, goal {v['goal_reached']}, tick lateness "
          f"p50 {t['p50_ms']:.2f} ms, p99 {t['p99_ms']:.2f} ms, max {t['max_ms']:.1f} ms "
          f"({t['samples']} ticks)")
try:
    c = json.load(open(f"{out}/client.json"))
    print(f"client: {c['count']} {c['topic']} messages in {c['window_s']:.1f} s "
          f"= {c['count'] / c['window_s']:.1f}/s over the Foxglove WebSocket protocol")
except Exception as e:
    print(f"client: no report ({e}); see {out}/client.log")
PY
