// SPDX-License-Identifier: Apache-2.0
#pragma once

// The raw frames plumb-backend kept of one session of its fragment store
// (backend/ingest/raw_frame_store.hpp), opened as a scan to process again on a workstation:
// `plumb reconstruct store:DIR`, `plumb fuse`, `plumb calibrate`.
//
// Thread-safety: openStoredScan keeps no state; the source is a FrameSource (one consumer).

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "common/camera/pinhole.hpp"
#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"

namespace plumb::backend {

/// The raw frames of one session of a fragment store, opened as a scan to process again on a
/// workstation (`plumb reconstruct store:DIR`, `plumb fuse`, `plumb calibrate`): every raw frame
/// kept whose capture time lies within the session's (its fragments' first and last frames, a
/// second either side), in capture order, numbered 0, 1, ... (Frame::name keeps the capture
/// index).
struct StoredScanOptions {
    std::optional<int64_t> session;  ///< none: the newest session in the store
    size_t max_frames = 0;           ///< 0 = all
    bool colour = true;              ///< false: the frames' colour is dropped
    /// The camera; none: the camera_info.json the ingest wrote beside the store (its parent
    /// directory) or inside it.
    std::optional<PinholeCamera> camera;
};

struct StoredScan {
    std::unique_ptr<FrameSource> source;
    int64_t session = 0;
    size_t frames = 0;  ///< raw frames of the session
    /// How they cover the frames of the session's fragments (frames the device tracked).
    size_t fragment_frames = 0;
    size_t fragment_frames_with_raw = 0;
    /// A warning for the user, empty when there is none: the store's other sessions, or frames
    /// of the session without a raw frame.
    std::string note;
};

/// NotFound: no store at `fragments_dir`, no fragment of the session, or no raw frame of it
/// (the message says how a device streams them); as readCameraInfo without a camera.
Result<StoredScan> openStoredScan(const std::filesystem::path& fragments_dir,
                                  const StoredScanOptions& options);

}  // namespace plumb::backend
