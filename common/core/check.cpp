// SPDX-License-Identifier: Apache-2.0
#include "common/core/check.hpp"

#include <cstdio>
#include <cstdlib>

namespace plumb::detail {

CheckFailure::CheckFailure(const char* condition, const char* file, int line) {
    stream_ << file << ":" << line << ": check failed: " << condition;
}

CheckFailure::~CheckFailure() {
    const std::string text = stream_.str();
    std::fprintf(stderr, "%s\n", text.c_str());
    std::fflush(stderr);
    std::abort();
}

}  // namespace plumb::detail
