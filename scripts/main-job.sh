#!/usr/bin/env bash
# The main job on a host where vcan0 is up (run it through scripts/run.sh).
#
# Until the simulator and the controller exist, this is the closest real thing: the
# golf car's CAN contract on vcan0. A controller-side sequence (heartbeat, steering and
# throttle commands, encoded by ugv-can with counter and CRC) goes out with cansend,
# candump records the bus, ugv-can decodes and E2E-checks the recording, and one
# replayed and one corrupted frame are injected to show them rejected.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release
out=results
mkdir -p "$out"

candump -L vcan0 >"$out/bus.log" &
dump=$!
sleep 0.5

for i in $(seq 0 49); do
    c=$((i % 16))
    angle=$(awk -v i="$i" 'BEGIN { printf "%.2f", 20 * sin(i / 8) }')
    cansend vcan0 "$("$bin/ugv-can" encode CONTROLLER_HEARTBEAT State=auto --counter "$c")"
    cansend vcan0 "$("$bin/ugv-can" encode STEERING_CMD Enable=1 TargetAngle="$angle" MaxRate=60 --counter "$c")"
    cansend vcan0 "$("$bin/ugv-can" encode THROTTLE_CMD Enable=1 Gear=forward TargetSpeed=2.5 AccelLimit=1 --counter "$c")"
done
# A replayed frame (counter 1 again) and a corrupted one (CRC byte flipped).
cansend vcan0 "$("$bin/ugv-can" encode STEERING_CMD Enable=1 --counter 1)"
good=$("$bin/ugv-can" encode THROTTLE_CMD Enable=0 Brake=100 --counter 3)
cansend vcan0 "${good%??}$(printf '%02X' $(( 0x${good: -2} ^ 0xFF )))"
sleep 0.5
kill "$dump"
wait "$dump" 2>/dev/null || true

"$bin/ugv-can" decode "$out/bus.log" >"$out/bus-decoded.txt" 2>"$out/bus-summary.txt" || true
"$bin/ugv-can" decode --json "$out/bus.log" >"$out/bus-decoded.jsonl" 2>/dev/null || true
echo "== last decoded frames ($out/bus-decoded.txt)"
tail -n 4 "$out/bus-decoded.txt"
echo "== summary"
cat "$out/bus-summary.txt"
grep -q "152 frames, 2 rejected by E2E, 0 malformed lines" "$out/bus-summary.txt"
