// SPDX-License-Identifier: Apache-2.0
#pragma once

// Sub-commands of the `plumb` program register themselves with PLUMB_COMMAND; main() dispatches
// `plumb <name> args...` to the matching function, which returns the process exit code.
//
// Every command reports the same way (tools/plumb/command.cpp): a bad command line or
// configuration with usageError() (one line and a hint to --help, exit kExitUsage), failed work
// with failure() (the Status as text, exit kExitFailure), both on stderr:
//   plumb fuse: --frames needs a positive integer (see plumb fuse --help)
//   plumb fuse: corrupt: depth/12.png: cannot decode PNG (truncated or damaged, 5441 bytes): ...

#include <charconv>
#include <cmath>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "common/core/status.hpp"
#include "common/core/usage.hpp"

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
using ::plumb::kExitUsage;       ///< bad command line or configuration (common/core/usage.hpp)
constexpr int kExitInterrupted = 130;  ///< stopped by Ctrl-C (SIGINT) or SIGTERM, as shells do

/// plumb::usageError (common/core/usage.hpp) of `plumb <command>`: prints "plumb <command>:
/// <message> (see plumb <command> --help)" to stderr and returns kExitUsage. `command` is the
/// sub-command as typed ("fuse", "eval traj").
int usageError(std::string_view command, std::string_view message);

/// Prints "plumb <command>: [<context>: ]<status as text>" to stderr and returns kExitFailure.
int failure(std::string_view command, const Status& status, std::string_view context = {});

/// Parses the whole of `text` as a number of type T (an optional leading '+', a '-' for signed
/// types only, no spaces); a floating-point value must be finite ("nan", "inf" are refused).
/// False, with `*value` unspecified, otherwise.
template <typename T>
bool parseNumber(std::string_view text, T* value) {
    static_assert(std::is_arithmetic_v<T> && !std::is_same_v<T, bool>, "a number type");
    if (text.size() > 1 && text[0] == '+' && text[1] != '+' && text[1] != '-') {
        text.remove_prefix(1);
    }
    const char* end = text.data() + text.size();
    const auto [ptr, ec] = std::from_chars(text.data(), end, *value);
    if (ec != std::errc() || ptr != end) return false;
    if constexpr (std::is_floating_point_v<T>) return std::isfinite(*value);
    return true;
}

}  // namespace plumb::tools

#define PLUMB_COMMAND(ident, name, summary, fn)          \
    static const bool plumb_command_registered_##ident = \
        ::plumb::tools::registerCommand(::plumb::tools::Command{name, summary, fn})
