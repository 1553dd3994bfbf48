// SPDX-License-Identifier: Apache-2.0
#pragma once

// Command-line helper shared by the benchmarks.

#include <charconv>
#include <string>

namespace plumb::bench {

/// Parses argv[*i + 1] as a number into `out` and advances *i past it; false when it is missing
/// or not entirely a number.
template <typename T>
bool nextNumber(int argc, char** argv, int* i, T* out) {
    if (*i + 1 >= argc) return false;
    const std::string v = argv[++*i];
    const auto [p, ec] = std::from_chars(v.data(), v.data() + v.size(), *out);
    return ec == std::errc() && p == v.data() + v.size();
}

}  // namespace plumb::bench
