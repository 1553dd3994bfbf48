// SPDX-License-Identifier: Apache-2.0
#pragma once

// The loop every program and test fixture runs around a FragmentBuilder: read a frame from a
// source, track and fuse it, hand on the fragments it closed, and at the end of the source close
// the last one (FragmentBuilder::finish). What differs between callers (stopping at a frame
// boundary, skipping unreadable frames, dropping frames, tallies, where fragments go) are hooks.
//
// Thread-safety: fuseFrames() runs on the calling thread and calls the hooks there; the source
// and the builder must not be used elsewhere meanwhile.

#include <cstdint>
#include <functional>
#include <limits>

#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"
#include "device/fusion/fragment_builder.hpp"

namespace plumb::device {

/// What fuseFrames() asks and tells its caller; any hook may be left empty.
struct FuseHooks {
    /// Asked before every read: true stops the pass at this frame boundary (no finish()).
    std::function<bool()> stop;
    /// A read error other than the end of the source (kOutOfRange): true skips the frame and
    /// goes on; false, or no hook, ends the pass with the error.
    std::function<bool(const Status& error)> skip_error;
    /// Every frame read: false drops it unfused (no hook: every frame is fused).
    std::function<bool(const Frame& frame)> keep;
    /// Every fused frame with its report, before the fragments it closed go to on_fragment; a
    /// non-ok Status ends the pass with it.
    std::function<Status(const Frame& frame, const FrameReport& report)> on_frame;
    /// Every fragment as it closes, in order, the last one from finish() included; a non-ok
    /// Status ends the pass with it.
    std::function<Status(Fragment fragment)> on_fragment;
};

/// Reads frames from `source` until it ends (kOutOfRange) or `max_frames` frames were read,
/// tracks and fuses the kept ones with `builder`, and closes the last fragment with
/// builder.finish(). True when the pass ran to its end; false when `hooks.stop` stopped it (the
/// open fragment stays open in the builder). Fails with a read error no hook skips, a failed
/// FragmentBuilder::process() or a hook's error.
Result<bool> fuseFrames(FrameSource& source, FragmentBuilder& builder, const FuseHooks& hooks,
                        uint64_t max_frames = std::numeric_limits<uint64_t>::max());

}  // namespace plumb::device
