#!/usr/bin/env bash
# The main job (README.md): installs what it needs, builds (release), makes sure vcan0
# exists (natively, or inside a throwaway VM through vcan-setup vm when this kernel has
# no CAN), and runs scripts/main-job.sh on it. Results go to results/.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/install-deps.sh
source scripts/env.sh

cargo build --workspace --release --locked
mkdir -p results

if target/release/vcan-setup status >/dev/null 2>&1 && [[ $(id -u) -eq 0 ]]; then
    target/release/vcan-setup up vcan0
    bash scripts/main-job.sh
else
    target/release/vcan-setup vm -- bash scripts/main-job.sh
fi
