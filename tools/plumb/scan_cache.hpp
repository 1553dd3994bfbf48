// SPDX-License-Identifier: Apache-2.0
#pragma once

// The raw frames of a scan read once for the several passes of `plumb reconstruct
// --self-calibrate` (the planar stages, the first reconstruction, the estimate at its poses, the
// final reconstruction), each of which undistorts the depth with its own table. Every pass
// replays the kept raw frames through that table instead of reading (decoding, rendering) the
// scan again; the frames are the same either way, so the results are too. A scan that does not
// fit the memory set aside, or whose read fails, is read again by each pass as before.
//
// Thread-safety: a ScanCache is not thread-safe while it reads; afterwards open() may run
// concurrently (the kept frames are shared read-only).

#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"
#include "drivers/source.hpp"

namespace plumb::tools {

class ScanCache {
  public:
    /// Reads `raw` (opened from `uri` with `raw_options`, whose depth_calibration is "none") to
    /// its end and keeps its frames while they fit in `budget_bytes` (it stops reading as soon
    /// as they do not). `stop_requested` is polled between frames: kCancelled when it returns
    /// true. Frame errors are not errors here: the passes read the scan again and meet them.
    static Result<ScanCache> read(FrameSource& raw, const std::string& uri,
                                  const SourceOptions& raw_options, size_t budget_bytes,
                                  const std::function<bool()>& stop_requested);

    /// A pass over the scan with its depth undistorted by `depth_calibration` ("none" or a
    /// dist-model.txt file): the kept frames replayed (with their colour), or the source opened
    /// again (with colour when `colour` and the scan has it).
    Result<std::unique_ptr<FrameSource>> open(const std::string& depth_calibration,
                                              bool colour = true) const;

    /// True when every frame is kept; else why not (for the log).
    bool complete() const { return frames_ != nullptr; }
    const std::string& notKeptBecause() const { return not_kept_because_; }
    size_t frames() const { return frames_ ? frames_->size() : 0; }

  private:
    std::string uri_;
    SourceOptions raw_options_;
    PinholeCamera camera_;
    std::string description_;
    std::shared_ptr<const std::vector<Frame>> frames_;
    std::string not_kept_because_;
};

}  // namespace plumb::tools
