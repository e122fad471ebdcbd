#!/usr/bin/env bash
# The bus load of the paper's HIL run, ours (the verdict's bus_load, every frame at its
# worst-case bit stuffing) against can-utils' canbusload on the same traffic. Needs
# vcan0, so run it where the tests' vcan runs (natively, or in the VM):
#
#   target/debug/vcan-setup vm -- bash scripts/lab/busload-check.sh
#
# Uses the release binaries ($UGV_BIN_DIR, default target/release). canbusload prints
# one line a second per interface: frames, bits with stuffing, payload bits, load %;
# it runs three times side by side: worst-case stuffing (its default), exact stuffing
# (-e) and none (-i). Prints the per-second series and both means over the seconds the
# controller drove (frames seen), and leaves everything in results/busload-check/.
set -euo pipefail
cd "$(dirname "$0")/../.."
bin=${UGV_BIN_DIR:-$PWD/target/release}
out=results/busload-check
rm -rf "$out"
mkdir -p "$out"
for mode in worst exact none; do
    flag=()
    [ "$mode" = exact ] && flag=(-e)
    [ "$mode" = none ] && flag=(-i)
    # -t: a time line before each second's report; the line per interface follows.
    stdbuf -oL canbusload -t "${flag[@]}" vcan0@500000 >"$out/canbusload-$mode.txt" 2>&1 &
    echo $! >>"$out/pids"
done
"$bin/ugv-sim" run --controller "$bin/ugv-controller" --results "$out/run" --no-record \
    >"$out/verdict.stdout" 2>"$out/run.log" || true
sleep 1.5
xargs kill <"$out/pids" 2>/dev/null || true
wait 2>/dev/null || true
python3 - "$out" <<'EOF'
import json, re, sys
out = sys.argv[1]
verdict = json.load(open(f"{out}/run/verdict.json"))
ours = verdict["bus_load"]
print(f"ugv-sim verdict: {ours['frames']} frames, mean {ours['mean_pct']:.1f} %, "
      f"peak {ours['peak_pct']:.1f} % (100 ms window), worst-case stuffing")
for mode in ("worst", "exact", "none"):
    loads, frames = [], []
    for line in open(f"{out}/canbusload-{mode}.txt", encoding="utf-8", errors="replace"):
        m = re.match(r"\s*vcan0@500000\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)%", line)
        if m and int(m.group(1)) > 0:
            frames.append(int(m.group(1)))
            loads.append(int(m.group(4)))
    if not loads:
        print(f"canbusload ({mode}): no busy second recorded")
        continue
    # The busy seconds' own mean, and the load those frames make over the verdict's run.
    bits = sum(int(x) for x in re.findall(r"vcan0@500000\s+\d+\s+(\d+)", open(f"{out}/canbusload-{mode}.txt").read()))
    print(f"canbusload ({mode} stuffing): {sum(frames)} frames over {len(loads)} busy seconds, "
          f"mean {sum(loads)/len(loads):.1f} %, max {max(loads)} %, "
          f"{bits / 500000 / verdict['time'] * 100:.1f} % over the run's {verdict['time']:.1f} s")
EOF
