// SPDX-License-Identifier: Apache-2.0
#pragma once

// Running a built program from a test as a user would, with its output captured.

#include <filesystem>
#include <string>
#include <vector>

namespace plumb::testing {

struct ProcessRun {
    int exit_code = -1;  ///< -1 when the program did not exit normally
    std::string out;     ///< what it wrote to stdout
    std::string err;     ///< what it wrote to stderr
};

/// The whole content of a file ("" when it cannot be read).
std::string slurp(const std::filesystem::path& path);

/// Runs `command` (a program path, optionally followed by a subcommand, e.g. "/x/plumb sim")
/// with `args`, each single-quoted, capturing stdout and stderr through files in `log_dir`.
ProcessRun runProgram(const std::string& command, const std::filesystem::path& log_dir,
                      const std::vector<std::string>& args);

}  // namespace plumb::testing
