// SPDX-License-Identifier: Apache-2.0
// The simulated scanner as a FrameSource and as a dataset writer that drivers/dataset reads back.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>

#include "common/io/ply.hpp"
#include "common/layout/layout_json.hpp"
#include "drivers/dataset/dataset.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::sim {
namespace {

SimConfig smallConfig() {
    SimConfig c;
    c.scene = "living_room";
    c.camera = *cameraPreset("ci");
    c.trajectory.num_frames = 12;
    c.noise.distortion = DistortionKind::kParametric;  // no shared data needed
    c.seed = 5;
    return c;
}

std::string slurp(const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Warps the valid pixels of frame a into frame b with the GT poses and returns the median and
// the fraction within `tol` of |z_warped - z_b| over pixels that land on valid depth in b.
std::pair<double, double> gtWarpError(const Frame& a, const Frame& b, const PinholeCamera& cam,
                                      double tol) {
    const Eigen::Isometry3d T_b_a = b.T_W_C_gt->inverse() * *a.T_W_C_gt;
    std::vector<double> err;
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            const float z = a.depth(u, v);
            if (z <= 0.0F) continue;
            const Eigen::Vector3d p_b = T_b_a * cam.unproject(u, v, z);
            if (p_b.z() <= 0.1) continue;
            const Eigen::Vector2d px = cam.project(p_b);
            const int ub = static_cast<int>(std::lround(px.x()));
            const int vb = static_cast<int>(std::lround(px.y()));
            if (!b.depth.inside(ub, vb) || b.depth(ub, vb) <= 0.0F) continue;
            err.push_back(std::abs(p_b.z() - b.depth(ub, vb)));
        }
    }
    if (err.empty()) return {1e9, 0.0};
    std::sort(err.begin(), err.end());
    const double within =
        static_cast<double>(std::upper_bound(err.begin(), err.end(), tol) - err.begin()) /
        err.size();
    return {err[err.size() / 2], within};
}

TEST(SimSource, StreamsDeterministicFramesWithGroundTruth) {
    auto source = SimSource::create(smallConfig());
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    ASSERT_EQ((*source)->size(), 12U);
    std::vector<Frame> frames;
    while (true) {
        auto f = (*source)->next();
        if (!f.isOk()) {
            EXPECT_EQ(f.status().code(), StatusCode::kOutOfRange);
            break;
        }
        frames.push_back(std::move(f).value());
    }
    ASSERT_EQ(frames.size(), 12U);
    for (const Frame& f : frames) {
        ASSERT_TRUE(f.T_W_C_gt.has_value());
        EXPECT_EQ(f.depth.width(), 160);
        EXPECT_EQ(f.gray.width(), 160);
        EXPECT_GT(countValid(f.depth), 0.6 * 160 * 120) << f.name;
    }
    // Random access gives the same frame again.
    auto again = (*source)->render(7);
    ASSERT_TRUE(again.isOk());
    EXPECT_TRUE(again->frame.depth == frames[7].depth);
    // Consecutive frames agree under the GT poses (noisy depth: most pixels within 3 cm).
    const auto [median, within] = gtWarpError(frames[3], frames[4], (*source)->camera(), 0.03);
    EXPECT_LT(median, 0.01);
    EXPECT_GT(within, 0.9);
}

TEST(SimSource, OpensThroughTheSourceUri) {
    SourceOptions options;
    options.intrinsics = "ci";
    options.max_frames = 5;
    options.seed = 3;
    auto source = openFrameSource("sim:corridor", options);
    if (!source.isOk() && source.status().code() == StatusCode::kNotFound) {
        // The default Redwood table lives in the shared data.
        PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    }
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_EQ((*source)->size(), 5U);
    EXPECT_EQ((*source)->camera().width, 160);
    auto frame = (*source)->next();
    ASSERT_TRUE(frame.isOk());
    EXPECT_GT(countValid(frame->depth), 1000U);
    auto unknown = openFrameSource("sim:no_such_room", options);
    ASSERT_FALSE(unknown.isOk());
    EXPECT_NE(unknown.status().message().find("living_room"), std::string::npos);
}

TEST(SimDataset, SameSeedGivesByteIdenticalFiles) {
    const auto dir_a = testing::freshTempDir("sim_dataset_a");
    const auto dir_b = testing::freshTempDir("sim_dataset_b");
    SimDatasetOptions options;
    options.gt_spacing_m = 0.1;
    for (const auto& dir : {dir_a, dir_b}) {
        auto source = SimSource::create(smallConfig());
        ASSERT_TRUE(source.isOk());
        ASSERT_TRUE(writeSimDataset(**source, dir, options).isOk());
    }
    size_t files = 0;
    for (const auto& entry : std::filesystem::recursive_directory_iterator(dir_a)) {
        if (!entry.is_regular_file()) continue;
        const auto rel = std::filesystem::relative(entry.path(), dir_a);
        ASSERT_TRUE(std::filesystem::exists(dir_b / rel)) << rel;
        EXPECT_EQ(slurp(entry.path()), slurp(dir_b / rel)) << rel;
        ++files;
    }
    // 12 x (depth, depth_clean, gray) + depth.txt, groundtruth.txt, trajectory.log,
    // intrinsics.json, gt_points.ply, layout.json, sim.json.
    EXPECT_EQ(files, 12U * 3 + 7);
    // A different seed changes the noisy depth but not the clean render.
    SimConfig other = smallConfig();
    other.seed = 6;
    const auto dir_c = testing::freshTempDir("sim_dataset_c");
    auto source = SimSource::create(other);
    ASSERT_TRUE(source.isOk());
    ASSERT_TRUE(writeSimDataset(**source, dir_c, options).isOk());
    EXPECT_NE(slurp(dir_a / "depth/00003.png"), slurp(dir_c / "depth/00003.png"));
    EXPECT_EQ(slurp(dir_a / "depth_clean/00003.png"), slurp(dir_c / "depth_clean/00003.png"));
}

TEST(SimDataset, ReloadsThroughDatasetDriverAndPassesGtWarpCheck) {
    const auto dir = testing::freshTempDir("sim_dataset_reload");
    auto source = SimSource::create(smallConfig());
    ASSERT_TRUE(source.isOk());
    SimDatasetOptions options;
    options.gt_spacing_m = 0.1;
    ASSERT_TRUE(writeSimDataset(**source, dir, options).isOk());

    auto info = dataset::scanDataset(dir);
    ASSERT_TRUE(info.isOk()) << info.status().toString();
    EXPECT_EQ(info->layout, dataset::Layout::kPlumb);
    EXPECT_EQ(info->depth_scale, 1000.0);
    EXPECT_EQ(info->camera.width, 160);
    EXPECT_DOUBLE_EQ(info->camera.fx, (*source)->camera().fx);
    ASSERT_EQ(info->frames.size(), 12U);
    EXPECT_EQ(info->framesWithGroundTruth(), 12U);

    std::vector<Frame> loaded;
    for (size_t k = 0; k < info->frames.size(); ++k) {
        auto f = dataset::loadFrame(*info, k);
        ASSERT_TRUE(f.isOk()) << f.status().toString();
        auto sim = (*source)->render(k);
        ASSERT_TRUE(sim.isOk());
        // Depth round trip: millimetre PNGs.
        double worst = 0.0;
        for (size_t i = 0; i < f->depth.size(); ++i) {
            const float a = f->depth.data()[i], b = sim->frame.depth.data()[i];
            ASSERT_EQ(a > 0.0F, b > 0.0F) << "frame " << k << " pixel " << i;
            worst = std::max(worst, static_cast<double>(std::abs(a - b)));
        }
        EXPECT_LE(worst, 0.0005 + 1e-6);
        ASSERT_TRUE(f->T_W_C_gt.has_value());
        EXPECT_LT((f->T_W_C_gt->matrix() - sim->frame.T_W_C_gt->matrix()).norm(), 1e-6);
        loaded.push_back(std::move(f).value());
    }
    // The foundation's GT warp check: pairs (k, k+5), median |residual| at sensor-noise level.
    for (size_t k = 0; k + 5 < loaded.size(); ++k) {
        const auto [median, within] = gtWarpError(loaded[k], loaded[k + 5], info->camera, 0.03);
        EXPECT_LT(median, 0.02) << "frames " << k << "->" << k + 5;
        EXPECT_GT(within, 0.85) << "frames " << k << "->" << k + 5;
        std::printf("[sim dataset] warp %zu->%zu: median |dz| %.4f m, %.1f%% within 3 cm\n", k,
                    k + 5, median, 100.0 * within);
    }
    // GT layout and points read back.
    auto layout = io::readLayoutJson(dir / "layout.json");
    ASSERT_TRUE(layout.isOk()) << layout.status().toString();
    EXPECT_EQ(layout->walls().size(), 4U);
    EXPECT_DOUBLE_EQ(layout->ceiling_height_m, 2.6);
    auto points = io::readPointCloud(dir / "gt_points.ply");
    ASSERT_TRUE(points.isOk()) << points.status().toString();
    EXPECT_EQ(points->size(), sampleSurfaces((*source)->scene(), 0.1).size());
}

}  // namespace
}  // namespace plumb::sim
