# SPDX-License-Identifier: Apache-2.0
# CMake toolchain: Linux on aarch64 with Debian's cross compiler (g++-aarch64-linux-gnu), target
# libraries from Debian's arm64 packages unpacked into AARCH64_TARGET_ROOT, and qemu-aarch64 as
# the emulator that runs target programs (tests, try_run) on the build machine.
#
#   cmake -S . -B build-aarch64 -DCMAKE_TOOLCHAIN_FILE=toolchains/aarch64-linux-gnu.cmake \
#         [-DAARCH64_TARGET_ROOT=/opt/plumb-aarch64-root]
#
# AARCH64_TARGET_ROOT (default: $ENV{PLUMB_AARCH64_ROOT}, else /opt/plumb-aarch64-root) holds
# usr/include, usr/lib/aarch64-linux-gnu, usr/share as unpacked from .deb files; libc and
# libstdc++ come from the cross compiler's own root (/usr/aarch64-linux-gnu).

set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)

set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)

if(NOT AARCH64_TARGET_ROOT)
    if(DEFINED ENV{PLUMB_AARCH64_ROOT})
        set(AARCH64_TARGET_ROOT "$ENV{PLUMB_AARCH64_ROOT}")
    else()
        set(AARCH64_TARGET_ROOT /opt/plumb-aarch64-root)
    endif()
endif()
set(AARCH64_TARGET_ROOT "${AARCH64_TARGET_ROOT}" CACHE PATH "Unpacked arm64 target libraries")
# try_compile projects see the same root.
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES AARCH64_TARGET_ROOT)
set(_cross_root /usr/aarch64-linux-gnu)

# Target headers, libraries and package files only from the target roots; programs (lcm-gen,
# pkg-config) from the build machine.
set(CMAKE_FIND_ROOT_PATH "${AARCH64_TARGET_ROOT}" "${_cross_root}")
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)

# Target pkg-config: only the target root's .pc files, their /usr paths mapped into the root.
set(ENV{PKG_CONFIG_LIBDIR}
    "${AARCH64_TARGET_ROOT}/usr/lib/aarch64-linux-gnu/pkgconfig:${AARCH64_TARGET_ROOT}/usr/share/pkgconfig")
set(ENV{PKG_CONFIG_SYSROOT_DIR} "${AARCH64_TARGET_ROOT}")
set(ENV{PKG_CONFIG_PATH} "")

# Headers of the target root after the compiler's own, its multiarch directory first (OpenSSL's
# opensslconf.h and configuration.h live in usr/include/aarch64-linux-gnu); shared libraries'
# dependencies resolved in the target root at link time.
set(_lib "${AARCH64_TARGET_ROOT}/usr/lib/aarch64-linux-gnu")
set(_include "${AARCH64_TARGET_ROOT}/usr/include/aarch64-linux-gnu;${AARCH64_TARGET_ROOT}/usr/include")
set(CMAKE_C_STANDARD_INCLUDE_DIRECTORIES "${_include}")
set(CMAKE_CXX_STANDARD_INCLUDE_DIRECTORIES "${_include}")
foreach(kind EXE SHARED MODULE)
    set(CMAKE_${kind}_LINKER_FLAGS_INIT
        "-L${_lib} -Wl,-rpath-link,${_lib} -Wl,-rpath-link,${AARCH64_TARGET_ROOT}/lib/aarch64-linux-gnu")
endforeach()

# Run target programs with qemu: the cross compiler's root provides the dynamic loader and libc,
# the target root the other shared libraries.
find_program(AARCH64_QEMU NAMES qemu-aarch64-static qemu-aarch64 REQUIRED)
set(CMAKE_CROSSCOMPILING_EMULATOR
    "${AARCH64_QEMU};-L;${_cross_root};-E;LD_LIBRARY_PATH=${_lib}:${AARCH64_TARGET_ROOT}/lib/aarch64-linux-gnu")
