// SPDX-License-Identifier: Apache-2.0
#pragma once

// Sub-commands of the `plumb` program register themselves with PLUMB_COMMAND; main() dispatches
// `plumb <name> args...` to the matching function, which returns the process exit code.

#include <string>
#include <vector>

namespace plumb::tools {

using CommandFn = int (*)(const std::vector<std::string>& args);

struct Command {
    const char* name;     ///< the sub-command word
    const char* summary;  ///< one line for `plumb --help`
    CommandFn run;        ///< receives the arguments after the sub-command word
};

/// Registers a command (called from static initialisers in this executable's sources only).
bool registerCommand(const Command& command);
const std::vector<Command>& commands();

/// Exit codes shared by every command.
constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;  ///< the work failed (bad data, failed stage)
constexpr int kExitUsage = 2;    ///< bad command line

}  // namespace plumb::tools

#define PLUMB_COMMAND(ident, name, summary, fn)          \
    static const bool plumb_command_registered_##ident = \
        ::plumb::tools::registerCommand(::plumb::tools::Command{name, summary, fn})
