// SPDX-License-Identifier: Apache-2.0
// The CPU check of an x86-64-v2 build (common/cpu_check.cpp): this very test program, run by
// qemu's user-mode emulator as an older CPU, must refuse to start with a message and exit code 1,
// and run as a CPU that has SSE4.2.

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>

#include "tests/testing/run_program.hpp"
#include "tests/testing/shared_data.hpp"

namespace {

namespace fs = std::filesystem;

#if defined(__x86_64__) && defined(__SSE4_2__)
/// qemu's x86-64 user-mode emulator on PATH, or "" (tools/setup.sh installs qemu-user).
std::string findQemu() {
    const char* path = std::getenv("PATH");
    for (const char* name : {"qemu-x86_64-static", "qemu-x86_64"}) {
        std::istringstream dirs(path != nullptr ? path : "");
        for (std::string dir; std::getline(dirs, dir, ':');) {
            const fs::path candidate = fs::path(dir) / name;
            if (!dir.empty() && fs::exists(candidate)) return candidate.string();
        }
    }
    return "";
}

TEST(CpuCheck, AnX8664V2BuildRefusesAnOlderCpuWithAMessage) {
    const std::string qemu = findQemu();
    if (qemu.empty()) {
        if (plumb::testing::runningInCi()) FAIL() << "qemu-x86_64 not found under CI";
        GTEST_SKIP() << "qemu-x86_64 not found (tools/setup.sh installs qemu-user)";
    }
    const fs::path self = fs::read_symlink("/proc/self/exe");
    const fs::path dir = plumb::testing::freshTempDir("cpu_check");

    // qemu64: the x86-64 baseline, no SSE4.1, SSE4.2 or POPCNT.
    const plumb::testing::ProcessRun old_cpu = plumb::testing::runProgram(
        qemu + " -cpu qemu64 '" + self.string() + "'", dir, {"--gtest_list_tests"});
    EXPECT_EQ(old_cpu.exit_code, 1) << old_cpu.err;
    EXPECT_NE(old_cpu.err.find("this build needs an x86-64-v2 CPU (SSE4.2 and POPCNT)"),
              std::string::npos)
        << old_cpu.err;
    EXPECT_EQ(old_cpu.out, "");

    // Nehalem: the first x86-64-v2 CPU.
    const plumb::testing::ProcessRun v2_cpu = plumb::testing::runProgram(
        qemu + " -cpu Nehalem '" + self.string() + "'", dir, {"--gtest_list_tests"});
    EXPECT_EQ(v2_cpu.exit_code, 0) << v2_cpu.err;
    EXPECT_NE(v2_cpu.out.find("AnX8664V2BuildRefusesAnOlderCpuWithAMessage"), std::string::npos)
        << v2_cpu.out;
}
#endif

}  // namespace
