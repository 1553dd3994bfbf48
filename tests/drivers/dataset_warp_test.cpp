// SPDX-License-Identifier: Apache-2.0
// Ground-truth warp check on the real datasets: the intrinsics, depth scale and GT poses the
// dataset reader hands out must agree with each other. For frame pairs (k, k+5), every valid pixel
// of frame k is back-projected, moved into camera k+5 with T_Ck5_Ck = T_W_Ck5^-1 T_W_Ck, projected,
// and its z compared with frame k+5's depth at that pixel. With the right conventions the median
// |residual| is sensor noise (< 2 cm; ICL-NUIM's noisy release shows about 1.5 cm already between
// consecutive frames) and unbiased; a wrong sign of ICL-NUIM's fy or an inverted pose breaks it.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "drivers/dataset/dataset.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::dataset {
namespace {

struct WarpStats {
    double median_abs_m = 0.0;     ///< median |z_warped - z_observed| in metres
    double median_signed_m = 0.0;  ///< median z_warped - z_observed (a bias check) in metres
    size_t compared = 0;           ///< pixels that landed on a valid pixel of the target
    size_t source_valid = 0;       ///< valid pixels of the source frame
};

/// Warps `from` into `to` (both with GT) using `camera` and compares z (nearest pixel).
WarpStats warpResidual(const Frame& from, const Frame& to, const PinholeCamera& camera,
                       bool invert_relative = false) {
    Eigen::Isometry3d T_Cto_Cfrom = to.T_W_C_gt->inverse() * (*from.T_W_C_gt);
    if (invert_relative) T_Cto_Cfrom = T_Cto_Cfrom.inverse();
    std::vector<double> residuals, signed_residuals;
    WarpStats stats;
    for (int v = 0; v < from.depth.height(); ++v) {
        for (int u = 0; u < from.depth.width(); ++u) {
            const float z = from.depth(u, v);
            if (!(z > 0.0f)) continue;
            ++stats.source_valid;
            const Eigen::Vector3d p_to = T_Cto_Cfrom * camera.unproject(u, v, z);
            if (p_to.z() <= 0.0) continue;
            const Eigen::Vector2d uv = camera.project(p_to);
            if (!camera.contains(uv.x(), uv.y())) continue;
            const float observed = to.depth(static_cast<int>(std::lround(uv.x())),
                                            static_cast<int>(std::lround(uv.y())));
            if (!(observed > 0.0f)) continue;
            residuals.push_back(std::abs(p_to.z() - observed));
            signed_residuals.push_back(p_to.z() - observed);
        }
    }
    stats.compared = residuals.size();
    if (!residuals.empty()) {
        auto mid = residuals.begin() + static_cast<std::ptrdiff_t>(residuals.size() / 2);
        std::nth_element(residuals.begin(), mid, residuals.end());
        stats.median_abs_m = *mid;
        auto signed_mid = signed_residuals.begin() + (mid - residuals.begin());
        std::nth_element(signed_residuals.begin(), signed_mid, signed_residuals.end());
        stats.median_signed_m = *signed_mid;
    }
    return stats;
}

/// Runs the pairs (k, k+5) on one dataset and checks median < 2 cm and broad overlap.
void checkDataset(const std::filesystem::path& dir, const std::vector<size_t>& firsts,
                  const char* label) {
    auto scanned = scanDataset(dir);
    ASSERT_TRUE(scanned.isOk()) << scanned.status().toString();
    const DatasetInfo& info = *scanned;
    for (size_t k : firsts) {
        auto a = loadFrame(info, k);
        auto b = loadFrame(info, k + 5);
        ASSERT_TRUE(a.isOk()) << a.status().toString();
        ASSERT_TRUE(b.isOk()) << b.status().toString();
        ASSERT_TRUE(a->T_W_C_gt && b->T_W_C_gt) << label << " frame " << k << " lacks GT";
        const WarpStats s = warpResidual(*a, *b, info.camera);
        std::printf(
            "[ warp     ] %s (%zu, %zu): median |dz| = %.2f mm (signed %+.2f mm) over %zu of %zu "
            "pixels\n",
            label, k, k + 5, 1000.0 * s.median_abs_m, 1000.0 * s.median_signed_m, s.compared,
            s.source_valid);
        EXPECT_LT(s.median_abs_m, 0.02) << label << " pair " << k;
        EXPECT_LT(std::abs(s.median_signed_m), 0.005) << label << " pair " << k << " is biased";
        EXPECT_GT(s.compared, s.source_valid / 2) << label << " pair " << k;
    }
}

TEST(DatasetWarp, TumGroundTruthFitsDepth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "tum-fr3-structure-notexture-far");
    const std::filesystem::path dir = path;
    checkDataset(dir, {5, 50, 100, 150, 200, 246}, "TUM");
}

TEST(DatasetWarp, IclNuimGroundTruthFitsDepthWithNegativeFy) {
    PLUMB_REQUIRE_SHARED_DATA(path, "icl-nuim-office-kt0");
    const std::filesystem::path dir = path;
    checkDataset(dir, {0, 20, 40, 60, 80, 94}, "ICL-NUIM");
}

TEST(DatasetWarp, WrongConventionsAreDetected) {
    // The check has teeth: ICL-NUIM with +480 (no y-flip), or either dataset with the relative
    // pose inverted, gives a clearly larger residual over a 20-frame baseline.
    PLUMB_REQUIRE_SHARED_DATA(path, "icl-nuim-office-kt0");
    const std::filesystem::path icl_dir = path;
    auto icl = scanDataset(icl_dir);
    ASSERT_TRUE(icl.isOk()) << icl.status().toString();
    const size_t k = 40, k2 = 60;
    auto a = loadFrame(*icl, k), b = loadFrame(*icl, k2);
    ASSERT_TRUE(a.isOk() && b.isOk());
    const WarpStats right = warpResidual(*a, *b, icl->camera);
    PinholeCamera flipped = icl->camera;
    flipped.fy = -flipped.fy;
    const WarpStats wrong_fy = warpResidual(*a, *b, flipped);
    const WarpStats wrong_pose = warpResidual(*a, *b, icl->camera, /*invert_relative=*/true);
    std::printf(
        "[ warp     ] ICL-NUIM (%zu, %zu): right %.2f mm, fy=+480 %.2f mm, inverted %.2f mm\n", k,
        k2, 1000.0 * right.median_abs_m, 1000.0 * wrong_fy.median_abs_m,
        1000.0 * wrong_pose.median_abs_m);
    EXPECT_LT(right.median_abs_m, 0.02);
    EXPECT_GT(wrong_fy.median_abs_m, 3.0 * right.median_abs_m);
    EXPECT_GT(wrong_pose.median_abs_m, 3.0 * right.median_abs_m);
}

}  // namespace
}  // namespace plumb::dataset
