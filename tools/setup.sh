#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Installs every Debian 12 package that plumb's build, tests and demo need. Non-interactive and
# idempotent: when everything is present it only checks (a second or two) and installs nothing.
set -euo pipefail

packages=(
    # toolchain
    build-essential cmake ninja-build pkg-config git clang clang-format clang-tidy
    # common/ and the device side
    libeigen3-dev libtbb-dev libfmt-dev libspdlog-dev libtomlplusplus-dev nlohmann-json3-dev
    libnanoflann-dev
    # drivers
    libopencv-dev libopenni2-dev libusb-1.0-0-dev libv4l-dev
    # messages: LCM (lcm.pc requires glib)
    liblcm-dev liblcm-bin libglib2.0-dev
    # backend: PCL (its VTK needs MPI's C bindings), Ceres, Boost graph
    libpcl-dev libopenmpi-dev libceres-dev libboost-graph-dev
    # tests, benchmarks and the peer (Open3D is an oracle and a peer, never on the runtime path)
    libgtest-dev libgmock-dev libbenchmark-dev libopen3d-dev python3-open3d python3-numpy
    # monitor
    libcpp-httplib-dev
)

missing=()
for p in "${packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$p")
    fi
done

if [ ${#missing[@]} -eq 0 ]; then
    echo "setup: all ${#packages[@]} packages present"
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
echo "setup: done"
