// SPDX-License-Identifier: Apache-2.0
#include "tests/backend/calibration/simulated_depth.hpp"

#include <gtest/gtest.h>

#include <utility>

#include "drivers/sim/noise.hpp"
#include "drivers/sim/sim_source.hpp"

namespace plumb::testing {

std::vector<DepthImage> simulateLivingRoom(const std::string& noise_mode,
                                           const std::string& table_path, size_t frames,
                                           size_t step, PinholeCamera* camera) {
    sim::SimConfig config;
    config.scene = "living_room";
    config.camera = cameraPreset("primesense").value();
    config.trajectory.num_frames = frames;
    config.noise_model_path = table_path;
    EXPECT_TRUE(sim::parseNoiseMode(noise_mode, &config.noise).isOk());
    auto source = sim::SimSource::create(config);
    EXPECT_TRUE(source.isOk()) << source.status().toString();
    std::vector<DepthImage> depth;
    if (!source.isOk()) return depth;
    *camera = (*source)->camera();
    for (size_t k = 0; k < frames; ++k) {
        Result<Frame> f = (*source)->next();
        EXPECT_TRUE(f.isOk()) << f.status().toString();
        if (!f.isOk()) break;
        if (k % step == 0) depth.push_back(std::move(f->depth));
    }
    return depth;
}

}  // namespace plumb::testing
