# SPDX-License-Identifier: Apache-2.0
# LCM 1.3.1 ships only pkg-config (lcm.pc, which needs glib) and no CMake helper. This module finds
# the library and the host lcm-gen and generates C++ headers from .lcm files at build time.

find_package(PkgConfig REQUIRED)
pkg_check_modules(lcm REQUIRED IMPORTED_TARGET lcm)
find_program(PLUMB_LCM_GEN_EXECUTABLE NAMES lcm-gen REQUIRED
    DOC "Host lcm-gen (Debian liblcm-bin), run at build time")

# plumb_lcm_generate(<target> FILES <x_t.lcm>... INCLUDE_PREFIX <dir>)
# Runs `lcm-gen --cpp` on FILES into <build>/lcmgen/<INCLUDE_PREFIX>/<package>/x_t.hpp and creates
# the INTERFACE library <target> that carries the include directory (as SYSTEM: generated code is
# not held to our warning flags), LCM itself and the build-order dependency on the generation.
# Sources include the headers as "<INCLUDE_PREFIX>/<package>/x_t.hpp". The package is read from
# each file's `package` line; every file must declare one.
function(plumb_lcm_generate target)
    cmake_parse_arguments(ARG "" "INCLUDE_PREFIX" "FILES" ${ARGN})
    if(NOT ARG_FILES)
        message(FATAL_ERROR "plumb_lcm_generate(${target}): no FILES given")
    endif()
    set(root "${PROJECT_BINARY_DIR}/lcmgen")
    set(out_dir "${root}/${ARG_INCLUDE_PREFIX}")
    set(outputs "")
    set(inputs "")
    foreach(file IN LISTS ARG_FILES)
        get_filename_component(abs "${file}" ABSOLUTE)
        get_filename_component(name "${abs}" NAME_WE)
        file(STRINGS "${abs}" package_line REGEX "^[ \t]*package[ \t]+[A-Za-z0-9_.]+[ \t]*;")
        if(NOT package_line)
            message(FATAL_ERROR "plumb_lcm_generate: ${abs} declares no package")
        endif()
        string(REGEX REPLACE "^[ \t]*package[ \t]+([A-Za-z0-9_.]+).*$" "\\1" package
            "${package_line}")
        string(REPLACE "." "/" package_dir "${package}")
        list(APPEND outputs "${out_dir}/${package_dir}/${name}.hpp")
        list(APPEND inputs "${abs}")
    endforeach()
    add_custom_command(
        OUTPUT ${outputs}
        COMMAND ${CMAKE_COMMAND} -E make_directory "${out_dir}"
        COMMAND ${PLUMB_LCM_GEN_EXECUTABLE} --cpp --cpp-std c++11 --cpp-hpath "${out_dir}"
                --cpp-include "${ARG_INCLUDE_PREFIX}" ${inputs}
        DEPENDS ${inputs}
        COMMENT "lcm-gen: ${target}"
        VERBATIM)
    add_custom_target(${target}_lcmgen DEPENDS ${outputs})
    add_library(${target} INTERFACE)
    add_dependencies(${target} ${target}_lcmgen)
    target_include_directories(${target} SYSTEM INTERFACE "${root}")
    target_link_libraries(${target} INTERFACE PkgConfig::lcm)
    set_property(TARGET ${target} PROPERTY PLUMB_LCM_HEADERS ${outputs})
endfunction()
