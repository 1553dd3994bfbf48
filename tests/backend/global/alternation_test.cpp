// SPDX-License-Identifier: Apache-2.0
// Algorithm 1 (paper §3.3): the alternation of layout estimation and global registration.

#include "backend/global/alternation.hpp"

#include <gtest/gtest.h>

#include <cstdio>

#include "common/config/config.hpp"
#include "tests/backend/global/global_test_util.hpp"
#include "tests/backend/global/sim_fragments.hpp"

namespace plumb::global {
namespace {

const testing::SimFragments& scan() {
    static const testing::SimFragments sim = [] {
        testing::SimFragmentsOptions o;
        o.scene = "weak_manhattan";
        o.loop = false;
        o.num_fragments = 10;
        return testing::makeSimFragments(o);
    }();
    return sim;
}

TEST(Alternation, ConvergesWithTheGroundTruthLayout) {
    const auto& sim = scan();
    AlternationConfig cfg;
    Result<std::vector<GlobalCloud>> clouds = prepareClouds(sim.fragments, cfg.global);
    ASSERT_TRUE(clouds.isOk());
    const auto priors = testing::makePriors(sim, clouds.value(), 0.3, 0.005);
    const auto T0 = testing::perturbedPoses(sim, 1.0, 0.03, 41);
    int calls = 0;
    LayoutEstimator estimator = [&](const std::vector<Eigen::Isometry3d>& T) -> Result<Layout> {
        EXPECT_EQ(T.size(), sim.fragments.size());
        ++calls;
        return sim.layout_gt;
    };
    Result<AlternationResult> r = alternate(clouds.value(), T0, priors, estimator, cfg);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    const double ate0 = testing::cameraPositionRmse(sim, T0);
    const double ate1 = testing::cameraPositionRmse(sim, r->T_W_F);
    std::printf(
        "weak_manhattan no-loop: %zu outer iterations (%s), camera RMSE %.2f -> %.2f cm, "
        "recon error %.2f -> %.2f cm (GT %.2f cm)\n",
        r->iterations.size(), r->stop_reason.c_str(), 100 * ate0, 100 * ate1,
        100 * testing::meanReconstructionError(sim, T0),
        100 * testing::meanReconstructionError(sim, r->T_W_F),
        100 * testing::meanReconstructionError(sim, sim.T_W_F_gt));
    for (const OuterIteration& it : r->iterations) {
        std::printf(
            "  outer %d: E %.4g -> %.4g (layout %.3g frag %.3g pair %.3g), %d inner, "
            "max change %.2g rad %.2g m\n",
            it.iteration, it.before.total, it.after.total, it.after.layout, it.after.frag,
            it.after.pair, it.inner_iterations, it.max_pose_change_rad, it.max_pose_change_m);
        // LM never accepts an increase within a round (fixed correspondences); a new round
        // re-establishes correspondences, so energies of different rounds are not compared.
        for (size_t k = 1; k < it.inner.size(); ++k) {
            if (it.inner[k].round != it.inner[k - 1].round) continue;
            EXPECT_LE(it.inner[k].energy.total, it.inner[k - 1].energy.total)
                << "outer " << it.iteration << ", inner " << k;
        }
        EXPECT_FALSE(it.inner.empty());
    }
    ASSERT_FALSE(r->iterations.empty());
    EXPECT_LT(r->iterations.back().after.total, 0.5 * r->iterations.front().before.total);
    EXPECT_TRUE(r->converged);
    EXPECT_EQ(r->stop_reason, "converged");
    EXPECT_LT(r->iterations.size(), 20U);
    EXPECT_EQ(calls, static_cast<int>(r->iterations.size()));
    EXPECT_LT(ate1, 0.3 * ate0);
    EXPECT_LT(ate1, 0.01);
    EXPECT_TRUE(r->T_W_F[0].matrix() == T0[0].matrix());
    EXPECT_EQ(r->layout.planes.size(), sim.layout_gt.planes.size());
}

TEST(Alternation, LayoutErrorsNameTheIteration) {
    const auto& sim = scan();
    AlternationConfig cfg;
    cfg.global.rounds = 1;
    int calls = 0;
    LayoutEstimator estimator = [&](const std::vector<Eigen::Isometry3d>&) -> Result<Layout> {
        if (calls++ == 1) return failedPrecondition("no base plane");
        return sim.layout_gt;
    };
    Result<AlternationResult> r =
        alternate(sim.fragments, testing::perturbedPoses(sim, 0.5, 0.01, 3), {}, estimator, cfg);
    ASSERT_FALSE(r.isOk());
    EXPECT_EQ(r.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_NE(r.status().message().find("outer iteration 1"), std::string::npos);
    EXPECT_NE(r.status().message().find("no base plane"), std::string::npos);
}

TEST(Alternation, CompareLayoutsMeasuresPlaneChanges) {
    const Layout a = scan().layout_gt;
    Layout b = a;
    double angle = 0, offset = 0;
    EXPECT_TRUE(compareLayouts(a, b, &angle, &offset));
    EXPECT_EQ(angle, 0.0);
    EXPECT_EQ(offset, 0.0);
    b.planes[2].d_L += 0.01;
    EXPECT_TRUE(compareLayouts(a, b, &angle, &offset));
    EXPECT_NEAR(offset, 0.01, 1e-12);
    b.planes.pop_back();
    EXPECT_FALSE(compareLayouts(a, b, &angle, &offset));
}

TEST(Alternation, ConfigIsDocumentedAndRoundTrips) {
    AlternationConfig c;
    c.global.pair_weight = 0.25;
    c.max_outer_iterations = 7;
    const std::string toml = config::toToml(c, "alternation");
    EXPECT_NE(toml.find("pair_weight"), std::string::npos);
    EXPECT_NE(toml.find("wall_margin_m"), std::string::npos);
    AlternationConfig back;
    ASSERT_TRUE(config::loadString(toml, "roundtrip", back).isOk());
    EXPECT_EQ(back.global.pair_weight, 0.25);
    EXPECT_EQ(back.max_outer_iterations, 7);
    EXPECT_FALSE(config::applyOverrides({"registration.frag_max_distance_m=-1"}, back).isOk() &&
                 config::validate(back).isOk());
}

}  // namespace
}  // namespace plumb::global
