#!/usr/bin/env bash
# The test command (README.md): installs what the tests need, builds the workspace,
# checks lints and formatting, and runs every test. Tests that need a real vcan (the
# nextest group vcan of .config/nextest.toml: test binaries named vcan_*) run natively
# when this kernel has vcan and we may create interfaces, otherwise inside a throwaway
# VM (vcan-setup vm) whose stock kernel has CAN. Either way they run: a missing vcan
# fails them loudly, it never skips them.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/install-deps.sh
source scripts/env.sh

cargo build --workspace --all-targets --locked
# The real-time runs on vcan (ugv-sim with the real controller binary) use release
# binaries: debug builds are too slow for the 100 ms watchdogs inside an emulated VM.
cargo build --workspace --release --locked
export UGV_BIN_DIR="$PWD/target/release"
# The C++ example controller (examples/cpp, run by tests/tests/vcan_cpp_example.rs):
# built here on the host, not inside the VM, against the release build's laser shim.
make -C examples/cpp CXXFLAGS="-O2 -g -Werror"

echo "== lints and formatting"
cargo clippy --workspace --all-targets --locked -- -D warnings
cargo fmt --all --check

echo "== tests on the host (everything but the vcan group)"
cargo nextest run --workspace --locked --no-fail-fast -E 'not group(vcan)'

echo "== tests on a real vcan (the vcan group: vcan_*)"
# One at a time (the group's max-threads in .config/nextest.toml): inside an emulated
# VM two vCPUs are shared by the simulator, the controller and the test processes, and
# the real-time runs keep 100 ms watchdogs.
vcan_tests=(cargo nextest run --workspace --locked --no-fail-fast -E 'group(vcan)')
if target/debug/vcan-setup status >/dev/null 2>&1 && [[ $(id -u) -eq 0 ]]; then
    "${vcan_tests[@]}"
else
    target/debug/vcan-setup status || true
    target/debug/vcan-setup vm -- "${vcan_tests[@]}"
fi
