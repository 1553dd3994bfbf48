// SPDX-License-Identifier: Apache-2.0
// Self-calibration with poses from plumb's own tracking (device FragmentBuilder), re-run on the
// undistorted frames at every step of the alternation (reference §7c).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "backend/calibration/self_calibration.hpp"
#include "device/fusion/fragment_builder.hpp"
#include "drivers/sim/sim_source.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::calibration {
namespace {

using Table = DistortionTable;

/// Median over the cells covered in `bin` of |learnt / scale - true| with one scale (the median
/// ratio over both near bins), and of |1 - true| (no calibration).
std::pair<double, double> tableError(const DistortionEstimate& e, const Table& learnt,
                                     const Table& truth, int bin) {
    Result<TableComparison> c = compareTables(learnt, e, truth);
    if (!c.isOk()) return {1.0, 1.0};
    const TableComparison::Bin& b = c->bins[static_cast<size_t>(bin)];
    return {b.median_error, b.median_uncalibrated};
}

TEST(SelfCalibration, WithPosesFromOwnTrackingTheFarBinImprovesOnNoCalibration) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    sim::SimConfig sim_config;
    sim_config.camera = cameraPreset("ci").value();
    sim_config.trajectory.num_frames = 300;
    sim_config.noise_model_path = path.string();
    auto source = sim::SimSource::create(sim_config);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    std::vector<DepthImage> raw;
    for (size_t k = 0; k < sim_config.trajectory.num_frames; ++k) {
        Result<Frame> f = (*source)->next();
        ASSERT_TRUE(f.isOk()) << f.status().toString();
        raw.push_back(std::move(f->depth));
    }
    const PinholeCamera camera = (*source)->camera();
    auto truth = Table::load(path);
    ASSERT_TRUE(truth.isOk());

    // Frame-to-model tracking over the whole scan in one fragment, from the undistorted frames.
    device::FusionConfig fusion;
    fusion.frames_per_fragment = 100000;
    fusion.tsdf.voxel_size_m = 0.01F;
    int runs = 0;
    const PoseProvider track =
        [&](const std::vector<DepthImage>& depth) -> Result<std::vector<Eigen::Isometry3d>> {
        device::FragmentBuilder builder(camera, fusion);
        std::vector<Eigen::Isometry3d> poses;
        int lost = 0;
        for (size_t k = 0; k < depth.size(); ++k) {
            Frame frame;
            frame.index = static_cast<int64_t>(k);
            frame.timestamp_s = static_cast<double>(k) / 30.0;
            frame.depth = depth[k];
            Result<device::FrameReport> r = builder.process(frame);
            if (!r.isOk()) return r.status();
            lost += r->tracked ? 0 : 1;
            poses.push_back(r->T_W_C);
        }
        std::printf("  tracking run %d: %d of %zu frames not tracked\n", ++runs, lost,
                    depth.size());
        return poses;
    };
    SelfCalibrationConfig config;
    config.max_iterations = 4;
    const Table* truth_table = &*truth;
    auto result =
        selfCalibrate(raw, camera, track, config, nullptr, [&](const CalibrationIteration& it) {
            const auto [e0, n0] = tableError(it.estimate, it.estimate.table, *truth_table, 0);
            const auto [e1, n1] = tableError(it.estimate, it.estimate.table, *truth_table, 1);
            std::printf(
                "  iteration %d: change median %.5f; median |learned - "
                "true| 1 m %.4f %% (none %.4f %%), 3 m %.4f %% (none "
                "%.4f %%); cells %d %d\n",
                it.iteration, it.estimate.median_change, 100 * e0, 100 * n0, 100 * e1, 100 * n1,
                it.estimate.covered_cells[0], it.estimate.covered_cells[1]);
        });
    ASSERT_TRUE(result.isOk()) << result.status().toString();
    const DistortionEstimate& last = result->iterations.back().estimate;
    EXPECT_EQ(runs, static_cast<int>(result->iterations.size()));  // re-tracked every step
    // Tracking from the frames themselves absorbs part of the distortion into the poses: at 3 m
    // the learnt table removes a quarter of the distortion or more, though not yet the 1 m bin's.
    const auto [e1, n1] = tableError(last, result->table, *truth, 1);
    EXPECT_LT(e1, 0.75 * n1);
}

}  // namespace
}  // namespace plumb::calibration
