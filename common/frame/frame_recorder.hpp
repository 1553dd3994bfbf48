// SPDX-License-Identifier: Apache-2.0
#pragma once

// Keeping a scan's frames in memory for a second pass. `plumb reconstruct` reads every raw frame
// twice: once to track and fuse it, once to re-integrate it at the optimised poses (the final
// model). A read decodes two images of a dataset or renders a simulated frame; a FrameRecorder
// around the first pass keeps what it yields, up to a byte budget, and a ReplaySource gives the
// same frames, in the same order, to the second pass without reading them again.
//
// Thread-safety: neither class is thread-safe (one consumer calls next() at a time, as for every
// FrameSource). Replay sources made from the same kept frames may run concurrently: the frames
// are shared read-only.

#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/frame/frame_source.hpp"

namespace plumb {

/// Bytes a frame holds in memory (its images and name).
size_t frameBytes(const Frame& frame);

/// Passes every call through to `inner` (not owned; it must outlive the recorder) and keeps a
/// copy of each frame next() yields while the kept frames stay within `budget_bytes`. Wrap the
/// source before its first frame is read.
class FrameRecorder : public FrameSource {
  public:
    FrameRecorder(FrameSource& inner, size_t budget_bytes);

    const PinholeCamera& camera() const override { return inner_.camera(); }
    /// The inner source's next frame; a copy is kept while complete() can still hold. An error
    /// other than the end of the stream drops the kept frames (the stream has a gap).
    Result<Frame> next() override;
    /// A skipped frame cannot be replayed: drops the kept frames.
    Status skip() override;
    std::optional<size_t> size() const override { return inner_.size(); }
    bool canSkipErrors() const override { return inner_.canSkipErrors(); }
    std::string description() const override { return inner_.description(); }
    const FrameSource& underlying() const override { return inner_.underlying(); }
    void cameraArrived() override { inner_.cameraArrived(); }

    /// True when every frame of the stream, from its first to its end (next() returned
    /// kOutOfRange), is kept: nothing skipped, no error, within the budget.
    bool complete() const { return ended_ && !dropped_; }
    /// Why the frames are not all kept ("" while they are): for the log.
    const std::string& droppedBecause() const { return dropped_because_; }
    /// Bytes of the kept frames.
    size_t bytes() const { return bytes_; }

    /// The kept frames, moved out of the recorder; nullptr unless complete().
    std::shared_ptr<const std::vector<Frame>> take();

  private:
    void drop(std::string why);

    FrameSource& inner_;
    size_t budget_bytes_;
    std::vector<Frame> frames_;
    size_t bytes_ = 0;
    bool ended_ = false;
    bool dropped_ = false;
    std::string dropped_because_;
};

/// The frames a FrameRecorder kept, yielded again in order (copies: the kept frames stay intact
/// for further replays), as a source with the recorded source's camera.
class ReplaySource : public FrameSource {
  public:
    /// `description` names what was recorded, for logs.
    ReplaySource(std::shared_ptr<const std::vector<Frame>> frames, const PinholeCamera& camera,
                 std::string description);

    const PinholeCamera& camera() const override { return camera_; }
    Result<Frame> next() override;
    Status skip() override;
    std::optional<size_t> size() const override { return frames_->size(); }
    std::string description() const override { return description_; }

  private:
    std::shared_ptr<const std::vector<Frame>> frames_;
    PinholeCamera camera_;
    std::string description_;
    size_t position_ = 0;
};

}  // namespace plumb
