// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/planar_stage.hpp"

#include <array>
#include <utility>
#include <vector>

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

DistortionTable composeTables(const DistortionTable& first, const DistortionTable& then) {
    constexpr int n = DistortionTable::kCellsPerSide;
    std::vector<std::array<float, 5>> cells(static_cast<size_t>(n) * n);
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) {
            std::array<float, 5>& c = cells[static_cast<size_t>(y) * n + x];
            for (size_t b = 0; b < c.size(); ++b) c[b] = first.cell(x, y)[b] * then.cell(x, y)[b];
        }
    }
    return DistortionTable::fromCells(std::move(cells));
}

}  // namespace plumb::tools
