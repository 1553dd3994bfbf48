// SPDX-License-Identifier: Apache-2.0
#pragma once

// The raw depth of a simulated scan, for the calibration tests that need frames but no poses.

#include <string>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/image/image.hpp"

namespace plumb::testing {

/// Every `step`-th of `frames` frames of a simulated living_room scan at 640x480 (primesense),
/// raw depth with the simulator's noise mode `noise_mode` and distortion table `table_path`;
/// `camera` receives the scan's camera. Test failures are recorded for a source that fails.
std::vector<DepthImage> simulateLivingRoom(const std::string& noise_mode,
                                           const std::string& table_path, size_t frames,
                                           size_t step, PinholeCamera* camera);

}  // namespace plumb::testing
