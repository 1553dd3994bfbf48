// SPDX-License-Identifier: Apache-2.0
#include "tests/testing/run_program.hpp"

#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <iterator>

namespace plumb::testing {

std::string slurp(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

ProcessRun runProgram(const std::string& command, const std::filesystem::path& log_dir,
                      const std::vector<std::string>& args) {
    std::string line = command;
    for (const std::string& a : args) line += " '" + a + "'";
    line += " > '" + (log_dir / "stdout.txt").string() + "' 2> '" +
            (log_dir / "stderr.txt").string() + "'";
    const int status = std::system(line.c_str());
    ProcessRun run;
    run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    run.out = slurp(log_dir / "stdout.txt");
    run.err = slurp(log_dir / "stderr.txt");
    return run;
}

}  // namespace plumb::testing
