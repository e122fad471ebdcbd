#!/usr/bin/env bash
# Fuzz campaigns (RELIABILITY.md): every cargo-fuzz target for RUNS executions
# (default 10 million) or MAX_TIME seconds if that comes first (default 0: no limit),
# JOBS targets at a time (default 2), each on its whole committed corpus, which the
# campaign grows. Prints a Markdown table row per target: executions, seconds,
# executions per second, crashes, corpus inputs before and after. Crash inputs land
# in fuzz/artifacts/<target>/.
#
# A target's corpus is in two parts (fuzz-targets/tests/corpora.rs replays both on
# stable): the seed folder fuzz/corpus/<target>/, plain files, at most SEEDS inputs
# picked on coverage by cmin's merge (pack_one below), and the archive
# fuzz/corpus/<target>.tar.gz, every other input ever kept. A campaign unpacks the
# archive into the folder, fuzzes, then packs: the seeds are picked again out of
# everything, the rest goes back into the archive. No input is dropped.
#
#   bash scripts/lab/fuzz-campaign.sh [TARGET...]          # a campaign; all targets when none is named
#   bash scripts/lab/fuzz-campaign.sh unpack [TARGET...]   # the archive's inputs into the folder
#   bash scripts/lab/fuzz-campaign.sh pack [TARGET...]     # cmin picks the seeds, the rest into the archive
#
# unpack then `cargo +nightly fuzz run <target>` then pack is a campaign by hand. The
# archives are deterministic (sorted names, no times or owners): packing the same
# inputs gives the same bytes, so git sees a change only when the inputs change.
#
# Needs the nightly toolchain and cargo-fuzz (installed here when missing) for a
# campaign and for pack; the README's test command does not: it replays the corpora on
# stable.
set -euo pipefail
# The repository's root, wherever under it this script lives.
cd "$(dirname "$0")"
while [[ ! -f fuzz/Cargo.toml ]]; do
    [[ $PWD != / ]] || { echo "fuzz-campaign.sh: no fuzz/Cargo.toml above $0" >&2; exit 1; }
    cd ..
done
source scripts/env.sh

RUNS=${RUNS:-10000000}
MAX_TIME=${MAX_TIME:-0}
JOBS=${JOBS:-2}
# No sanitizer (the workspace denies unsafe code; libFuzzer still finds panics,
# overflows with debug assertions on, hangs and out-of-memory), for throughput.
FLAGS=(--sanitizer none --debug-assertions --release)
# The seed folder: at most SEEDS inputs (default 32) per target, picked on the edges
# each input covers (cmin's control file), not their hit counts (pack_one below).
SEEDS=${SEEDS:-32}
BIN=fuzz/target/x86_64-unknown-linux-gnu/release
CMIN_ARGS=(-set_cover_merge=1 -use_counters=0 -rss_limit_mb=2048 -timeout=10)

mode=campaign
if [[ ${1:-} == unpack || ${1:-} == pack ]]; then
    mode=$1
    shift
fi

need_fuzz() {
    if ! cargo +nightly --version >/dev/null 2>&1; then
        rustup toolchain install nightly --profile minimal
    fi
    if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
        cargo install cargo-fuzz --version '^0.13' --locked
    fi
}

if [[ $# -gt 0 ]]; then
    targets=("$@")
else
    # The targets are the [[bin]]s of fuzz/Cargo.toml (cargo fuzz list needs nightly).
    mapfile -t targets < <(sed -n 's/^name = "\(.*\)"$/\1/p' fuzz/Cargo.toml | grep -vx ugv-fuzz)
fi

count() { find "$1" -maxdepth 1 -type f | wc -l; }

# The archive's inputs into the seed folder (the two are disjoint, so nothing is
# overwritten); a target without an archive yet has nothing to unpack.
unpack_one() {
    local t=$1
    mkdir -p "fuzz/corpus/$t"
    if [[ -f fuzz/corpus/$t.tar.gz ]]; then
        tar -xzf "fuzz/corpus/$t.tar.gz" -C "fuzz/corpus/$t"
    fi
}

# Everything (the folder and the archive, so packing a folder that was never unpacked
# loses nothing) goes through cmin, whose control file gives each input's edges; the
# seed folder becomes the SEEDS inputs a greedy set cover picks first out of all (each
# the one adding most edges not yet covered, ties to the smaller input, then the name;
# fewer when nothing adds an edge); every input whose content is not a seed's goes
# into the archive, written anew. Nothing is removed before the new archive is in
# place: a failure loses no input.
pack_one() {
    local t=$1 dir=fuzz/corpus/$1 all work keep picks
    all=$(mktemp -d)
    work=$(mktemp -d)
    cp -a "$dir/." "$all/"
    if [[ -f $dir.tar.gz ]]; then
        tar -xzf "$dir.tar.gz" -C "$all"
    fi
    # cmin's merge, by the fuzzer binary that `cargo fuzz build` made (as `cargo fuzz
    # cmin` runs it, without a build of its own), into a scratch folder.
    mkdir "$work/out"
    "$BIN/$t" -merge=1 "${CMIN_ARGS[@]}" -merge_control_file="$work.ctl" "$work/out" "$all" \
        >"$work.log" 2>&1 || { echo "$t: cmin failed, see $work.log; no input moved" >&2; return 1; }
    picks=$(mktemp)
    python3 - "$work.ctl" "$SEEDS" >"$picks" <<'PY'
import os, sys
lines = open(sys.argv[1]).read().split("\n")
n = int(lines[0])
paths = lines[2 : 2 + n]
size, edges = {}, {}
for line in lines[2 + n :]:
    words = line.split()
    if words[:1] == ["STARTED"]:
        size[int(words[1])] = int(words[2])
    elif words[:1] == ["FT"]:
        edges[int(words[1])] = set(map(int, words[2:]))
covered, picked = set(), []
left = set(edges)
while left and len(picked) < int(sys.argv[2]):
    best = min(left, key=lambda i: (-len(edges[i] - covered), size[i], paths[i]))
    if not edges[best] - covered:
        break
    picked.append(best)
    covered |= edges[best]
    left.discard(best)
every = set().union(*edges.values()) if edges else set()
print(f"{len(picked)} seeds cover {len(covered)} of the {len(every)} edges of {len(edges)} inputs", file=sys.stderr)
for i in picked:
    print(os.path.basename(paths[i]))
PY
    # The archive: every input of `all` whose content is not a seed's.
    local -A seed=()
    local sum f
    while IFS= read -r f; do
        seed[$(sha1sum <"$all/$f" | cut -c1-40)]=1
    done <"$picks"
    keep=$(mktemp)
    while read -r sum f; do
        [[ -n ${seed[$sum]:-} ]] || printf '%s\n' "${f#./}"
    done < <(cd "$all" && find . -maxdepth 1 -type f -exec sha1sum {} +) | LC_ALL=C sort >"$keep"
    tar -C "$all" --sort=name --owner=0 --group=0 --numeric-owner --mtime=@0 --mode=0644 \
        --format=gnu -cf - --verbatim-files-from -T "$keep" | gzip -9n >"$dir.tar.gz.new"
    mv "$dir.tar.gz.new" "$dir.tar.gz"
    find "$dir" -maxdepth 1 -type f -delete
    while IFS= read -r f; do cp -a "$all/$f" "$dir/"; done <"$picks"
    echo "$t: $(count "$dir") seeds in $dir, $(wc -l <"$keep") inputs in $dir.tar.gz" >&2
    rm -rf "$all" "$work" "$work.ctl" "$work.log" "$keep" "$picks"
}

case $mode in
unpack)
    for t in "${targets[@]}"; do unpack_one "$t"; done
    exit 0
    ;;
pack)
    # BUILD=0: with the fuzzer binaries of the last build as they are.
    if [[ ${BUILD:-1} != 0 ]]; then
        need_fuzz
        cargo +nightly fuzz build --fuzz-dir fuzz "${FLAGS[@]}" >/dev/null
    fi
    for t in "${targets[@]}"; do pack_one "$t"; done
    exit 0
    ;;
esac

need_fuzz
cargo +nightly fuzz build --fuzz-dir fuzz "${FLAGS[@]}" >/dev/null

logs=$(mktemp -d)
run_one() {
    local t=$1 before after start end crashes execs
    unpack_one "$t"
    before=$(count "fuzz/corpus/$t")
    start=$(date +%s)
    # -rss_limit_mb and -timeout: an input that takes 2 GiB or 10 s is a finding.
    cargo +nightly fuzz run --fuzz-dir fuzz "${FLAGS[@]}" "$t" -- \
        -runs="$RUNS" -max_total_time="$MAX_TIME" -print_final_stats=1 -rss_limit_mb=2048 -timeout=10 \
        >"$logs/$t.log" 2>&1 || true
    end=$(date +%s)
    after=$(count "fuzz/corpus/$t")
    pack_one "$t" 2>>"$logs/$t.log"
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$logs/$t.log" | grep -o '[0-9]*$' | tail -1)
    crashes=$(find "fuzz/artifacts/$t" -type f 2>/dev/null | wc -l)
    printf '| %s | %s | %s | %s | %s | %s -> %s |\n' "$t" "${execs:-0}" "$((end - start))" \
        "$(( ${execs:-0} / (end - start > 0 ? end - start : 1) ))" "$crashes" "$before" "$after"
}

echo "| target | executions | seconds | exec/s | crashes | corpus inputs |"
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
