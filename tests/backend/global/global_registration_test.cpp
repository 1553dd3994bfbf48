// SPDX-License-Identifier: Apache-2.0
// Layout-constrained global registration (paper §3.3) on simulated rooms with exact ground truth.

#include "backend/global/global_registration.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <limits>
#include <random>

#include "drivers/sim/scene.hpp"
#include "tests/backend/global/global_test_util.hpp"
#include "tests/backend/global/sim_fragments.hpp"

namespace plumb::global {
namespace {

using testing::SimFragments;

/// The living-room loop scan, built once for the suite.
const SimFragments& livingRoom() {
    static const SimFragments sim = [] {
        testing::SimFragmentsOptions o;
        return testing::makeSimFragments(o);
    }();
    return sim;
}

std::vector<GlobalCloud> clouds(const std::vector<Fragment>& fragments, const GlobalConfig& c) {
    Result<std::vector<GlobalCloud>> r = prepareClouds(fragments, c);
    EXPECT_TRUE(r.isOk()) << r.status().toString();
    return r.isOk() ? std::move(r).value() : std::vector<GlobalCloud>{};
}

const std::vector<GlobalCloud>& livingRoomClouds() {
    static const std::vector<GlobalCloud> clouds = [] {
        Result<std::vector<GlobalCloud>> c = prepareClouds(livingRoom().fragments, GlobalConfig{});
        PLUMB_CHECK(c.isOk()) << c.status().toString();
        return std::move(c).value();
    }();
    return clouds;
}

TEST(GlobalRegistration, PreparedCloudsAreSubsampledWithUnitNormals) {
    const auto& clouds = livingRoomClouds();
    ASSERT_EQ(clouds.size(), livingRoom().fragments.size());
    for (size_t k = 0; k < clouds.size(); ++k) {
        EXPECT_GT(clouds[k].size(), 500U);
        EXPECT_LE(clouds[k].size(), 6000U);
        EXPECT_LT(clouds[k].size(), livingRoom().fragments[k].points_F.size());
        for (const auto& n : clouds[k].normals()) ASSERT_NEAR(n.norm(), 1.0, 1e-9);
    }
}

TEST(GlobalRegistration, RefinementReducesTrajectoryAndReconstructionError) {
    const SimFragments& sim = livingRoom();
    const auto& clouds = livingRoomClouds();
    const auto priors = testing::makePriors(sim, clouds, 0.3, 0.005);
    const auto T0 = testing::perturbedPoses(sim, 1.0, 0.03, 11);
    GlobalConfig cfg;
    Result<GlobalResult> r = refinePoses(clouds, T0, priors, sim.layout_gt, cfg);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    const double ate0 = testing::cameraPositionRmse(sim, T0);
    const double ate1 = testing::cameraPositionRmse(sim, r->T_W_F);
    const double rec0 = testing::meanReconstructionError(sim, T0);
    const double rec1 = testing::meanReconstructionError(sim, r->T_W_F);
    const double rec_gt = testing::meanReconstructionError(sim, sim.T_W_F_gt);
    std::printf(
        "living_room loop: camera RMSE %.2f -> %.2f cm, recon error %.2f -> %.2f cm "
        "(GT poses %.2f cm); E %.3g -> %.3g (layout %zu, frag %zu, pair %zu; %zu pairs, "
        "lambda1 %.3g lambda2 %.3g)\n",
        100 * ate0, 100 * ate1, 100 * rec0, 100 * rec1, 100 * rec_gt, r->initial.total,
        r->final.total, r->final.num_layout, r->final.num_frag, r->final.num_pair,
        r->num_frag_pairs, r->lambda1, r->lambda2);
    EXPECT_LT(ate1, 0.25 * ate0);
    EXPECT_LT(ate1, 0.01);
    EXPECT_LT(rec1 - rec_gt, 0.25 * (rec0 - rec_gt));
    EXPECT_LT(rec1, rec_gt + 0.002);
    EXPECT_GT(r->final.num_layout, 1000U);
    EXPECT_GT(r->final.num_frag, 1000U);
    // Fragment 0 is the gauge: bit-identical.
    EXPECT_TRUE(r->T_W_F[0].matrix() == T0[0].matrix());
}

TEST(GlobalRegistration, EnergyNeverIncreasesWithinAnInnerLoop) {
    const SimFragments& sim = livingRoom();
    const auto& clouds = livingRoomClouds();
    const auto priors = testing::makePriors(sim, clouds, 0.5, 0.01);
    const auto T0 = testing::perturbedPoses(sim, 1.5, 0.04, 23);
    GlobalConfig cfg;
    cfg.rounds = 2;
    Result<GlobalResult> r = refinePoses(clouds, T0, priors, sim.layout_gt, cfg);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    ASSERT_FALSE(r->iterations.empty());
    double previous = r->initial.total;
    int round = 0;
    int accepted = 0;
    for (const GlobalIteration& it : r->iterations) {
        if (it.round != round) {
            round = it.round;
            previous = std::numeric_limits<double>::infinity();  // new correspondences
        }
        EXPECT_LE(it.energy.total, previous) << "round " << it.round << " it " << it.iteration;
        EXPECT_NEAR(it.energy.total, it.energy.layout + it.energy.frag + it.energy.pair, 1e-15);
        previous = it.energy.total;
        accepted += it.accepted ? 1 : 0;
    }
    EXPECT_GT(accepted, 2);
    EXPECT_LT(r->final.total, 0.5 * r->initial.total);
}

TEST(GlobalRegistration, ResultIsIndependentOfThreadCount) {
    const SimFragments& sim = livingRoom();
    const auto& clouds = livingRoomClouds();
    const auto priors = testing::makePriors(sim, clouds, 0.3, 0.005);
    const auto T0 = testing::perturbedPoses(sim, 1.0, 0.03, 5);
    GlobalConfig cfg;
    cfg.rounds = 1;
    cfg.num_threads = 1;
    Result<GlobalResult> a = refinePoses(clouds, T0, priors, sim.layout_gt, cfg);
    cfg.num_threads = 2;
    Result<GlobalResult> b = refinePoses(clouds, T0, priors, sim.layout_gt, cfg);
    cfg.num_threads = 0;
    Result<GlobalResult> c = refinePoses(clouds, T0, priors, sim.layout_gt, cfg);
    ASSERT_TRUE(a.isOk() && b.isOk() && c.isOk());
    for (size_t k = 0; k < T0.size(); ++k) {
        EXPECT_TRUE(a->T_W_F[k].matrix() == b->T_W_F[k].matrix()) << k;
        EXPECT_TRUE(a->T_W_F[k].matrix() == c->T_W_F[k].matrix()) << k;
    }
    EXPECT_EQ(a->final.total, b->final.total);
}

TEST(GlobalRegistration, FurnitureAgainstWallsStaysPut) {
    // The living room has a sofa against the south wall, a shelf against the east wall and a
    // sideboard against the west wall. After the layout-constrained refinement the points of
    // every box stay on their box (error at the level of the ground-truth poses).
    const SimFragments& sim = livingRoom();
    const auto& clouds = livingRoomClouds();
    const auto priors = testing::makePriors(sim, clouds, 0.3, 0.005);
    const auto T0 = testing::perturbedPoses(sim, 1.0, 0.03, 11);
    Result<GlobalResult> r = refinePoses(clouds, T0, priors, sim.layout_gt, GlobalConfig{});
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    // The residual pose error after refinement is a few millimetres at the camera (see
    // RefinementReducesTrajectoryAndReconstructionError); a box pulled onto a wall would be off
    // by its distance to the wall (>= 0.3 m for the faces parallel to walls).
    double sum_gt = 0.0, sum_after = 0.0;
    int seen = 0;
    for (int b = 0; b < static_cast<int>(sim.scene.boxes.size()); ++b) {
        const int label = sim::boxLabel(sim.scene, b);
        const double gt = testing::meanReconstructionError(sim, sim.T_W_F_gt, label);
        const double before = testing::meanReconstructionError(sim, T0, label);
        const double after = testing::meanReconstructionError(sim, r->T_W_F, label);
        std::printf("box %d: error %.2f mm -> %.2f mm (GT poses %.2f mm)\n", b, 1000 * before,
                    1000 * after, 1000 * gt);
        if (before == 0.0) continue;  // no fragment saw this box
        ++seen;
        EXPECT_LT(after, gt + 0.003) << "box " << b;
        EXPECT_LT(after, before) << "box " << b;
        sum_gt += gt;
        sum_after += after;
    }
    ASSERT_GE(seen, 3);
    EXPECT_LT(sum_after / seen, sum_gt / seen + 0.0015);
    // No point of a box is pulled onto a layout plane at the refined poses.
    const auto assignment = layoutAssignments(clouds, r->T_W_F, sim.layout_gt, GlobalConfig{});
    size_t box_points = 0, box_assigned = 0;
    for (size_t k = 0; k < clouds.size(); ++k) {
        for (size_t p = 0; p < clouds[k].size(); ++p) {
            const int label = sim.labels[k][clouds[k].sourceIndex()[p]];
            if (label < sim::boxLabel(sim.scene, 0) || label >= sim::cylinderLabel(sim.scene, 0)) {
                continue;
            }
            ++box_points;
            if (assignment[k][p] >= 0) ++box_assigned;
        }
    }
    std::printf("box points assigned to layout planes: %zu of %zu\n", box_assigned, box_points);
    EXPECT_GT(box_points, 500U);
    EXPECT_LT(static_cast<double>(box_assigned), 0.01 * static_cast<double>(box_points));
}

/// An L-shaped room (the built-in l_shape outline) with a cabinet whose front face lies 3 cm off
/// the infinite extension of the reflex corner's wall y = 3.2 (x from 7 down to 3.2, facing -y):
/// only the support-region test keeps that face from being pulled onto the wall.
struct CabinetRoom {
    sim::Scene scene;
    Layout layout;
    std::vector<Fragment> fragments;  // 0: the room, 1: the cabinet's corner; both at identity
    std::vector<std::vector<bool>> on_cabinet;
};

CabinetRoom makeCabinetRoom() {
    CabinetRoom c;
    c.scene.name = "cabinet_room";
    c.scene.polygon = {{0.0, 0.0}, {7.0, 0.0}, {7.0, 3.2}, {3.2, 3.2}, {3.2, 7.0}, {0.0, 7.0}};
    c.scene.height_m = 2.6;
    sim::Box cabinet;
    cabinet.center_W = {0.45, 3.53, 0.5};  // y in [3.23, 3.83]: front face at y = 3.23
    cabinet.size_m = {0.8, 0.6, 1.0};
    c.scene.boxes = {cabinet};
    PLUMB_CHECK(sim::validateScene(c.scene).isOk());
    c.layout = makeRoomLayout(c.scene.polygon, c.scene.height_m).value();
    const PointCloud surface = sim::sampleSurfaces(c.scene, 0.02);
    c.fragments.resize(2);
    c.on_cabinet.resize(2);
    for (size_t k = 0; k < surface.size(); ++k) {
        const Eigen::Vector3f& p = surface.points[k];
        const bool corner = p.x() < 1.3F && p.y() > 2.9F && p.y() < 4.2F;
        const bool cab = p.x() < 0.86F && p.y() > 3.22F && p.y() < 3.84F && p.z() < 1.01F &&
                         (p.x() > 0.04F && p.z() > 0.001F);
        Fragment& f = c.fragments[corner ? 1 : 0];
        f.points_F.points.push_back(p);
        f.points_F.normals.push_back(surface.normals[k]);
        c.on_cabinet[corner ? 1 : 0].push_back(cab);
    }
    c.fragments[1].id = 1;
    return c;
}

double meanCabinetOffset(const CabinetRoom& c, const Eigen::Isometry3d& T_W_1) {
    double sum = 0.0;
    size_t n = 0;
    for (size_t k = 0; k < c.fragments[1].points_F.size(); ++k) {
        if (!c.on_cabinet[1][k]) continue;
        const Eigen::Vector3d p = c.fragments[1].points_F.points[k].cast<double>();
        sum += (T_W_1 * p - p).norm();
        ++n;
    }
    return n > 0 ? sum / static_cast<double>(n) : 0.0;
}

TEST(GlobalRegistration, SupportRegionKeepsFurnitureOffWallExtensions) {
    const CabinetRoom room = makeCabinetRoom();
    GlobalConfig cfg;
    Result<std::vector<GlobalCloud>> clouds = prepareClouds(room.fragments, cfg);
    ASSERT_TRUE(clouds.isOk());
    const std::vector<Eigen::Isometry3d> gt(2, Eigen::Isometry3d::Identity());

    // Assignment: with the support test no cabinet point is pulled; without it its front face is.
    GlobalConfig no_support = cfg;
    no_support.wall_margin_m = 100.0;
    no_support.floor_margin_m = 100.0;
    auto count_cabinet = [&](const GlobalConfig& c) {
        const auto a = layoutAssignments(clouds.value(), gt, room.layout, c);
        size_t n = 0;
        for (size_t p = 0; p < clouds.value()[1].size(); ++p) {
            if (room.on_cabinet[1][clouds.value()[1].sourceIndex()[p]] && a[1][p] >= 0) ++n;
        }
        return n;
    };
    const size_t with_support = count_cabinet(cfg);
    const size_t without_support = count_cabinet(no_support);
    std::printf("cabinet points on layout planes: %zu with support test, %zu without\n",
                with_support, without_support);
    EXPECT_EQ(with_support, 0U);
    EXPECT_GT(without_support, 300U);

    // Refinement from a perturbed corner fragment, with a ground-truth pair prior.
    testing::SimFragments sim;  // only for makePriors' ground truth
    sim.fragments = room.fragments;
    sim.T_W_F_gt = gt;
    const auto priors = testing::makePriors(sim, clouds.value(), 0.0, 0.0);
    std::vector<Eigen::Isometry3d> T0 = gt;
    T0[1] = testing::randomPerturbation(1.0, 0.02, 3);
    Result<GlobalResult> on = refinePoses(clouds.value(), T0, priors, room.layout, cfg);
    Result<GlobalResult> off = refinePoses(clouds.value(), T0, priors, room.layout, no_support);
    ASSERT_TRUE(on.isOk() && off.isOk());
    const double before = meanCabinetOffset(room, T0[1]);
    const double with = meanCabinetOffset(room, on->T_W_F[1]);
    const double without = meanCabinetOffset(room, off->T_W_F[1]);
    std::printf(
        "cabinet displacement: %.2f mm initially, %.2f mm with support test, %.2f mm "
        "without\n",
        1000 * before, 1000 * with, 1000 * without);
    EXPECT_LT(with, 0.002);
    EXPECT_GT(without, 3.0 * with + 0.003);
}

TEST(GlobalRegistration, WithoutLayoutItStillAlignsFragments) {
    // The Choi-style baseline (E_frag + E_pair): also reduces the error, less constrained.
    const SimFragments& sim = livingRoom();
    const auto& clouds = livingRoomClouds();
    const auto priors = testing::makePriors(sim, clouds, 0.3, 0.005);
    const auto T0 = testing::perturbedPoses(sim, 1.0, 0.03, 11);
    GlobalConfig cfg;
    cfg.use_layout = false;
    Result<GlobalResult> r = refinePoses(clouds, T0, priors, sim.layout_gt, cfg);
    ASSERT_TRUE(r.isOk());
    EXPECT_EQ(r->final.num_layout, 0U);
    const double rec0 = testing::meanReconstructionError(sim, T0);
    const double rec1 = testing::meanReconstructionError(sim, r->T_W_F);
    std::printf("no layout: recon error %.2f -> %.2f cm, camera RMSE %.2f -> %.2f cm\n", 100 * rec0,
                100 * rec1, 100 * testing::cameraPositionRmse(sim, T0),
                100 * testing::cameraPositionRmse(sim, r->T_W_F));
    EXPECT_LT(rec1, rec0);
    // The layout term (the paper's contribution) does better than the baseline on the same input.
    cfg.use_layout = true;
    Result<GlobalResult> with = refinePoses(clouds, T0, priors, sim.layout_gt, cfg);
    ASSERT_TRUE(with.isOk());
    const double rec_layout = testing::meanReconstructionError(sim, with->T_W_F);
    std::printf("with layout: recon error %.2f cm, camera RMSE %.2f cm\n", 100 * rec_layout,
                100 * testing::cameraPositionRmse(sim, with->T_W_F));
    EXPECT_LT(rec_layout, rec1);
    EXPECT_LT(testing::cameraPositionRmse(sim, with->T_W_F),
              testing::cameraPositionRmse(sim, r->T_W_F));
}

TEST(GlobalRegistration, TrackedPriorsAreWeighedByTheirOwnWeight) {
    // Two fragments without points, held only by two priors on the same pair that disagree: a
    // tracked odometry prior puts fragment 1 at x = 0.1 m, a loop prior at x = 0. E_pair is
    // (1/2) (w_t |x - 0.1|^2 + w_l |x|^2), minimal at x = 0.1 w_t / (w_t + w_l).
    const std::vector<Fragment> empty(2);
    const std::vector<Eigen::Isometry3d> T(2, Eigen::Isometry3d::Identity());
    PairPrior tracked;
    tracked.i = 0;
    tracked.j = 1;
    tracked.T_i_j.translation() = Eigen::Vector3d(0.1, 0.0, 0.0);
    tracked.count = 1.0;
    tracked.tracked = true;
    PairPrior loop = tracked;
    loop.T_i_j = Eigen::Isometry3d::Identity();
    loop.tracked = false;
    for (const double w_t : {0.01, 1.0}) {
        GlobalConfig cfg;
        cfg.pair_weight = 0.01;
        cfg.tracked_pair_weight = w_t;
        Result<EnergyTerms> e = evaluateEnergy(clouds(empty, cfg), T, {tracked, loop}, {}, cfg);
        ASSERT_TRUE(e.isOk()) << e.status().toString();
        EXPECT_NEAR(e->pair, 0.5 * w_t * 0.01, 1e-12) << "only the tracked prior is off at x = 0";
        Result<GlobalResult> r = refinePoses(empty, T, {tracked, loop}, {}, cfg);
        ASSERT_TRUE(r.isOk()) << r.status().toString();
        const double x = 0.1 * w_t / (w_t + cfg.pair_weight);
        EXPECT_NEAR(r->T_W_F[1].translation().x(), x, 1e-6) << "w_t " << w_t;
        EXPECT_NEAR(r->T_W_F[1].translation().tail<2>().norm(), 0.0, 1e-9);
    }
}

/// Perturbed poses of the living room, its priors, and its true layout moved by 3 cm along x.
struct TwoLayouts {
    const SimFragments& sim = livingRoom();
    const std::vector<GlobalCloud>& cl = livingRoomClouds();
    std::vector<Eigen::Isometry3d> T = testing::perturbedPoses(sim, 1.0, 0.03, 11);
    std::vector<PairPrior> priors = testing::makePriors(sim, cl, 0.3, 0.005);
    Layout moved = [this] {
        Layout l = sim.layout_gt;
        l.T_W_L = Eigen::Translation3d(0.03, 0.0, 0.0) * l.T_W_L;
        return l;
    }();
    GlobalConfig cfg;
};

TEST(GlobalRegistration, TwoLayoutsAreEvaluatedAsEachAlone) {
    // evaluateEnergies() shares the fragment pairs' correspondences between the two layouts: its
    // energies are those of two evaluateEnergy() calls, term by term and bit for bit, and the
    // layout terms differ (the second layout is moved by 3 cm).
    const TwoLayouts in;
    const auto& [sim, cl, T, priors, moved, cfg] = in;
    Result<std::array<EnergyTerms, 2>> both =
        evaluateEnergies(cl, T, priors, sim.layout_gt, moved, cfg);
    ASSERT_TRUE(both.isOk()) << both.status().toString();
    const std::array<const Layout*, 2> layouts{&sim.layout_gt, &moved};
    for (size_t k = 0; k < 2; ++k) {
        Result<EnergyTerms> alone = evaluateEnergy(cl, T, priors, *layouts[k], cfg);
        ASSERT_TRUE(alone.isOk()) << alone.status().toString();
        EXPECT_EQ((*both)[k].total, alone->total) << k;
        EXPECT_EQ((*both)[k].layout, alone->layout) << k;
        EXPECT_EQ((*both)[k].frag, alone->frag) << k;
        EXPECT_EQ((*both)[k].pair, alone->pair) << k;
        EXPECT_EQ((*both)[k].num_layout, alone->num_layout) << k;
        EXPECT_EQ((*both)[k].num_frag, alone->num_frag) << k;
    }
    EXPECT_NE((*both)[0].layout, (*both)[1].layout);
    EXPECT_GT((*both)[0].num_frag, 0U);
    Layout bad = in.moved;
    bad.planes.front().normal_L = Eigen::Vector3d(0.0, 0.0, 2.0);
    EXPECT_EQ(evaluateEnergies(cl, T, priors, sim.layout_gt, bad, cfg).status().code(),
              StatusCode::kInvalidArgument);
    EXPECT_EQ(refinePosesAfterLayoutStep(cl, T, priors, sim.layout_gt, bad, cfg).status().code(),
              StatusCode::kInvalidArgument);
}

TEST(GlobalRegistration, TheRegistrationStepAfterALayoutStepIsTheTestThenRefinePoses) {
    // refinePosesAfterLayoutStep() reuses the correspondences of its test in the first round:
    // the poses and every iteration's energy are those of evaluateEnergies() then refinePoses().
    // A layout moved by 3 cm raises E_R against the true one and is not registered onto.
    const TwoLayouts in;
    const auto& [sim, cl, T, priors, moved, cfg] = in;
    Result<LayoutStepOutcome> kept =
        refinePosesAfterLayoutStep(cl, T, priors, moved, sim.layout_gt, cfg);
    ASSERT_TRUE(kept.isOk()) << kept.status().toString();
    ASSERT_TRUE(kept->step.has_value());
    Result<std::array<EnergyTerms, 2>> e =
        evaluateEnergies(cl, T, priors, moved, sim.layout_gt, cfg);
    Result<GlobalResult> plain = refinePoses(cl, T, priors, sim.layout_gt, cfg);
    ASSERT_TRUE(e.isOk() && plain.isOk());
    EXPECT_EQ(kept->energies[0].total, (*e)[0].total);
    EXPECT_EQ(kept->energies[1].total, (*e)[1].total);
    EXPECT_EQ(kept->step->initial.total, (*e)[1].total);
    ASSERT_EQ(kept->step->iterations.size(), plain->iterations.size());
    for (size_t k = 0; k < plain->iterations.size(); ++k)
        EXPECT_EQ(kept->step->iterations[k].energy.total, plain->iterations[k].energy.total) << k;
    for (size_t i = 0; i < T.size(); ++i)
        EXPECT_TRUE(kept->step->T_W_F[i].matrix() == plain->T_W_F[i].matrix()) << i;

    Result<LayoutStepOutcome> refused =
        refinePosesAfterLayoutStep(cl, plain->T_W_F, priors, sim.layout_gt, moved, cfg);
    ASSERT_TRUE(refused.isOk()) << refused.status().toString();
    EXPECT_GT(refused->energies[1].total, refused->energies[0].total);
    EXPECT_FALSE(refused->step.has_value());
}

TEST(GlobalRegistration, ANearestSearchFromAnyHintFindsWhatTheSearchWithoutOneFinds) {
    // A hint only bounds the search by its own distance: from the true nearest point, from a
    // neighbour of it, from a far point, or out of range, the same point and distance.
    const GlobalCloud& to = livingRoomClouds()[1];
    const GlobalCloud& from = livingRoomClouds()[0];
    const double max_sq = 0.05 * 0.05;
    std::mt19937 rng(7);
    std::uniform_int_distribution<uint32_t> any(0, static_cast<uint32_t>(to.size() - 1));
    size_t found = 0;
    for (size_t k = 0; k < from.size(); ++k) {
        const Eigen::Vector3d q = from.points()[k] + Eigen::Vector3d(0.01, -0.02, 0.005);
        uint32_t idx = 0;
        double d_sq = 0.0;
        const bool ok = to.nearestWithin(q, max_sq, &idx, &d_sq);
        uint32_t exact = 0;
        double exact_sq = 0.0;
        ASSERT_TRUE(to.nearest(q, &exact, &exact_sq));
        const uint32_t neighbour =
            std::min<uint32_t>(exact + 1, static_cast<uint32_t>(to.size() - 1));
        for (const uint32_t hint :
             {exact, neighbour, any(rng), std::numeric_limits<uint32_t>::max()}) {
            uint32_t h_idx = 0;
            double h_sq = 0.0;
            ASSERT_EQ(to.nearestWithin(q, max_sq, &h_idx, &h_sq, hint), ok) << k << " " << hint;
            if (!ok) continue;
            ASSERT_EQ(h_idx, idx) << k << " " << hint;
            ASSERT_EQ(h_sq, d_sq) << k << " " << hint;
        }
        if (ok) {
            ++found;
            EXPECT_EQ(idx, exact);
        }
    }
    EXPECT_GT(found, from.size() / 10);
}

TEST(GlobalRegistration, HintsCarriedBetweenRefinementsChangeNothing) {
    // Algorithm 1 hands each registration the last one's correspondences (MatchHints): the
    // second refinement from the first one's poses gives the same poses and energies with the
    // hints as without, and a hint object from other poses is as good as none.
    const TwoLayouts in;
    const auto& [sim, cl, T, priors, moved, cfg] = in;
    MatchHints hints;
    Result<GlobalResult> first = refinePoses(cl, T, priors, sim.layout_gt, cfg, &hints);
    ASSERT_TRUE(first.isOk());
    ASSERT_NE(hints.pairs, nullptr);
    Result<GlobalResult> plain = refinePoses(cl, first->T_W_F, priors, moved, cfg);
    Result<GlobalResult> hinted = refinePoses(cl, first->T_W_F, priors, moved, cfg, &hints);
    ASSERT_TRUE(plain.isOk() && hinted.isOk());
    ASSERT_EQ(hinted->iterations.size(), plain->iterations.size());
    for (size_t k = 0; k < plain->iterations.size(); ++k)
        EXPECT_EQ(hinted->iterations[k].energy.total, plain->iterations[k].energy.total) << k;
    for (size_t i = 0; i < T.size(); ++i)
        EXPECT_TRUE(hinted->T_W_F[i].matrix() == plain->T_W_F[i].matrix()) << i;
    Result<LayoutStepOutcome> step =
        refinePosesAfterLayoutStep(cl, T, priors, moved, sim.layout_gt, cfg, &hints);
    Result<LayoutStepOutcome> step_plain =
        refinePosesAfterLayoutStep(cl, T, priors, moved, sim.layout_gt, cfg);
    ASSERT_TRUE(step.isOk() && step_plain.isOk());
    EXPECT_EQ(step->energies[0].total, step_plain->energies[0].total);
    EXPECT_EQ(step->energies[1].total, step_plain->energies[1].total);
    ASSERT_TRUE(step->step.has_value() && step_plain->step.has_value());
    for (size_t i = 0; i < T.size(); ++i)
        EXPECT_TRUE(step->step->T_W_F[i].matrix() == step_plain->step->T_W_F[i].matrix()) << i;
}

TEST(GlobalRegistration, BadInputGivesSpecificErrors) {
    const SimFragments& sim = livingRoom();
    const auto& clouds = livingRoomClouds();
    const Layout& layout = sim.layout_gt;
    auto T = sim.T_W_F_gt;
    GlobalConfig cfg;
    // Size mismatch.
    auto short_T = T;
    short_T.pop_back();
    Result<GlobalResult> r = refinePoses(clouds, short_T, {}, layout, cfg);
    ASSERT_FALSE(r.isOk());
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    // NaN pose.
    auto nan_T = T;
    nan_T[3].translation().x() = std::nan("");
    r = refinePoses(clouds, nan_T, {}, layout, cfg);
    ASSERT_FALSE(r.isOk());
    EXPECT_NE(r.status().message().find("fragment 3"), std::string::npos);
    // Prior out of range / self pair / asymmetric information.
    PairPrior p;
    p.i = 0;
    p.j = 99;
    r = refinePoses(clouds, T, {p}, layout, cfg);
    ASSERT_FALSE(r.isOk());
    EXPECT_NE(r.status().message().find("pair prior 0"), std::string::npos);
    p.j = 0;
    r = refinePoses(clouds, T, {p}, layout, cfg);
    EXPECT_FALSE(r.isOk());
    p.j = 1;
    p.information(0, 5) = 3.0;
    r = refinePoses(clouds, T, {p}, layout, cfg);
    EXPECT_FALSE(r.isOk());
    // Bad layout plane.
    Layout bad = layout;
    bad.planes[0].normal_L = Eigen::Vector3d(0, 0, 2);
    r = refinePoses(clouds, T, {}, bad, cfg);
    EXPECT_FALSE(r.isOk());
    // Bad config.
    GlobalConfig bad_cfg;
    bad_cfg.frag_max_distance_m = -1.0;
    r = refinePoses(clouds, T, {}, layout, bad_cfg);
    EXPECT_FALSE(r.isOk());
    // Points without normals.
    std::vector<Fragment> frags(2);
    frags[0].points_F.points.push_back(Eigen::Vector3f::Zero());
    Result<std::vector<GlobalCloud>> c = prepareClouds(frags, cfg);
    ASSERT_FALSE(c.isOk());
    EXPECT_NE(c.status().message().find("without normals"), std::string::npos);
    // Empty fragments are fine (no constraints; the poses stay).
    std::vector<Fragment> empty(3);
    Result<GlobalResult> e = refinePoses(
        empty, std::vector<Eigen::Isometry3d>(3, Eigen::Isometry3d::Identity()), {}, layout, cfg);
    ASSERT_TRUE(e.isOk()) << e.status().toString();
    for (const auto& pose : e->T_W_F) EXPECT_TRUE(pose.isApprox(Eigen::Isometry3d::Identity()));
}

}  // namespace
}  // namespace plumb::global
