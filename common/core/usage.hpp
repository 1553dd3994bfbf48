// SPDX-License-Identifier: Apache-2.0
#pragma once

// How every plumb program (plumb and its commands, plumb-device, plumb-backend) reports a bad
// command line or configuration: the program's name and the message on stderr, and the exit
// status kExitUsage.
//
// Thread-safety: usageError() may be called from any thread (its line may interleave with other
// writers of stderr).

#include <string_view>

namespace plumb {

/// Exit status of a program whose command line or configuration is bad.
constexpr int kExitUsage = 2;

/// Prints "<program>: <message>" to stderr and returns kExitUsage. `program` is the program as
/// typed ("plumb-backend", "plumb fuse"). With `usage` empty a hint to --help ends the line:
///   plumb-backend: --out is required (see plumb-backend --help)
/// otherwise a blank line and `usage` (printed as it is) follow the message.
int usageError(std::string_view program, std::string_view message, std::string_view usage = {});

}  // namespace plumb
