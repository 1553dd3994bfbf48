// SPDX-License-Identifier: Apache-2.0
#include "common/core/simd.hpp"

#include <atomic>
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

std::atomic<int> g_cap{static_cast<int>(Level::kAvx2)};  // ScopedLevel's cap

}  // namespace

Level best() {
    static const Level level = detect();
    const int cap = g_cap.load(std::memory_order_relaxed);
    return static_cast<int>(level) <= cap ? level : static_cast<Level>(cap);
}

ScopedLevel::ScopedLevel(Level level) : previous_(g_cap.exchange(static_cast<int>(level))) {}

ScopedLevel::~ScopedLevel() { g_cap.store(previous_); }

}  // namespace plumb::simd
