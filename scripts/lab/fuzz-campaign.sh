#!/usr/bin/env bash
# Fuzz campaigns (RELIABILITY.md): every cargo-fuzz target for RUNS executions
# (default 10 million) or MAX_TIME seconds if that comes first (default 0: no limit),
# JOBS targets at a time (default 2), each on its committed
# corpus (fuzz/corpus/<target>/), which the campaign grows; the corpus is minimised
# afterwards (cargo fuzz cmin) so the stable replay test stays quick. Prints a
# Markdown table row per target: executions, seconds, executions per second, crashes,
# corpus files before and after. Crash inputs land in fuzz/artifacts/<target>/.
#
#   bash scripts/lab/fuzz-campaign.sh [TARGET...]     # all targets when none is named
#
# Needs the nightly toolchain and cargo-fuzz (installed here when missing); the
# README's test command does not: it replays the corpora on stable.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/env.sh

RUNS=${RUNS:-10000000}
MAX_TIME=${MAX_TIME:-0}
JOBS=${JOBS:-2}
# No sanitizer (the workspace denies unsafe code; libFuzzer still finds panics,
# overflows with debug assertions on, hangs and out-of-memory), for throughput.
FLAGS=(--sanitizer none --debug-assertions --release)

if ! cargo +nightly --version >/dev/null 2>&1; then
    rustup toolchain install nightly --profile minimal
fi
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
    cargo install cargo-fuzz --version '^0.13' --locked
fi

if [[ $# -gt 0 ]]; then
    targets=("$@")
else
    mapfile -t targets < <(cargo +nightly fuzz list --fuzz-dir fuzz)
fi

cargo +nightly fuzz build --fuzz-dir fuzz "${FLAGS[@]}" >/dev/null

logs=$(mktemp -d)
run_one() {
    local t=$1 before after start end crashes execs
    before=$(find "fuzz/corpus/$t" -type f | wc -l)
    start=$(date +%s)
    # -rss_limit_mb and -timeout: an input that takes 2 GiB or 10 s is a finding.
    cargo +nightly fuzz run --fuzz-dir fuzz "${FLAGS[@]}" "$t" -- \
        -runs="$RUNS" -max_total_time="$MAX_TIME" -print_final_stats=1 -rss_limit_mb=2048 -timeout=10 \
        >"$logs/$t.log" 2>&1 || true
    end=$(date +%s)
    cargo +nightly fuzz cmin --fuzz-dir fuzz "${FLAGS[@]}" "$t" >/dev/null 2>&1 || true
    after=$(find "fuzz/corpus/$t" -type f | wc -l)
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$logs/$t.log" | grep -o '[0-9]*$' | tail -1)
    crashes=$(find "fuzz/artifacts/$t" -type f 2>/dev/null | wc -l)
    printf '| %s | %s | %s | %s | %s | %s -> %s |\n' "$t" "${execs:-0}" "$((end - start))" \
        "$(( ${execs:-0} / (end - start > 0 ? end - start : 1) ))" "$crashes" "$before" "$after"
}

echo "| target | executions | seconds | exec/s | crashes | corpus files |"
echo "|---|---|---|---|---|---|"
running=0
for t in "${targets[@]}"; do
    run_one "$t" &
    running=$((running + 1))
    if [[ $running -ge $JOBS ]]; then
        wait -n
        running=$((running - 1))
    fi
done
wait
echo "logs: $logs"
