#!/usr/bin/env bash
# The comparison study the seed paper could not finish: the optimal control law against
# ANFIS across the whole scenario suite, in SIL, nominal and under disturbances that
# the replanning cannot hide (it restarts every path at the car every 0.5 s, so only
# errors that build up within a replanning period, or that push the car where the
# path did not go, show): a steering-sensor bias, extra steering dead time, a slow
# speed loop and white GPS noise. ANFIS is trained offline (hybrid learning, Jang 1993)
# on nominal runs of the optimal follower, then both followers run every condition.
# Writes results/comparison/ and the committed report docs/comparison.md with figures
# in docs/comparison/ (matplotlib). Uses $CARGO_TARGET_DIR when set. Every scenario runs
# with $SEEDS seeds (default 20; `ugv-sim suite --seeds`), so success rates come with
# their 95 % Wilson intervals.
set -euo pipefail
seeds=${SEEDS:-20}
cd "$(dirname "$0")/../.."
# The report's figures need matplotlib (not needed by the tests, so installed here).
python3 -c 'import matplotlib' 2>/dev/null || python3 -m pip install --quiet 'matplotlib==3.11.2'
# The workspace, not -p: another feature set would rebuild what the tests build.
cargo build --release --locked --workspace --bins
bin="${CARGO_TARGET_DIR:-target}/release"
out=results/comparison
rm -rf "$out"
mkdir -p "$out" docs/comparison

# 1. Record the optimal follower on three scenarios and join the training data.
for sc in 01-paper 02-two-posts 03-box; do
    "$bin/ugv-sim" run --sil "sim/scenarios/suite/$sc.toml" --results "$out/record/$sc" >/dev/null
done
{ head -n 1 "$out/record/01-paper/training.csv"; for f in "$out"/record/*/training.csv; do tail -n +2 "$f"; done; } >"$out/training.csv"

# 2. Train ANFIS: inputs lateral error, heading error, the path's steering angle.
"$bin/ugv-controller" anfis train --data "$out/training.csv" --inputs e_y,e_theta,phi_ref \
    --target steer_cmd --mfs 2 --epochs 30 --output "$out/anfis.json" >"$out/anfis-training.json"

# 3. The conditions: copies of the suite with the disturbance written into each file.
python3 scripts/lab/comparison-report.py conditions sim/scenarios/suite "$out/scenarios"

# 4. Both followers across the suite in every condition (exit codes 1 and 5 mean a
#    failed scenario: reported, not fatal).
for cond in $(ls "$out/scenarios"); do
    "$bin/ugv-sim" suite "$out/scenarios/$cond" --seeds "$seeds" --results "$out/$cond/optimal" >/dev/null 2>&1 || true
    "$bin/ugv-sim" suite "$out/scenarios/$cond" --seeds "$seeds" --results "$out/$cond/anfis" \
        --follower anfis --anfis-model "$out/anfis.json" >/dev/null 2>&1 || true
done

# 5. The paper's scenario with the steering bias, each follower, for the figures.
for f in optimal anfis; do
    args=()
    [ "$f" = anfis ] && args=(--follower anfis --anfis-model "$out/anfis.json")
    "$bin/ugv-sim" run --sil "$out/scenarios/steer-bias/01-paper.toml" "${args[@]}" \
        --results "$out/paper-bias-$f" >/dev/null || true
    cp "$out/paper-bias-$f/figure.png" "docs/comparison/paper-bias-$f.png"
done

python3 scripts/lab/comparison-report.py report "$out" docs/comparison >docs/comparison.md
echo "report: docs/comparison.md"
