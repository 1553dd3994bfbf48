// SPDX-License-Identifier: Apache-2.0
#include "drivers/device_clock.hpp"

#include <algorithm>
#include <chrono>

#include "common/core/timing.hpp"

namespace plumb {

double DeviceClock::toHost(uint64_t device_us, double host_arrival_s) {
    const double device_s = static_cast<double>(device_us) * 1e-6;
    if (offset_s_) {
        const double step_s =
            (static_cast<double>(device_us) - static_cast<double>(last_device_us_)) * 1e-6;
        if (device_us < last_device_us_ || step_s > max_jump_s_) {
            offset_s_.reset();
            ++resets_;
        }
    }
    last_device_us_ = device_us;
    const double candidate = host_arrival_s - device_s;
    offset_s_ = offset_s_ ? std::min(*offset_s_, candidate) : candidate;
    return device_s + *offset_s_;
}

double hostNowSeconds() { return wallClockSeconds(); }

}  // namespace plumb
