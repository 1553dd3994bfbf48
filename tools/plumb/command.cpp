// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/command.hpp"

#include <fmt/format.h>

#include <cstdio>

namespace plumb::tools {

int usageError(std::string_view command, std::string_view message) {
    return ::plumb::usageError(fmt::format("plumb {}", command), message);
}

int failure(std::string_view command, const Status& status, std::string_view context) {
    if (context.empty()) {
        fmt::print(stderr, "plumb {}: {}\n", command, status.toString());
    } else {
        fmt::print(stderr, "plumb {}: {}: {}\n", command, context, status.toString());
    }
    return kExitFailure;
}

}  // namespace plumb::tools
