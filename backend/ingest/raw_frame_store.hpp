// SPDX-License-Identifier: Apache-2.0
#pragma once

// The raw frames a device streams (depth_frame3_t on PLUMB_RGBD3; depth_frame2_t on PLUMB_RGBD
// and depth_frame_t on PLUMB_DEPTH from older devices; plumb-device's stream.raw_frame_every),
// kept beside the fragment store so that the final model can re-integrate the frames themselves
// instead of the fragments' surfaces:
//  - RawFrameStore writes each frame's message as it arrived to
//    `<dir>/<utime>_<index>_s<session>.raw`, or `<dir>/<utime>_<index>.raw` for a message that
//    names no session (a temporary file renamed into place, not fsync'ed: raw frames are never
//    acknowledged, and one lost to a crash only leaves its frame to the fragment surfaces);
//  - rawFrameCoverage() matches them with the frames of a session's fragments (the session when
//    the frame names one, frame index and capture time, so that frames of other sessions never
//    mix in) and says how well they cover each fragment; openRawFrameSource() reads the matches
//    in capture order (the final model's source; backend/ingest/stored_scan.hpp opens a
//    session's frames as a scan of their own).
//
// Thread-safety: a RawFrameStore is used by one thread (the ingest's); the FrameSource is a
// FrameSource (one consumer).

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "common/frame/frame_source.hpp"

namespace plumb::backend {

/// Where the ingest keeps the raw frames of the fragment store in `fragments_dir`.
std::filesystem::path rawFramesDir(const std::filesystem::path& fragments_dir);

/// One stored raw frame.
struct StoredRawFrame {
    int64_t utime = 0;        ///< capture time, microseconds
    int64_t frame_index = 0;  ///< index in the capture stream
    std::filesystem::path path;
    std::optional<int64_t> session_id;  ///< the device session, when the message named it
};

class RawFrameStore {
  public:
    /// Opens (creating) `dir`; temporary files of an interrupted write are removed.
    /// IoError names the directory.
    static Result<std::unique_ptr<RawFrameStore>> open(const std::filesystem::path& dir);

    /// Writes one raw frame's message bytes (as received), of session `session_id` when the
    /// message names one; the same frame again replaces it. IoError (e.g. a full disk) names the
    /// file; nothing is left half written under its name.
    Status put(int64_t utime, int64_t frame_index, std::span<const uint8_t> message_bytes,
               std::optional<int64_t> session_id = std::nullopt);

    const std::filesystem::path& dir() const { return dir_; }

  private:
    explicit RawFrameStore(std::filesystem::path dir) : dir_(std::move(dir)) {}
    std::filesystem::path dir_;
};

/// Every raw frame file in `dir`, by capture time, index, then session (an absent directory
/// holds none).
/// Files that are not named as RawFrameStore names them are ignored. IoError when the
/// directory cannot be listed.
Result<std::vector<StoredRawFrame>> listRawFrames(const std::filesystem::path& dir);

/// How the stored raw frames cover the frames of a session's fragments.
struct RawFrameCoverage {
    size_t tracked_frames = 0;  ///< frames of the fragments whose tracking succeeded
    size_t matched = 0;         ///< of these, with a raw frame (same index and capture time)
    /// The smallest share of a fragment's tracked frames that have a raw frame (0 without
    /// fragments), and the fragment it belongs to.
    double min_fragment_share = 0.0;
    uint32_t min_fragment_id = 0;
    std::vector<StoredRawFrame> frames;  ///< the matched frames, in capture order
    /// The most common step between the frame indices of consecutive matched frames: the
    /// device's stream.raw_frame_every when it streamed every k-th frame (1 with fewer than
    /// two frames).
    int64_t stride = 1;
};

/// Matches `stored` with the tracked frames of `fragments`, which are of session `session_id`
/// (when given): a raw frame of another session is never matched; one that names no session
/// matches by frame index and capture time (within a millisecond), as do the others.
RawFrameCoverage rawFrameCoverage(const std::vector<StoredRawFrame>& stored,
                                  const std::vector<Fragment>& fragments,
                                  std::optional<int64_t> session_id = std::nullopt);

/// How openRawFrameSource presents the frames.
struct RawFrameView {
    /// Frame::index is the frame's position among the source's frames instead of its capture
    /// index (Frame::name then says the capture index).
    bool renumber = false;
    bool colour = true;       ///< false: colour dropped
    std::string description;  ///< empty: "N stored raw frames (WxH)"
};

/// A FrameSource over `frames` (e.g. RawFrameCoverage::frames) as `camera` sees them: depth in
/// metres, colour when the frame carries it, Frame::index the capture index (unless `view` says
/// otherwise). A file that no longer reads or decodes, or whose size is not the camera's, is
/// skipped with a warning. A few frames are read and decoded ahead, each on a thread of its
/// own; the frames come out in order. `stop_requested` (may be empty) is asked before every
/// frame; when it returns true next() returns kCancelled.
std::unique_ptr<FrameSource> openRawFrameSource(std::vector<StoredRawFrame> frames,
                                                const PinholeCamera& camera,
                                                std::function<bool()> stop_requested = {},
                                                RawFrameView view = {});

}  // namespace plumb::backend
