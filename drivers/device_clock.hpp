// SPDX-License-Identifier: Apache-2.0
#pragma once

// Maps a sensor's own clock (device timestamps, microseconds since it powered up or started
// streaming) to host time. Frames reach the host some latency after capture, so
//     host_arrival_k = device_k + offset + latency_k,  latency_k >= 0,
// and min_k (host_arrival_k - device_k) converges to offset + min latency: the estimate only ever
// moves down, so host times stay monotonic while the offset is being learnt. A device clock that
// jumps backwards (camera re-plugged, stream restarted) or forwards by more than `max_jump_s`
// starts a new estimate.
//
// Not thread-safe: one DeviceClock per stream, used by the thread that receives its frames.

#include <cstdint>
#include <optional>

namespace plumb {

class DeviceClock {
  public:
    explicit DeviceClock(double max_jump_s = 5.0) : max_jump_s_(max_jump_s) {}

    /// Host time (seconds, same clock as host_arrival_s) of a frame stamped device_us by the
    /// device and received at host_arrival_s.
    double toHost(uint64_t device_us, double host_arrival_s);

    /// Forget the offset (next frame starts a new estimate).
    void reset() { offset_s_.reset(); }
    /// Number of times the device clock restarted (backwards jump or large gap).
    int resets() const { return resets_; }

  private:
    double max_jump_s_;
    std::optional<double> offset_s_;
    uint64_t last_device_us_ = 0;
    int resets_ = 0;
};

/// Host wall-clock time in seconds since the Unix epoch (plumb::wallClockSeconds).
double hostNowSeconds();

}  // namespace plumb
