#!/usr/bin/env bash
# Install everything ugv-hil needs on a fresh Debian 12 (bookworm) machine, as root.
#
# Idempotent: packages already present are skipped, `apt-get update` runs only
# when something has to be installed, so a second run takes about a second.
#
# Why a VM at all: the host kernel here has no CAN support, so SocketCAN tests run
# inside a throwaway QEMU VM (virtme-ng) booted from Debian's stock kernel, which
# ships vcan/can/can-raw as modules. Recipe verified with virtme-ng 1.42, QEMU 10.0.2
# (TCG, no KVM), linux-image 6.1.0-56-amd64:
#
#   KERNEL=$(ls /boot/vmlinuz-*-amd64 | sort -V | tail -n1)
#   vng --run "$KERNEL" --disable-kvm --memory 2G --cpus 2 \
#       [--rwdir /path/the/guest/may/write] \
#       -- env PATH="$PATH" sh -c 'ip link add dev vcan0 type vcan && ip link set up vcan0 && ...' \
#       </dev/null 2>&1 | cat ; rc=${PIPESTATUS[0]}
#
# Quirks (see `--check` below for a runnable example):
#  * stdin MUST be open (</dev/null is fine); a closed stdin makes vng crash.
#  * stdout/stderr MUST be pipes (hence `| cat`): vng hands QEMU /proc/self/fd/1 and
#    /proc/self/fd/2 as file chardevs, which QEMU re-opens with O_TRUNC, so a
#    regular-file stdout gets truncated and stdout/stderr overwrite each other.
#  * The guest command's exit code is returned by vng.
#  * Guest env is NOT inherited (PATH is reset, custom vars dropped): pass them with `env`.
#  * Host / is shared read-only (9p); cwd is kept. /tmp is a private overlay
#    (writes vanish); use --rwdir DIR for anything the host must see (e.g. target/).
#  * /dev/shm is a private tmpfs (half the guest RAM).
#  * vng needs its own bin dir (pyenv) on PATH: it execs `virtme-run`.
set -euo pipefail

if [[ $(id -u) -ne 0 ]]; then
    echo "install-deps.sh: must run as root" >&2
    exit 1
fi

export DEBIAN_FRONTEND=noninteractive

# ---------------------------------------------------------------- apt packages
# Packages from bookworm:
APT_PKGS=(
    linux-image-amd64   # Debian stock kernel booted in the VM; has vcan, can, can-raw, 9p modules
    busybox-static      # virtme-ng builds the guest initramfs (module loading for 9p/virtio) with it
    can-utils           # candump / cansend / cangen for tests and debugging inside the VM
    iproute2            # `ip link add dev vcan0 type vcan` inside the VM
    fonts-dejavu-core   # the font ugv-sim draws its figures with (plotters, ab_glyph)
    gpsd                # NMEA cross-check: sim/tests/gps_gpsd.rs runs gpsd -N -n -b on the simulated GPS pty
    gpsd-clients        # gpsfake and gpspipe: tests/tests/record.rs replays a recorded gps.nmea into gpsd
    g++                 # the C++ example controller (examples/cpp, C++17), built by scripts/test.sh
    make                # its Makefile
)
# From bookworm-backports: the machine image ships qemu-utils 10.0 from backports,
# which Breaks bookworm's qemu-system-common 7.2 (apt would remove qemu-utils).
BPO_PKGS=(
    qemu-system-x86     # the VM itself (runs under TCG: no usable KVM here)
)
BPO_SOURCES=/etc/apt/sources.list.d/bookworm-backports.sources

pkg_installed() {
    [[ $(dpkg-query -W -f='${db:Status-Status}' "$1" 2>/dev/null || true) == installed ]]
}

missing_apt=()
for p in "${APT_PKGS[@]}"; do pkg_installed "$p" || missing_apt+=("$p"); done
missing_bpo=()
for p in "${BPO_PKGS[@]}"; do pkg_installed "$p" || missing_bpo+=("$p"); done

need_update=0
if ((${#missing_bpo[@]})) && ! grep -rqs 'bookworm-backports' /etc/apt/sources.list /etc/apt/sources.list.d/; then
    cat >"$BPO_SOURCES" <<'EOF'
Types: deb
URIs: http://deb.debian.org/debian
Suites: bookworm-backports
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
    need_update=1
fi
if ((${#missing_apt[@]} + ${#missing_bpo[@]})); then
    need_update=1
fi

APT_INSTALL=(apt-get install -y -q --no-install-recommends
    -o Dpkg::Options::=--force-confdef -o Dpkg::Options::=--force-confold)

if ((need_update)); then
    echo "install-deps: apt-get update"
    apt-get update -q
fi
if ((${#missing_bpo[@]})); then
    echo "install-deps: installing from bookworm-backports: ${missing_bpo[*]}"
    "${APT_INSTALL[@]}" -t bookworm-backports "${missing_bpo[@]}"
fi
if ((${#missing_apt[@]})); then
    echo "install-deps: installing: ${missing_apt[*]}"
    "${APT_INSTALL[@]}" "${missing_apt[@]}"
fi

# ---------------------------------------------------------------- pip packages
PIP_PKGS=(
    virtme-ng==1.42     # `vng`: boots the kernel with the host fs shared; quirks above verified on 1.42
    cantools==45.1.0    # DBC encode/decode used by the tests
    pynmea2==1.19.0     # NMEA cross-check: sim/tests/gps_pynmea2.rs parses every simulated sentence
    kubernetes==37.0.2  # the API models sim/tests/deploy.rs validates deploy/k8s/suite-job.yaml against
    pyyaml==6.0.3       # YAML for the same test (the manifest, the GitHub Actions workflow)
    mcap==1.6.0         # an independent MCAP reader: tests/tests/record.rs opens run.mcap with it
    mcap-protobuf-support==0.6.0  # its protobuf decoder: the Foxglove panels' check (record_common/foxglove_panels.py)
    protobuf==7.36.2    # what that decoder decodes the messages with, from the schemas in the file
    websockets==15.0.1  # a Foxglove WebSocket client that is not the SDK: sim/tests/live_view.rs (live_client.py)
)
PY=${PYTHON:-python3}

missing_pip=()
for spec in "${PIP_PKGS[@]}"; do
    name=${spec%%==*}
    want=${spec#*==}
    have=$("$PY" -m pip show "$name" 2>/dev/null | sed -n 's/^Version: //p' || true)
    [[ $have == "$want" ]] || missing_pip+=("$spec")
done
if ((${#missing_pip[@]})); then
    echo "install-deps: pip installing: ${missing_pip[*]}"
    if ! "$PY" -m pip install -q --root-user-action=ignore "${missing_pip[@]}"; then
        # Debian's own python3 is "externally managed" (PEP 668); pyenv's is not.
        "$PY" -m pip install -q --root-user-action=ignore --break-system-packages "${missing_pip[@]}"
    fi
    if command -v pyenv >/dev/null 2>&1; then pyenv rehash || true; fi
fi

# ---------------------------------------------------------------- the Python example's venv
# examples/python/ (a controller of its own on the wires, docs/wire-contract.md) runs in
# a venv of its own with the packages pinned in its requirements.txt (pyserial,
# iceoryx2's binding, python-can, cantools); rebuilt only when that file changes, so a
# second run costs one cmp.
EXAMPLE_DIR=$(cd "$(dirname "$0")/../examples/python" && pwd)
if ! cmp -s "$EXAMPLE_DIR/requirements.txt" "$EXAMPLE_DIR/.venv/requirements.installed"; then
    echo "install-deps: the Python example's venv (examples/python/.venv)"
    "$PY" -m venv "$EXAMPLE_DIR/.venv"
    "$EXAMPLE_DIR/.venv/bin/python" -m pip install -q --disable-pip-version-check \
        -r "$EXAMPLE_DIR/requirements.txt"
    cp "$EXAMPLE_DIR/requirements.txt" "$EXAMPLE_DIR/.venv/requirements.installed"
fi

# ---------------------------------------------------------------- cargo tools
# clippy and rustfmt: scripts/test.sh checks lints and formatting; rustup's minimal
# profile has neither.
if command -v rustup >/dev/null 2>&1; then
    installed=$(rustup component list --installed)
    for component in clippy rustfmt; do
        grep -q "^$component" <<<"$installed" || rustup component add "$component"
    done
fi
# cargo-nextest runs the tests (one process per test, the vcan test group; 0.9.133 or
# later, .config/nextest.toml); the machine image ships it, a bare Rust install does not.
if ! command -v cargo-nextest >/dev/null 2>&1 && [[ ! -x $HOME/.cargo/bin/cargo-nextest ]]; then
    echo "install-deps: cargo install cargo-nextest"
    cargo install --locked cargo-nextest
fi

# ---------------------------------------------------------------- summary
KERNEL=$(ls /boot/vmlinuz-*-amd64 2>/dev/null | sort -V | tail -n1 || true)
VNG_BIN=$(dirname "$("$PY" -c 'import sys; print(sys.executable)')")/vng
[[ -n $KERNEL ]] || { echo "install-deps: no /boot/vmlinuz-*-amd64 found" >&2; exit 1; }
[[ -x $VNG_BIN ]] || { echo "install-deps: vng not found at $VNG_BIN" >&2; exit 1; }
echo "install-deps: ok (kernel: $KERNEL, modules: /lib/modules/${KERNEL#/boot/vmlinuz-}, vng: $VNG_BIN)"

# ---------------------------------------------------------------- optional smoke test
# `install-deps.sh --check` boots the VM (~15-20 s) and round-trips one CAN frame on vcan0.
if [[ ${1:-} == --check ]]; then
    export PATH="$(dirname "$VNG_BIN"):$PATH"
    set +e
    vng --run "$KERNEL" --disable-kvm --memory 2G --cpus 2 -- env PATH="$PATH" sh -ec '
        ip link add dev vcan0 type vcan
        ip link set up vcan0
        candump -n 1 -T 5000 vcan0 > /tmp/candump.out &
        sleep 0.5
        cansend vcan0 123#DEADBEEF
        wait
        cat /tmp/candump.out
        grep -q "DE AD BE EF" /tmp/candump.out
    ' </dev/null 2>&1 | cat
    rc=${PIPESTATUS[0]}
    set -e
    if ((rc == 0)); then echo "install-deps: vcan check passed"; else echo "install-deps: vcan check FAILED (rc=$rc)" >&2; fi
    exit "$rc"
fi
