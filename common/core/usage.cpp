// SPDX-License-Identifier: Apache-2.0
#include "common/core/usage.hpp"

#include <fmt/format.h>

#include <cstdio>

namespace plumb {

int usageError(std::string_view program, std::string_view message, std::string_view usage) {
    if (usage.empty()) {
        fmt::print(stderr, "{}: {} (see {} --help)\n", program, message, program);
    } else {
        fmt::print(stderr, "{}: {}\n\n{}", program, message, usage);
    }
    return kExitUsage;
}

}  // namespace plumb
