// SPDX-License-Identifier: Apache-2.0
#include "tests/backend/calibration/simulated_depth.hpp"

#include <gtest/gtest.h>

#include <utility>

#include "drivers/sim/noise.hpp"
#include "drivers/sim/sim_source.hpp"

namespace plumb::testing {

SimulatedScan simulateLivingRoomScan(const std::string& camera_preset,
                                     const std::string& noise_mode, const std::string& table_path,
                                     size_t frames, size_t step) {
    sim::SimConfig config;
    config.scene = "living_room";
    config.camera = cameraPreset(camera_preset).value();
    config.trajectory.num_frames = frames;
    config.noise_model_path = table_path;
    EXPECT_TRUE(sim::parseNoiseMode(noise_mode, &config.noise).isOk());
    auto source = sim::SimSource::create(config);
    EXPECT_TRUE(source.isOk()) << source.status().toString();
    SimulatedScan scan;
    if (!source.isOk()) return scan;
    scan.camera = (*source)->camera();
    for (size_t k = 0; k < frames; ++k) {
        Result<Frame> f = (*source)->next();
        EXPECT_TRUE(f.isOk()) << f.status().toString();
        if (!f.isOk()) break;
        if (k % step != 0) continue;
        EXPECT_TRUE(f->T_W_C_gt.has_value());
        scan.depth.push_back(std::move(f->depth));
        scan.T_W_C.push_back(f->T_W_C_gt.value_or(Eigen::Isometry3d::Identity()));
    }
    return scan;
}

std::vector<DepthImage> simulateLivingRoom(const std::string& noise_mode,
                                           const std::string& table_path, size_t frames,
                                           size_t step, PinholeCamera* camera) {
    SimulatedScan scan = simulateLivingRoomScan("primesense", noise_mode, table_path, frames, step);
    *camera = scan.camera;
    return std::move(scan.depth);
}

}  // namespace plumb::testing
