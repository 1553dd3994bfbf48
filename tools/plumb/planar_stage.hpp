// SPDX-License-Identifier: Apache-2.0
#pragma once

// The first stage of self-calibration in `plumb calibrate` and `plumb reconstruct
// --self-calibrate`: the smooth bend of the depth, learned from the planes every frame sees
// (backend/calibration/planar_distortion.hpp), with no pose.

#include <functional>
#include <optional>
#include <string>

#include "backend/calibration/planar_distortion.hpp"
#include "backend/calibration/right_angles.hpp"
#include "common/calibration/distortion_table.hpp"
#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"

namespace plumb::tools {

struct PlanarStage {
    calibration::PlanarEstimate estimate;
    /// The planar model's table, less the right angles' offset when that stage ran and held.
    DistortionTable table = DistortionTable::neutral();
    size_t frames_read = 0;
    /// The right angles' offset removed from the table (right_angles.enabled), ...
    std::optional<calibration::RightAngleEstimate> right_angles;
    /// ... or why none was (empty when the stage was off).
    std::string right_angles_skipped;
};

/// Reads `source` (its raw depth) to its end and fits the planar model to its frames
/// (every config.frame_step-th); with right_angles.enabled, then removes the disparity offset
/// the right angles between the planes of the frames corrected by that model show (a scan
/// whose pairs do not determine it keeps the planar table, and the reason is kept). Errors: a
/// frame error other than the end of the stream, and those of
/// PlanarDistortionEstimator::estimate (no planar segment in any frame).
Result<PlanarStage> learnPlanarTable(
    FrameSource& source, const calibration::PlanarDistortionConfig& config,
    const calibration::RightAngleConfig& right_angles,
    const std::function<void(const calibration::PlanarIteration&)>& observer = {});

/// The table that undistorts as `first` followed by `then`: per cell and bin the product of
/// their factors (z_true = f_then * (f_first * z_raw), the bin of both taken at the same depth);
/// a cell invalid in either is invalid.
DistortionTable composeTables(const DistortionTable& first, const DistortionTable& then);

}  // namespace plumb::tools
