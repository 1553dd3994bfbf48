// SPDX-License-Identifier: Apache-2.0
#pragma once

// Wall-clock measurement of stages, for diagnostics and benchmarks (never for results).
// Thread-safe.

#include <chrono>

namespace plumb {

using SteadyClock = std::chrono::steady_clock;

/// Milliseconds elapsed on the steady clock since `t0`.
inline double msSince(SteadyClock::time_point t0) {
    return std::chrono::duration<double, std::milli>(SteadyClock::now() - t0).count();
}

/// Seconds since the Unix epoch on the system (wall) clock: host timestamps of frames and
/// messages.
inline double wallClockSeconds() {
    return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

}  // namespace plumb
