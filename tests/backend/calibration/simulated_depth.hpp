// SPDX-License-Identifier: Apache-2.0
#pragma once

// The raw depth of a simulated scan and its true poses, for the calibration tests.

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/image/image.hpp"

namespace plumb::testing {

/// A simulated scan: its camera, raw depth and ground-truth poses T_W_C.
struct SimulatedScan {
    PinholeCamera camera;
    std::vector<DepthImage> depth;
    std::vector<Eigen::Isometry3d> T_W_C;
};

/// Every `step`-th of `frames` frames of a simulated living_room scan with the camera preset
/// `camera_preset` ("primesense": 640x480, "ci": 160x120), raw depth with the simulator's noise
/// mode `noise_mode` and distortion table `table_path`, and their poses. Test failures are
/// recorded for a source that fails or a frame without a pose.
SimulatedScan simulateLivingRoomScan(const std::string& camera_preset,
                                     const std::string& noise_mode, const std::string& table_path,
                                     size_t frames, size_t step = 1);

/// Every `step`-th of `frames` frames of a simulated living_room scan at 640x480 (primesense),
/// raw depth with the simulator's noise mode `noise_mode` and distortion table `table_path`;
/// `camera` receives the scan's camera. Test failures are recorded for a source that fails.
std::vector<DepthImage> simulateLivingRoom(const std::string& noise_mode,
                                           const std::string& table_path, size_t frames,
                                           size_t step, PinholeCamera* camera);

}  // namespace plumb::testing
