#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Prepares the aarch64 cross build of plumb's device side (`make cross-device`, issue 11):
#   1. the Debian cross compiler (g++-aarch64-linux-gnu, with its libc/libstdc++ for arm64) and
#      qemu-user-static (runs the aarch64 tests on this machine);
#   2. the arm64 builds of the device side's libraries from Debian (multiarch `:arm64` packages),
#      unpacked into a target root, by default /opt/plumb-aarch64-root (PLUMB_AARCH64_ROOT).
#
# Why unpack instead of `apt-get install pkg:arm64`: LCM (liblcm1, liblcm-dev) is not Multi-Arch
# co-installable, so installing its arm64 build removes the host's LCM; and installing arm64
# -dev packages beside the host's forces the host's shared packages (linux-libc-dev, libssl,
# systemd, ...) to the same version, which rebuilds every host build tree. Unpacking the
# packages with dpkg-deb leaves the host untouched. The list has no OpenCV: its arm64 imgcodecs
# pulls GDAL, which conflicts with the host's; drivers/ reads and writes PNGs with libpng there.
#
# Idempotent: when the compiler, qemu and the root for the current package list are present it
# only checks. Needs root (or sudo) for apt-get and to write the target root.
set -euo pipefail

root="${PLUMB_AARCH64_ROOT:-/opt/plumb-aarch64-root}"

# The device side's libraries (headers, pkg-config/CMake files, shared libraries) and the shared
# libraries they load at run time. libc, libgcc and libstdc++ come with the cross compiler.
arm64_packages=(
    libtbb-dev libtbb12 libtbbmalloc2 libtbbbind-2-5 libhwloc15 libudev1
    libfmt-dev libfmt9 libspdlog-dev libspdlog1.10
    libtomlplusplus-dev libtomlplusplus3
    liblcm-dev liblcm1 libglib2.0-dev libglib2.0-0 libpcre2-dev libpcre2-8-0 libffi8 libmount1 libblkid1
    libselinux1
    libopenni2-dev libopenni2-0 libjpeg62-turbo libusb-1.0-0-dev libusb-1.0-0 libv4l-dev
    libv4l-0 libv4lconvert0
    libpng-dev libpng16-16 zlib1g-dev zlib1g
    libssl-dev libssl3
    libgtest-dev libgmock-dev
)
# Header-only libraries (architecture-independent packages) the device side includes.
all_packages=(libeigen3-dev nlohmann-json3-dev libnanoflann-dev)
host_packages=(g++-aarch64-linux-gnu qemu-user-static)

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "setup-aarch64: need root or sudo" >&2; exit 1; }
    SUDO="sudo"
fi
export DEBIAN_FRONTEND=noninteractive

missing=()
for p in "${host_packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$p")
    fi
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup-aarch64: installing ${missing[*]}"
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

stamp="$root/.plumb-packages"
wanted="$(printf '%s:arm64\n' "${arm64_packages[@]}"; printf '%s\n' "${all_packages[@]}")"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$wanted" ]; then
    echo "setup-aarch64: cross compiler, qemu and $root present"
    exit 0
fi

if ! dpkg --print-foreign-architectures | grep -qx arm64; then
    echo "setup-aarch64: adding the arm64 architecture to apt (package lists only)"
    $SUDO dpkg --add-architecture arm64
    $SUDO apt-get update -qq
elif ! apt-cache show libtbb12:arm64 >/dev/null 2>&1; then
    $SUDO apt-get update -qq
fi

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
echo "setup-aarch64: downloading ${#arm64_packages[@]} arm64 and ${#all_packages[@]} header packages"
(cd "$work" && apt-get download -qq $(printf '%s:arm64 ' "${arm64_packages[@]}") \
    "${all_packages[@]}")
$SUDO rm -rf "$root.new"
$SUDO mkdir -p "$root.new"
for deb in "$work"/*.deb; do
    $SUDO dpkg-deb -x "$deb" "$root.new"
done
# pkg-config files say prefix=/usr; PKG_CONFIG_SYSROOT_DIR (set by the toolchain file) maps them
# into the root. Absolute symlinks (lib.so -> /lib/...) would point into the host: make them
# relative to the root.
while IFS= read -r -d '' link; do
    target="$(readlink "$link")"
    case "$target" in
        /*) $SUDO ln -sfn "$(realpath -m --relative-to="$(dirname "$link")" "$root.new$target")" \
                "$link" ;;
    esac
done < <(find "$root.new" -type l -print0)
echo "$wanted" | $SUDO tee "$root.new/.plumb-packages" >/dev/null
$SUDO rm -rf "$root"
$SUDO mv "$root.new" "$root"
echo "setup-aarch64: arm64 libraries unpacked into $root"
