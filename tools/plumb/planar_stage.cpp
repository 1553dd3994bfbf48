// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/planar_stage.hpp"

#include <utility>

namespace plumb::tools {

Result<PlanarStage> learnPlanarTable(
    FrameSource& source, const calibration::PlanarDistortionConfig& config,
    const std::function<void(const calibration::PlanarIteration&)>& observer) {
    calibration::PlanarDistortionEstimator estimator(source.camera(), config);
    PlanarStage out;
    for (;;) {
        Result<Frame> frame = source.next();
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            return frame.status();
        }
        ++out.frames_read;
        if (Status s = estimator.addFrame(frame->depth); !s.isOk()) return s;
    }
    Result<calibration::PlanarEstimate> estimate = estimator.estimate(observer);
    if (!estimate.isOk()) return estimate.status();
    out.estimate = std::move(*estimate);
    out.table = out.estimate.model.toTable();
    return out;
}

}  // namespace plumb::tools
