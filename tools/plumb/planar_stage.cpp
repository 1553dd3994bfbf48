// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/planar_stage.hpp"

#include <array>
#include <utility>
#include <vector>

#include "common/core/logging.hpp"

namespace plumb::tools {
namespace {

/// The right-angle step of learnPlanarTable on an estimator already fitted to `stage->estimate`:
/// the table less the offset the frames' right angles show, or the reason there is none.
void removeRightAngleOffset(const calibration::PlanarDistortionEstimator& estimator,
                            const calibration::RightAngleConfig& config,
                            const PinholeCamera& camera, PlanarStage* stage) {
    Result<calibration::RightAngleEstimate> offset =
        calibration::estimateRightAngles(estimator.framePlanes(stage->estimate.model), config);
    if (!offset.isOk()) {
        stage->right_angles_skipped = offset.status().message();
        log::warn("self-calibration: {}; the planar table is kept", offset.status().message());
        return;
    }
    const calibration::DisparityOffset& d = offset->delta;
    log::info(
        "self-calibration, right angles: disparity offset ({:.5f}, {:.5f}, {:.5f}) /m at 1 m, "
        "({:.5f}, {:.5f}, {:.5f}) /m at 3 m, from {} perpendicular and {} parallel plane pairs "
        "in {} frames; their angle residual {:.3f} -> {:.3f} deg",
        d.near.x(), d.near.y(), d.near.z(), d.far.x(), d.far.y(), d.far.z(), offset->perpendicular,
        offset->parallel, offset->frames, offset->rms_before_deg, offset->rms_after_deg);
    stage->table = calibration::removeDisparityOffset(stage->table, offset->delta, camera);
    stage->right_angles = *offset;
}

}  // namespace

Result<PlanarStage> learnPlanarTable(
    FrameSource& source, const calibration::PlanarDistortionConfig& config,
    const calibration::RightAngleConfig& right_angles,
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
    if (right_angles.enabled)
        removeRightAngleOffset(estimator, right_angles, source.camera(), &out);
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
