// SPDX-License-Identifier: Apache-2.0
// Layout estimation on real data fused with ground-truth poses: ICL-NUIM office kt0 (floor,
// ceiling and the visible walls at right angles) and TUM fr3 structure_notexture_far (the floor
// is the base plane).

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "backend/layout/estimate_layout.hpp"
#include "backend/layout/fragment_planes.hpp"
#include "drivers/dataset/dataset.hpp"
#include "tests/backend/layout/layout_fixtures.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::layout {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

double angleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) / kDeg;
}

/// Distance of an angle from the nearest of 0, 90, 180 degrees.
double offRightAngleDeg(double angle) {
    return std::min({std::abs(angle), std::abs(angle - 90.0), std::abs(angle - 180.0)});
}

struct RealRun {
    std::vector<Fragment> fragments;
    std::vector<Eigen::Isometry3d> T_W_F;
    std::vector<FragmentPlanes> planes;
};

RealRun fuseDataset(const std::filesystem::path& dir, size_t step, int frames_per_fragment,
                    float max_depth_m) {
    RealRun run;
    auto info = dataset::scanDataset(dir);
    EXPECT_TRUE(info.isOk()) << info.status().toString();
    if (!info.isOk()) return run;
    auto fused = testing::fuseWithGroundTruth(
        [&](size_t k) { return dataset::loadFrame(*info, k); }, info->frames.size(), step,
        frames_per_fragment, info->camera, 0.02f, max_depth_m);
    EXPECT_TRUE(fused.isOk()) << fused.status().toString();
    if (!fused.isOk()) return run;
    run.fragments = std::move(fused->fragments);
    run.T_W_F = std::move(fused->T_W_F);
    for (const Fragment& f : run.fragments) {
        auto fp = extractFragmentPlanes(f);
        EXPECT_TRUE(fp.isOk()) << fp.status().toString();
        if (fp.isOk()) run.planes.push_back(std::move(fp).value());
    }
    return run;
}

TEST(RealLayout, IclNuimOfficeFloorCeilingAndRightAngledWalls) {
    PLUMB_REQUIRE_SHARED_DATA(path, "icl-nuim-office-kt0");
    const RealRun run = fuseDataset(path, 1, 25, 5.0f);
    ASSERT_EQ(run.planes.size(), run.fragments.size());
    LayoutConfig cfg;
    cfg.camera_up_C = Eigen::Vector3d(0.0, 1.0, 0.0);  // ICL-NUIM's y-flipped camera (fy < 0)
    auto est = estimateLayout(run.fragments, run.planes, run.T_W_F, cfg);
    ASSERT_TRUE(est.isOk()) << est.status().toString();
    const LayoutDiagnostics& d = est->diagnostics;
    ASSERT_NE(est->layout.firstOf(LayoutPlaneKind::kFloor), nullptr);
    ASSERT_NE(est->layout.firstOf(LayoutPlaneKind::kCeiling), nullptr);
    ASSERT_GE(d.opposite_plane_id, 0) << "no ceiling/floor opposite the base plane";
    // ICL-NUIM's world is y-up: the floor normal must be +y.
    const Eigen::Vector3d up_W = est->layout.T_W_L.linear().col(2);
    EXPECT_LE(angleDeg(up_W, Eigen::Vector3d::UnitY()), 2.0);
    // Raw (unsnapped) planes: floor parallel to ceiling, walls at right angles to both and to
    // each other, within 2 degrees.
    const Eigen::Vector3d n_base = d.dominant_planes[d.base_plane_id].normal_W;
    const Eigen::Vector3d n_opp = d.dominant_planes[d.opposite_plane_id].normal_W;
    EXPECT_LE(offRightAngleDeg(angleDeg(n_base, n_opp)), 2.0);
    std::vector<Eigen::Vector3d> walls;
    for (const WallDecision& w : d.walls) {
        if (!w.kept) continue;
        walls.push_back(d.dominant_planes[w.plane_id].normal_W);
        EXPECT_NEAR(angleDeg(walls.back(), n_base), 90.0, 2.0) << "wall " << w.plane_id;
    }
    EXPECT_GE(walls.size(), 2u);
    for (size_t a = 0; a < walls.size(); ++a) {
        for (size_t b = a + 1; b < walls.size(); ++b) {
            EXPECT_LE(offRightAngleDeg(angleDeg(walls[a], walls[b])), 2.0) << a << "-" << b;
        }
    }
    std::printf("[icl-nuim] %zu walls, base %s, ceiling height %.3f m, %d dominant planes\n",
                walls.size(), d.base_kind.c_str(), est->layout.ceiling_height_m,
                static_cast<int>(d.dominant_planes.size()));
}

TEST(RealLayout, TumStructureNotextureFarFloorIsTheBasePlane) {
    PLUMB_REQUIRE_SHARED_DATA(path, "tum-fr3-structure-notexture-far");
    const RealRun run = fuseDataset(path, 3, 21, 4.5f);
    ASSERT_EQ(run.planes.size(), run.fragments.size());
    auto est = estimateLayout(run.fragments, run.planes, run.T_W_F);
    ASSERT_TRUE(est.isOk()) << est.status().toString();
    const LayoutDiagnostics& d = est->diagnostics;
    EXPECT_EQ(d.base_kind, "floor");
    // The base plane is the lowest large horizontal surface: every other dominant plane's points
    // lie above it, and the camera is held upright above it.
    const Eigen::Vector3d up_W = est->layout.T_W_L.linear().col(2);
    EXPECT_GT(up_W.dot(d.up_hint_W), std::cos(30.0 * kDeg));
    for (const Eigen::Isometry3d& T : run.T_W_F) {
        const double cam_height = (est->layout.T_W_L.inverse() * T.translation()).z();
        EXPECT_GT(cam_height, 0.5);
        EXPECT_LT(cam_height, 2.5);
    }
    std::printf("[tum-structure] base %s, %d dominant planes, %zu walls\n", d.base_kind.c_str(),
                static_cast<int>(d.dominant_planes.size()), est->layout.walls().size());
}

}  // namespace
}  // namespace plumb::layout
