// SPDX-License-Identifier: Apache-2.0
// The simulated scanner as a FrameSource and as a dataset writer that drivers/dataset reads back.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>

#include "common/io/ply.hpp"
#include "common/io/trajectory.hpp"
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

struct WarpCheck {
    double median_abs_m = 1e9;     ///< median |z_warped - z_b|
    double median_signed_m = 1e9;  ///< median z_warped - z_b (bias)
    double within = 0.0;           ///< fraction of compared pixels with |residual| <= tol
    size_t compared = 0;           ///< pixels that landed on valid depth in b
    size_t source_valid = 0;       ///< valid pixels of a
};

// The foundation's GT warp check (tests/drivers/dataset_warp_test.cpp): warps the valid pixels of
// frame a into frame b with the GT poses, T_b_a = T_W_b^-1 T_W_a, and compares z with b's depth
// at the nearest pixel.
WarpCheck gtWarpCheck(const Frame& a, const Frame& b, const PinholeCamera& cam, double tol) {
    const Eigen::Isometry3d T_b_a = b.T_W_C_gt->inverse() * *a.T_W_C_gt;
    std::vector<double> err, signed_err;
    WarpCheck out;
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            const float z = a.depth(u, v);
            if (z <= 0.0F) continue;
            ++out.source_valid;
            const Eigen::Vector3d p_b = T_b_a * cam.unproject(u, v, z);
            if (p_b.z() <= 0.1) continue;
            const Eigen::Vector2d px = cam.project(p_b);
            const int ub = static_cast<int>(std::lround(px.x()));
            const int vb = static_cast<int>(std::lround(px.y()));
            if (!b.depth.inside(ub, vb) || b.depth(ub, vb) <= 0.0F) continue;
            err.push_back(std::abs(p_b.z() - b.depth(ub, vb)));
            signed_err.push_back(p_b.z() - b.depth(ub, vb));
        }
    }
    out.compared = err.size();
    if (err.empty()) return out;
    std::sort(err.begin(), err.end());
    std::sort(signed_err.begin(), signed_err.end());
    out.within = static_cast<double>(std::upper_bound(err.begin(), err.end(), tol) - err.begin()) /
                 err.size();
    out.median_abs_m = err[err.size() / 2];
    out.median_signed_m = signed_err[signed_err.size() / 2];
    return out;
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
        // Views through the open door or at corners beyond the 4 m range leave up to half of the
        // pixels without depth.
        EXPECT_GT(countValid(f.depth), 0.5 * 160 * 120) << f.name;
    }
    // Random access gives the same frame again.
    auto again = (*source)->render(7);
    ASSERT_TRUE(again.isOk());
    EXPECT_TRUE(again->frame.depth == frames[7].depth);
    // Consecutive frames agree under the GT poses. The views reach 2-3.5 m, where disparity
    // steps are 14-44 mm and the parametric distortion up to 2 % towards the corners: the
    // median is about 1 cm, and most pixels are within 4 cm.
    const WarpCheck w = gtWarpCheck(frames[3], frames[4], (*source)->camera(), 0.04);
    EXPECT_LT(w.median_abs_m, 0.015);
    EXPECT_GT(w.within, 0.9);
}

TEST(SimSource, SkipPassesOverAFrameWithoutChangingTheOthers) {
    auto plain = SimSource::create(smallConfig());
    auto skipping = SimSource::create(smallConfig());
    ASSERT_TRUE(plain.isOk() && skipping.isOk());
    for (size_t k = 0; k < 12; ++k) {
        auto f = (*plain)->next();
        ASSERT_TRUE(f.isOk()) << f.status().toString();
        if (k % 3 != 0) {
            EXPECT_TRUE((*skipping)->skip().isOk()) << k;
            continue;
        }
        auto g = (*skipping)->next();
        ASSERT_TRUE(g.isOk()) << g.status().toString();
        EXPECT_EQ(g->index, f->index);
        EXPECT_TRUE(g->depth == f->depth) << k;
        EXPECT_TRUE(g->colour == f->colour) << k;
    }
    EXPECT_EQ((*skipping)->skip().code(), StatusCode::kOutOfRange);
    EXPECT_EQ((*skipping)->next().status().code(), StatusCode::kOutOfRange);
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
    // 12 x (depth, depth_clean, gray, rgb) + depth.txt, rgb.txt, groundtruth.txt,
    // trajectory.log, intrinsics.json, gt_points.ply, layout.json, sim.json.
    EXPECT_EQ(files, 12U * 4 + 8);
    // A different seed changes the noisy depth but not the clean render.
    SimConfig other = smallConfig();
    other.seed = 6;
    const auto dir_c = testing::freshTempDir("sim_dataset_c");
    auto source = SimSource::create(other);
    ASSERT_TRUE(source.isOk());
    ASSERT_TRUE(writeSimDataset(**source, dir_c, options).isOk());
    EXPECT_NE(slurp(dir_a / "depth/00003.png"), slurp(dir_c / "depth/00003.png"));
    EXPECT_EQ(slurp(dir_a / "depth_clean/00003.png"), slurp(dir_c / "depth_clean/00003.png"));
    EXPECT_NE(slurp(dir_a / "rgb/00003.png"), slurp(dir_c / "rgb/00003.png"));
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
    // The foundation's GT warp check: pairs (k, k+5), median |residual| at sensor-noise level
    // (< 2 cm), unbiased (|signed median| < 5 mm), over more than half of the valid pixels.
    for (size_t k = 0; k + 5 < loaded.size(); ++k) {
        const WarpCheck w = gtWarpCheck(loaded[k], loaded[k + 5], info->camera, 0.03);
        EXPECT_LT(w.median_abs_m, 0.02) << "frames " << k << "->" << k + 5;
        EXPECT_LT(std::abs(w.median_signed_m), 0.005) << "frames " << k << "->" << k + 5;
        EXPECT_GT(w.compared, w.source_valid / 2) << "frames " << k << "->" << k + 5;
        EXPECT_GT(w.within, 0.85) << "frames " << k << "->" << k + 5;
        std::printf(
            "[sim dataset] warp %zu->%zu: median |dz| %.4f m (signed %+.4f m), %.1f%% within "
            "3 cm, %zu of %zu pixels compared\n",
            k, k + 5, w.median_abs_m, w.median_signed_m, 100.0 * w.within, w.compared,
            w.source_valid);
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

TEST(SimSource, FollowsATrajectoryFileAndRejectsPosesOutsideTheRoom) {
    // Write a generated no-loop path as TUM, then render from the file: same poses, same frames.
    SimConfig generated = smallConfig();
    generated.trajectory.loop = false;
    auto reference = SimSource::create(generated);
    ASSERT_TRUE(reference.isOk());
    const auto dir = testing::freshTempDir("sim_trajectory_file");
    ASSERT_TRUE(io::writeTumTrajectory(dir / "path.txt", (*reference)->trajectory()).isOk());

    SimConfig from_file = smallConfig();
    from_file.trajectory_file = (dir / "path.txt").string();
    from_file.trajectory.num_frames = 8;  // truncates the file's 12 poses
    auto source = SimSource::create(from_file);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    ASSERT_EQ((*source)->size(), 8U);
    for (size_t k = 0; k < 8; ++k) {
        const auto& a = (*source)->trajectory()[k];
        const auto& b = (*reference)->trajectory()[k];
        EXPECT_NEAR(a.timestamp_s, b.timestamp_s, 1e-9);
        EXPECT_LT((a.T_W_C.matrix() - b.T_W_C.matrix()).norm(), 1e-9) << k;
    }
    auto a = (*source)->render(5);
    auto b = (*reference)->render(5);
    ASSERT_TRUE(a.isOk() && b.isOk());
    EXPECT_TRUE(a->view.label == b->view.label);
    EXPECT_NE((*source)->description().find("path.txt"), std::string::npos);

    // A pose outside the room is an error that names the file and the pose.
    std::ofstream(dir / "outside.txt") << "0 1 1 1.4 0 0 0 1\n0.033 1 1 9.0 0 0 0 1\n";
    from_file.trajectory_file = (dir / "outside.txt").string();
    auto outside = SimSource::create(from_file);
    ASSERT_FALSE(outside.isOk());
    EXPECT_NE(outside.status().message().find("pose 1"), std::string::npos)
        << outside.status().message();
    EXPECT_NE(outside.status().message().find("outside.txt"), std::string::npos);
    from_file.trajectory_file = (dir / "missing.txt").string();
    EXPECT_FALSE(SimSource::create(from_file).isOk());
}

}  // namespace
}  // namespace plumb::sim
