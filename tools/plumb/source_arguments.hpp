// SPDX-License-Identifier: Apache-2.0
#pragma once

// The source options that `plumb fuse` and `plumb reconstruct` share, read one command-line word
// at a time into drivers' SourceOptions, with the same checks and messages in both:
//   --frames N, --intrinsics X, --depth-scale S, --seed S, --depth-calibration X, --no-colour,
//   --noise MODE

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/source.hpp"

namespace plumb::tools {

/// Reads the source option at args[*i] into `*options`, advancing *i past its value.
/// `*matched` says whether args[*i] was one of them. nullopt when it was read or was not a
/// source option; else the exit status of the usage error printed for `command` (a missing or
/// bad value).
std::optional<int> parseSourceOption(std::string_view command, const std::vector<std::string>& args,
                                     size_t* i, SourceOptions* options, bool* matched);

}  // namespace plumb::tools
