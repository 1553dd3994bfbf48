// SPDX-License-Identifier: Apache-2.0
#pragma once

// What a live device keeps of its camera's frames, from the time each frame took to track and
// fuse (measured offline, e.g. by `plumb fuse` or plumb-bench-fusion). It replays the device's
// capture queue (device/stream/device_runner.hpp): frame k arrives at k * period; the fusion
// thread takes the oldest waiting frame whenever it is free and spends that frame's time on it;
// a frame that finds `queue_frames` frames waiting is dropped. A frame that takes long (one that
// closes a fragment, or casts the model afresh) fills the queue, and the frames after it are
// dropped in a row, which a rate from the mean time a frame alone does not show.
//
// The replay charges a kept frame the time it took offline and a dropped one nothing; the live
// device's fragments close every so many kept frames, not at the same frames, so the figures are
// an estimate of the same kind as the mean rate, with the queue's bursts in them.
//
// Thread-safety: a pure function.

#include <cstddef>
#include <span>

namespace plumb::device {

/// Frames waiting between capture and fusion on plumb-device by default
/// (CaptureConfig::queue_frames).
inline constexpr int kDefaultCaptureQueueFrames = 4;

struct LiveRate {
    size_t frames = 0;            ///< frames the camera delivered
    size_t kept = 0;              ///< of those, tracked and fused
    size_t longest_drop_run = 0;  ///< most frames dropped one after the other
    /// Longest time from a kept frame's arrival to the end of its processing, milliseconds.
    double max_latency_ms = 0.0;
    double keptFraction() const {
        return frames == 0 ? 1.0 : static_cast<double>(kept) / static_cast<double>(frames);
    }
};

/// Replays a camera of the given frame period (milliseconds) against frames that took
/// `frame_ms` each, in order, with `queue_frames` (>= 0) frames of queue.
LiveRate replayLiveCamera(std::span<const double> frame_ms, double period_ms, int queue_frames);

}  // namespace plumb::device
