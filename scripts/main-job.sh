#!/usr/bin/env bash
# The main job on a host where vcan0 is up (run it through scripts/run.sh): the seed
# paper's scenario end to end in HIL. ugv-sim simulates the golf car, its RTK GPS
# (NMEA on a pty), its laser scanner (frames over iceoryx2) and its steering and
# throttle ECUs (SocketCAN vcan0, golf_car.dbc); the real ugv-controller binary runs
# as a separate process on those wires, recording its own ports (results/paper-hil/
# controller, which `ugv-sim replay` replays byte for byte). The verdict and the figure
# go to results/.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release
out=results/paper-hil
mkdir -p "$out"

set +e
"$bin/ugv-sim" run --controller "$bin/ugv-controller" --controller-log --results "$out" --status-every 2 >"$out/stdout.json"
code=$?
set -e
echo "== verdict ($out/verdict.json, figure $out/figure.png)"
python3 - "$out/verdict.json" <<'PY'
import json, sys
v = json.load(open(sys.argv[1]))
c = v.get("controller") or {}
print(f"passed={v['passed']} goal_reached={v['goal_reached']} collision={v['collision']} "
      f"time={v['time']:.2f}s path={v['path_length']:.2f}m "
      f"min_clearance={min(v['min_clearance']):.2f}m max_steer={v['max_steer_deg']:.1f}deg "
      f"tracking_rms={c.get('tracking_error_rms', float('nan')):.3f}m "
      f"rejected_frames={sum(n for k, n in v['steering_can']['e2e'].items() if k != 'accepted') + sum(n for k, n in v['throttle_can']['e2e'].items() if k != 'accepted')}")
if v["failures"]:
    print("failures:", "; ".join(v["failures"]))
PY
exit "$code"
