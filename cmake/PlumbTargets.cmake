# SPDX-License-Identifier: Apache-2.0
# Helpers shared by every folder: warnings, libraries, tests.

# plumb_set_warnings(<target>): the one place that sets compiler warnings.
function(plumb_set_warnings target)
    target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic)
    if(PLUMB_WERROR)
        target_compile_options(${target} PRIVATE -Werror)
    endif()
endfunction()

# plumb_add_library(<name> SOURCES ... [PUBLIC_LIBS ...] [PRIVATE_LIBS ...])
# Creates plumb_<name> with the alias plumb::<name>; include root = repository root.
function(plumb_add_library name)
    cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_LIBS;PRIVATE_LIBS" ${ARGN})
    add_library(plumb_${name} STATIC ${ARG_SOURCES})
    add_library(plumb::${name} ALIAS plumb_${name})
    target_include_directories(plumb_${name} PUBLIC
        $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}> $<BUILD_INTERFACE:${PROJECT_BINARY_DIR}>)
    target_link_libraries(plumb_${name} PUBLIC ${ARG_PUBLIC_LIBS} PRIVATE ${ARG_PRIVATE_LIBS})
    plumb_set_warnings(plumb_${name})
endfunction()

# Labels added to every test of this build tree (the aarch64 cross build adds "aarch64").
set(PLUMB_EXTRA_TEST_LABELS "" CACHE STRING "Extra ctest labels for every test of this build")

# Test timeouts are multiplied by this (the aarch64 build runs its tests under qemu, about ten
# times slower than natively).
set(PLUMB_TEST_TIMEOUT_SCALE 1 CACHE STRING "Factor applied to every test timeout of this build")

# plumb_add_test(<name> SOURCES ... LIBS ... LABELS ... [TIMEOUT s])
# One GoogleTest executable per module; every test case is registered with ctest and labelled
# (LABELS plus PLUMB_EXTRA_TEST_LABELS).
function(plumb_add_test name)
    cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;LIBS;LABELS" ${ARGN})
    add_executable(${name} ${ARG_SOURCES})
    target_link_libraries(${name} PRIVATE ${ARG_LIBS} plumb::testing GTest::gtest GTest::gtest_main)
    plumb_set_warnings(${name})
    if(NOT ARG_TIMEOUT)
        set(ARG_TIMEOUT 600)
    endif()
    math(EXPR ARG_TIMEOUT "${ARG_TIMEOUT} * ${PLUMB_TEST_TIMEOUT_SCALE}")
    gtest_discover_tests(${name}
        WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
        PROPERTIES LABELS "${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
        DISCOVERY_TIMEOUT 60)
    if(PLUMB_EXTRA_TEST_LABELS)
        # gtest_discover_tests flattens PROPERTIES, so one label list cannot pass through it: a
        # ctest include file, run after the discovered tests', relabels them.
        set(all_labels ${ARG_LABELS} ${PLUMB_EXTRA_TEST_LABELS})
        set(extra "${CMAKE_CURRENT_BINARY_DIR}/${name}_extra_labels.cmake")
        file(WRITE "${extra}" "foreach(t IN LISTS ${name}_TESTS)\n"
            "  set_tests_properties(\"\${t}\" PROPERTIES LABELS \"${all_labels}\")\n"
            "endforeach()\n")
        set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES "${extra}")
    endif()
endfunction()
