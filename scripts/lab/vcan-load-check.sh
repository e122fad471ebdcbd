#!/usr/bin/env bash
# The vcan group's pass rate under load (issue 16, item 6): every host core taken by a
# CPU hog (one busy loop per core, at ordinary priority), the vcan group run RUNS times
# in a row inside one `vcan-setup vm` boot, as the README's test command runs it (two
# retries per test, .config/nextest.toml). Per run: the tests passed at the first try,
# passed on a retry (FLAKY), failed, and the frames the guest's input backlog dropped
# (runs.txt). Everything is left in results/vcan-load/.
#
#   bash scripts/lab/vcan-load-check.sh [RUNS] [HOST_NICE] [HOG] [HOST_RT]
#
# RUNS defaults to 10; HOST_NICE (QEMU's niceness on the host, vcan-setup vm
# --host-nice) to its default -10; HOG=0 runs without the hog, for the comparison;
# HOST_RT (QEMU's SCHED_RR priority on the host, vcan-setup vm --host-rt) to its
# default 10, 0 for none (QEMU then competes with the hog by its niceness alone).
# Needs the release binaries (cargo build --workspace --release) and the test
# binaries built (cargo nextest run --no-run), so the guest compiles nothing.
set -euo pipefail
cd "$(dirname "$0")/../.."
out=results/vcan-load

if [ "${1:-}" = --in-vm ]; then
    runs=$2
    for i in $(seq 1 "$runs"); do
        start=$(date +%s)
        # Frames the guest's input backlog dropped (softnet_stat's second column, hex).
        drops() {
            local s=0 _ d _rest
            while read -r _ d _rest; do s=$((s + 16#$d)); done </proc/net/softnet_stat
            echo "$s"
        }
        before=$(drops)
        cargo nextest run --workspace --locked --no-fail-fast -E 'group(vcan)' \
            >"$out/run-$i.log" 2>&1 || true
        echo "run $i: $(($(date +%s) - start)) s, input backlog drops $(($(drops) - before)), $(grep -E '^ +Summary' "$out/run-$i.log" | tail -1)"
    done
    exit 0
fi

runs=${1:-10}
host_nice=${2:--10}
hog=${3:-1}
host_rt=${4:-10}
export UGV_BIN_DIR=${UGV_BIN_DIR:-$PWD/target/release}
# What the group needs from the host, checked before a series of hours: a missing piece
# would fail the same tests in every run.
missing=()
for bin in ugv-sim ugv-controller; do
    [ -x "$UGV_BIN_DIR/$bin" ] || missing+=("$UGV_BIN_DIR/$bin (cargo build --workspace --release)")
done
[ -x target/debug/vcan-setup ] || missing+=("target/debug/vcan-setup (cargo nextest run --workspace --locked --no-run)")
[ -x examples/python/.venv/bin/python ] ||
    missing+=("examples/python/.venv, the Python example's venv (bash scripts/install-deps.sh)")
if [ ${#missing[@]} -gt 0 ]; then
    printf 'vcan-load-check: missing %s\n' "${missing[@]}" >&2
    exit 2
fi
rm -rf "$out"
mkdir -p "$out"
if [ "$hog" != 0 ]; then
    for _ in $(seq 1 "$(nproc)"); do
        bash -c 'while :; do :; done' &
        echo $! >>"$out/hog.pids"
    done
    trap 'xargs kill <"$out/hog.pids" 2>/dev/null || true' EXIT
fi
echo "vcan group x $runs, hog on $(nproc) cores: $hog, QEMU niceness $host_nice, SCHED_RR $host_rt" | tee "$out/setup.txt"
target/debug/vcan-setup vm --host-nice "$host_nice" --host-rt "$host_rt" -- bash scripts/lab/vcan-load-check.sh --in-vm "$runs" |
    tee "$out/runs.txt"
python3 - "$out" "$runs" <<'EOF'
import re, sys, pathlib
out, runs = pathlib.Path(sys.argv[1]), int(sys.argv[2])
clean = 0
for i in range(1, runs + 1):
    log = out / f"run-{i}.log"
    text = log.read_text(errors="replace") if log.exists() else ""
    m = re.findall(r"Summary \[ *([\d.]+)s\] (\d+) tests? run: (\d+) passed(?: \((?:\d+ slow, )?(\d+) flaky\))?(?:, (\d+) failed)?", text)
    if not m:
        print(f"run {i}: no summary (see {log})")
        continue
    secs, total, passed, flaky, failed = m[-1]
    flaky, failed = int(flaky or 0), int(failed or 0)
    first = int(passed) - flaky
    flaky_names = re.findall(r"FLAKY \d+/\d+ \[.*?\] +\(.*?\) +\S+ (\S+)", text)
    failed_names = sorted(set(re.findall(r"^ +FAIL \[.*?\] +\(.*?\) +\S+ (\S+)", text, re.M)))
    ok = failed == 0
    clean += ok
    print(f"run {i}: {'passed' if ok else 'FAILED'} in {float(secs):.0f} s; {total} tests: "
          f"{first} at the first try, {flaky} on a retry {flaky_names}, {failed} failed {failed_names}")
print(f"{clean} of {runs} runs passed")
EOF
