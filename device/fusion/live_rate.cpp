// SPDX-License-Identifier: Apache-2.0
#include "device/fusion/live_rate.hpp"

#include <algorithm>
#include <deque>
#include <limits>

namespace plumb::device {
namespace {

/// Times this close count as the same instant (sums of frame times against multiples of the
/// period differ in their last bits), milliseconds.
constexpr double kSameInstantMs = 1e-6;

}  // namespace

LiveRate replayLiveCamera(std::span<const double> frame_ms, double period_ms, int queue_frames) {
    LiveRate out;
    out.frames = frame_ms.size();
    const size_t capacity = static_cast<size_t>(std::max(queue_frames, 0));
    std::deque<size_t> waiting;  // frames in the queue, oldest first
    double free_at = 0.0;        // when the fusion thread finishes its current frame
    size_t drop_run = 0;
    auto start = [&](size_t k, double now) {
        free_at = now + frame_ms[k];
        out.max_latency_ms =
            std::max(out.max_latency_ms, free_at - static_cast<double>(k) * period_ms);
        ++out.kept;
    };
    // The fusion thread takes waiting frames as it becomes free, up to time `now`.
    auto serve = [&](double now) {
        while (!waiting.empty() && free_at <= now + kSameInstantMs) {
            const size_t k = waiting.front();
            waiting.pop_front();
            start(k, std::max(free_at, static_cast<double>(k) * period_ms));
        }
    };
    for (size_t k = 0; k < frame_ms.size(); ++k) {
        const double arrival = static_cast<double>(k) * period_ms;
        serve(arrival);
        if (waiting.empty() && free_at <= arrival + kSameInstantMs) {
            start(k, arrival);
            drop_run = 0;
        } else if (waiting.size() < capacity) {
            waiting.push_back(k);
            drop_run = 0;
        } else {
            out.longest_drop_run = std::max(out.longest_drop_run, ++drop_run);
        }
    }
    serve(std::numeric_limits<double>::infinity());
    return out;
}

}  // namespace plumb::device
