#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Installs every Debian 12 package that plumb's build, tests and demo need. Non-interactive and
# idempotent: when everything is present it only checks (a second or two) and installs nothing.
set -euo pipefail

# `setup.sh --cross-aarch64`: the aarch64 cross compiler, qemu and the arm64 device libraries
# (`make cross-device`, see tools/setup_aarch64.sh). Not needed for `make test` or `make demo`.
if [ "${1:-}" = "--cross-aarch64" ]; then
    exec bash "$(dirname "$0")/setup_aarch64.sh"
fi

packages=(
    # toolchain
    build-essential cmake ninja-build pkg-config git clang clang-format clang-tidy
    libclang-rt-14-dev  # libFuzzer runtime for the optional fuzz_decoders test
    # common/ and the device side
    libeigen3-dev libtbb-dev libfmt-dev libspdlog-dev libtomlplusplus-dev nlohmann-json3-dev
    libnanoflann-dev
    # drivers
    libopencv-dev libpng-dev libopenni2-dev libusb-1.0-0-dev libv4l-dev
    # messages: LCM (lcm.pc requires glib); libcrypto (HMAC-SHA256) and zlib (CRC-32)
    liblcm-dev liblcm-bin libglib2.0-dev libssl-dev zlib1g-dev
    # backend: PCL (its VTK needs MPI's C bindings)
    libpcl-dev libopenmpi-dev
    # tests, benchmarks and the peer (Open3D is an oracle and a peer, never on the runtime path)
    libgtest-dev libgmock-dev libbenchmark-dev libopen3d-dev python3-open3d python3-numpy
    qemu-user  # runs a test program as an older x86-64 CPU (tests/common/cpu_check_test)
    # monitor, and its browser test (Debian's Chromium, driven by playwright-core from npm)
    libcpp-httplib-dev chromium chromium-driver
)

# The monitor's browser test drives /usr/bin/chromium with playwright-core (pinned in
# tools/monitor/browser-test/package-lock.json; it downloads no browser). Installed with the
# machine's npm into tools/monitor/browser-test/node_modules, again only when the lock changed.
browser_test_deps() {
    local dir
    dir="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)/monitor/browser-test"
    [ -f "$dir/package-lock.json" ] || return 0
    if ! command -v npm >/dev/null; then
        echo "setup: npm not found: the monitor's browser test cannot run (install Node.js >= 20)" >&2
        return 0
    fi
    if [ -f "$dir/node_modules/.package-lock.json" ] &&
        [ "$dir/node_modules/.package-lock.json" -nt "$dir/package-lock.json" ]; then
        return 0
    fi
    echo "setup: npm ci in $dir"
    (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error) ||
        echo "setup: npm ci failed: the monitor's browser test will not run" >&2
}

missing=()
for p in "${packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$p")
    fi
done

if [ ${#missing[@]} -eq 0 ]; then
    echo "setup: all ${#packages[@]} packages present"
    browser_test_deps
    exit 0
fi

echo "setup: installing ${#missing[@]} package(s): ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "setup: need root or sudo to install packages" >&2; exit 1; }
    SUDO="sudo"
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
browser_test_deps
echo "setup: done"
