// SPDX-License-Identifier: Apache-2.0
#include "common/core/simd.hpp"

#include <cstdlib>
#include <cstring>

namespace plumb::simd {
namespace {

Level detect() {
    if (const char* forced = std::getenv("PLUMB_SIMD");
        forced != nullptr && std::strcmp(forced, "portable") == 0) {
        return Level::kPortable;
    }
#if defined(__x86_64__) && defined(__GNUC__)
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx2")) return Level::kAvx2;
#endif
    return Level::kPortable;
}

}  // namespace

Level best() {
    static const Level level = detect();
    return level;
}

const char* toString(Level level) {
    switch (level) {
        case Level::kPortable:
            return "portable";
        case Level::kAvx2:
            return "avx2";
    }
    return "unknown";
}

}  // namespace plumb::simd
