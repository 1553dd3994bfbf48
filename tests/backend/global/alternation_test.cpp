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

/// The scan's clouds (default config), priors from its ground truth and poses perturbed by 1 deg
/// and 3 cm: the start of Algorithm 1 in these tests.
struct Start {
    std::vector<GlobalCloud> clouds;
    std::vector<PairPrior> priors;
    std::vector<Eigen::Isometry3d> T0;
};

const Start& perturbedStart() {
    static const Start start = [] {
        Start s;
        Result<std::vector<GlobalCloud>> clouds = prepareClouds(scan().fragments, GlobalConfig{});
        PLUMB_CHECK(clouds.isOk()) << clouds.status().toString();
        s.clouds = std::move(clouds).value();
        s.priors = testing::makePriors(scan(), s.clouds, 0.3, 0.005);
        s.T0 = testing::perturbedPoses(scan(), 1.0, 0.03, 41);
        return s;
    }();
    return start;
}

TEST(Alternation, ConvergesWithTheGroundTruthLayout) {
    const auto& sim = scan();
    AlternationConfig cfg;
    const Start& start = perturbedStart();
    const std::vector<Eigen::Isometry3d>& T0 = start.T0;
    int calls = 0;
    LayoutEstimator estimator = [&](const std::vector<Eigen::Isometry3d>& T) -> Result<Layout> {
        EXPECT_EQ(T.size(), sim.fragments.size());
        ++calls;
        return sim.layout_gt;
    };
    Result<AlternationResult> r = alternate(start.clouds, T0, start.priors, estimator, cfg);
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

TEST(Alternation, StopsWhenTheEnergyNoLongerFallsOnceTheAnnealingIsDone) {
    // Pose tolerances no run reaches, so only the energy test can end the loop early: without
    // it the loop runs to the iteration limit; with it, it stops once E_R falls by less than
    // energy_tolerance of itself in an iteration at the final distances, where the poses are
    // as good as the limit's.
    const auto& sim = scan();
    const Start& start = perturbedStart();
    LayoutEstimator estimator = [&](const std::vector<Eigen::Isometry3d>&) -> Result<Layout> {
        return sim.layout_gt;
    };
    AlternationConfig cfg;
    cfg.pose_tolerance_m = 1e-12;
    cfg.pose_tolerance_rad = 1e-12;
    cfg.max_outer_iterations = 8;
    cfg.energy_tolerance = 0.0;
    Result<AlternationResult> full =
        alternate(start.clouds, start.T0, start.priors, estimator, cfg);
    ASSERT_TRUE(full.isOk()) << full.status().toString();
    EXPECT_EQ(full->stop_reason, "max_outer_iterations");
    ASSERT_EQ(full->iterations.size(), 8U);

    cfg.energy_tolerance = 1e-3;
    Result<AlternationResult> early =
        alternate(start.clouds, start.T0, start.priors, estimator, cfg);
    ASSERT_TRUE(early.isOk()) << early.status().toString();
    EXPECT_EQ(early->stop_reason, "energy settled");
    EXPECT_TRUE(early->converged);
    // The distances shrink by 0.7 per iteration from 5 to 2.5 cm (fragments) and 10 to 5 cm
    // (layout, margins): iterations 0 to 2 anneal, so the earliest stop is after iteration 3.
    ASSERT_GE(early->iterations.size(), 4U);
    ASSERT_LT(early->iterations.size(), full->iterations.size());
    const size_t n = early->iterations.size();
    const double last = early->iterations[n - 1].after.total;
    const double before_last = early->iterations[n - 2].after.total;
    EXPECT_LT(before_last - last, 1e-3 * before_last);
    // The iterations run are those of the run without the test.
    for (size_t k = 0; k < n; ++k)
        EXPECT_EQ(early->iterations[k].after.total, full->iterations[k].after.total) << k;
    const double ate_early = testing::cameraPositionRmse(sim, early->T_W_F);
    const double ate_full = testing::cameraPositionRmse(sim, full->T_W_F);
    std::printf(
        "energy test: stopped after %zu of 8 outer iterations, camera RMSE %.3f cm "
        "(%.3f cm after 8)\n",
        n, 100 * ate_early, 100 * ate_full);
    EXPECT_LT(std::abs(ate_early - ate_full), 0.0005);
}

TEST(Alternation, ALayoutStepThatRaisesTheEnergyIsNotTaken) {
    // The estimator gives the true layout, then the whole layout moved by 7 cm: at the poses the
    // first registration step reached, the moved layout fits worse, so Algorithm 1 stops and
    // keeps the true one. Without the test it registers the fragments onto the moved layout.
    const auto& sim = scan();
    AlternationConfig cfg;
    const Start& start = perturbedStart();
    const std::vector<Eigen::Isometry3d>& T0 = start.T0;
    Layout moved = sim.layout_gt;
    moved.T_W_L = Eigen::Translation3d(0.04, -0.03, 0.05) * moved.T_W_L;
    int calls = 0;
    LayoutEstimator estimator = [&](const std::vector<Eigen::Isometry3d>&) -> Result<Layout> {
        return calls++ == 0 ? sim.layout_gt : moved;
    };
    Result<AlternationResult> r = alternate(start.clouds, T0, start.priors, estimator, cfg);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    EXPECT_EQ(r->stop_reason, "layout step raised the energy");
    ASSERT_EQ(r->iterations.size(), 1U);
    EXPECT_EQ(calls, 2);
    EXPECT_TRUE(r->layout.T_W_L.matrix() == sim.layout_gt.T_W_L.matrix());
    const double ate_kept = testing::cameraPositionRmse(sim, r->T_W_F);

    calls = 0;
    cfg.monotone_layout_steps = false;
    Result<AlternationResult> chased = alternate(start.clouds, T0, start.priors, estimator, cfg);
    ASSERT_TRUE(chased.isOk()) << chased.status().toString();
    EXPECT_GT(chased->iterations.size(), 1U);
    EXPECT_TRUE(chased->layout.T_W_L.matrix() == moved.T_W_L.matrix());
    const double ate_chased = testing::cameraPositionRmse(sim, chased->T_W_F);
    std::printf("camera RMSE: %.2f cm with the test, %.2f cm chasing the moved layout\n",
                100 * ate_kept, 100 * ate_chased);
    EXPECT_LT(ate_kept, 0.01);
    EXPECT_GT(ate_chased, ate_kept);
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
