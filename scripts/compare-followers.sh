#!/usr/bin/env bash
# The comparison study the seed paper could not finish: the optimal control law against
# ANFIS across the scenario suite, in SIL. ANFIS is trained offline (hybrid learning,
# Jang 1993) on runs recorded with the optimal follower, then both run the whole suite.
# Writes results/comparison/ and the committed report docs/comparison.md with figures.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --workspace --release --locked
bin=target/release
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

# 3. Both followers across the suite (exit code 1 means a failed scenario: reported).
"$bin/ugv-sim" suite sim/scenarios/suite --results "$out/optimal" >/dev/null || true
"$bin/ugv-sim" suite sim/scenarios/suite --results "$out/anfis" --follower anfis --anfis-model "$out/anfis.json" >/dev/null || true

# 4. The paper's scenario with each follower, for the figures.
"$bin/ugv-sim" run --sil --results "$out/paper-optimal" >/dev/null || true
"$bin/ugv-sim" run --sil --follower anfis --anfis-model "$out/anfis.json" --results "$out/paper-anfis" >/dev/null || true
cp "$out/paper-optimal/figure.png" docs/comparison/paper-optimal.png
cp "$out/paper-anfis/figure.png" docs/comparison/paper-anfis.png

python3 scripts/comparison-report.py "$out" >docs/comparison.md
echo "report: docs/comparison.md"
