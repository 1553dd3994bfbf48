// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/scan_cache.hpp"

#include <utility>

#include "common/calibration/depth_calibration.hpp"
#include "common/frame/frame_recorder.hpp"
#include "drivers/calibrated_source.hpp"
#include "tools/plumb/scan_source.hpp"

namespace plumb::tools {

Result<ScanCache> ScanCache::read(FrameSource& raw, const std::string& uri,
                                  const SourceOptions& raw_options, size_t budget_bytes,
                                  const std::function<bool()>& stop_requested) {
    ScanCache cache;
    cache.uri_ = uri;
    cache.raw_options_ = raw_options;
    cache.camera_ = raw.camera();
    cache.description_ = raw.description();
    FrameRecorder recorder(raw, budget_bytes);
    while (recorder.droppedBecause().empty()) {
        if (stop_requested && stop_requested()) return cancelled("while reading the scan");
        const Result<Frame> frame = recorder.next();
        if (!frame.isOk()) break;  // the end, or an error the passes will meet again
    }
    cache.frames_ = recorder.take();
    if (!cache.frames_) cache.not_kept_because_ = recorder.droppedBecause();
    return cache;
}

Result<std::unique_ptr<FrameSource>> ScanCache::open(const std::string& depth_calibration,
                                                     bool colour) const {
    if (!frames_) {
        SourceOptions options = raw_options_;
        options.depth_calibration = depth_calibration;
        options.colour = options.colour && colour;
        return openScanSource(uri_, options);
    }
    auto replay = std::make_unique<ReplaySource>(frames_, camera_, description_);
    if (depth_calibration == "none") return std::unique_ptr<FrameSource>(std::move(replay));
    Result<DepthCalibration> calibration = DepthCalibration::load(depth_calibration);
    if (!calibration.isOk()) return calibration.status();
    return std::unique_ptr<FrameSource>(
        std::make_unique<CalibratedSource>(std::move(replay), std::move(*calibration)));
}

}  // namespace plumb::tools
