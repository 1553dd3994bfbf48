// SPDX-License-Identifier: Apache-2.0
#pragma once

// The self-calibration's pose refinement (backend/calibration, FrameAligner) by the device's
// frame-to-model tracking: the frame, undistorted with the current table, is preprocessed into
// its pyramid (device/preprocess) and aligned by projective point-to-plane ICP to the model's
// raycast at its current pose (device/tracking/icp.hpp). A frame ICP does not align keeps its
// pose.

#include "backend/calibration/self_calibration.hpp"
#include "device/preprocess/preprocess.hpp"
#include "device/tracking/icp.hpp"

namespace plumb::tools {

struct CalibrationAlignerConfig {
    device::PreprocessConfig preprocess;
    device::IcpConfig icp;
    tsdf::RaycastConfig raycast;
};

/// The aligner; it counts the frames it could not align into `*failures` when given (which must
/// outlive it).
calibration::FrameAligner icpFrameAligner(const CalibrationAlignerConfig& config,
                                          size_t* failures = nullptr);

}  // namespace plumb::tools
