// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "common/eval/trajectory_metrics.hpp"
#include "common/geometry/lie.hpp"
#include "common/io/trajectory.hpp"

namespace plumb::eval {
namespace {

/// A smooth handheld-like trajectory: a random walk in twist space, stamps t0 + k dt.
io::Trajectory walk(size_t count, double t0, double dt, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> n(0.0, 1.0);
    io::Trajectory trajectory;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    for (size_t k = 0; k < count; ++k) {
        Vector6d xi;
        xi << 0.02 * n(rng), 0.02 * n(rng), 0.02 * n(rng), 0.05 * n(rng), 0.05 * n(rng),
            0.05 * n(rng);
        T = T * lie::expSE3(xi);
        trajectory.push_back({t0 + dt * static_cast<double>(k), T});
    }
    return trajectory;
}

std::vector<Eigen::Vector3d> positions(const io::Trajectory& t) {
    std::vector<Eigen::Vector3d> p;
    for (const io::StampedPose& s : t) p.push_back(s.T_W_C.translation());
    return p;
}

std::vector<Eigen::Isometry3d> poses(const io::Trajectory& t) {
    std::vector<Eigen::Isometry3d> p;
    for (const io::StampedPose& s : t) p.push_back(s.T_W_C);
    return p;
}

Eigen::Isometry3d knownTransform() {
    Vector6d xi;
    xi << 0.4, -1.1, 2.3, 3.0, -2.0, 0.5;
    return lie::expSE3(xi);
}

TEST(Ate, GroundTruthAgainstItselfIsZero) {
    const io::Trajectory gt = walk(500, 0.0, 0.033, 1);
    const Result<AteResult> ate = computeAte(positions(gt), positions(gt));
    ASSERT_TRUE(ate.isOk()) << ate.status().toString();
    EXPECT_EQ(ate->num_pairs, 500u);
    EXPECT_LT(ate->rmse_m, 1e-12);
    EXPECT_LT(ate->max_m, 1e-12);
    EXPECT_LT((ate->T_gt_est.matrix() - Eigen::Matrix4d::Identity()).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(Ate, AlignmentRecoversAKnownRigidMotion) {
    const io::Trajectory gt = walk(500, 0.0, 0.033, 2);
    const Eigen::Isometry3d T_est_gt = knownTransform();  // the estimate lives in another frame
    std::vector<Eigen::Vector3d> est;
    for (const Eigen::Vector3d& p : positions(gt)) est.push_back(T_est_gt * p);

    const Result<AteResult> ate = computeAte(est, positions(gt));
    ASSERT_TRUE(ate.isOk()) << ate.status().toString();
    EXPECT_LT(ate->rmse_m, 1e-9);
    EXPECT_LT((ate->T_gt_est.matrix() - T_est_gt.inverse().matrix()).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_NEAR(ate->T_gt_est.linear().determinant(), 1.0, 1e-12);

    // Without alignment the error of each point is exactly its displacement.
    const Result<AteResult> raw = computeAte(est, positions(gt), AteOptions{false});
    ASSERT_TRUE(raw.isOk());
    EXPECT_TRUE(raw->T_gt_est.matrix().isIdentity());
    EXPECT_NEAR(raw->errors_m[7], (est[7] - positions(gt)[7]).norm(), 1e-12);
    EXPECT_GT(raw->rmse_m, 1.0);
}

TEST(Ate, OneCentimetreIsotropicNoiseGivesSqrt3Centimetres) {
    const io::Trajectory gt = walk(5000, 0.0, 0.033, 3);
    std::mt19937_64 rng(4);
    std::normal_distribution<double> noise(0.0, 0.01);  // sigma 1 cm per axis
    const Eigen::Isometry3d T_est_gt = knownTransform();
    std::vector<Eigen::Vector3d> est;
    for (const Eigen::Vector3d& p : positions(gt)) {
        est.push_back(T_est_gt * (p + Eigen::Vector3d(noise(rng), noise(rng), noise(rng))));
    }
    const Result<AteResult> ate = computeAte(est, positions(gt));
    ASSERT_TRUE(ate.isOk());
    // E|n|^2 = 3 sigma^2: RMSE -> sqrt(3) cm; the median of a chi(3) * sigma is 1.538 sigma.
    EXPECT_NEAR(ate->rmse_m, std::sqrt(3.0) * 0.01, 0.05 * std::sqrt(3.0) * 0.01);
    EXPECT_NEAR(ate->median_m, 0.01538, 0.05 * 0.01538);
    EXPECT_NEAR(ate->mean_m, 0.01596, 0.05 * 0.01596);  // sigma * 2 sqrt(2 / pi)
    EXPECT_LT((ate->T_gt_est.matrix() - T_est_gt.inverse().matrix()).cwiseAbs().maxCoeff(), 1e-2);
}

TEST(Ate, StatisticsOfKnownErrors) {
    // Errors 1, 2, 3, 4 (no alignment): median of an even count is the mean of the middle two.
    const std::vector<Eigen::Vector3d> gt(4, Eigen::Vector3d::Zero());
    const std::vector<Eigen::Vector3d> est = {{0, 4, 0}, {1, 0, 0}, {0, 0, -3}, {0, 2, 0}};
    const Result<AteResult> ate = computeAte(est, gt, AteOptions{false});
    ASSERT_TRUE(ate.isOk());
    EXPECT_DOUBLE_EQ(ate->median_m, 2.5);
    EXPECT_DOUBLE_EQ(ate->mean_m, 2.5);
    EXPECT_DOUBLE_EQ(ate->rmse_m, std::sqrt(7.5));
    EXPECT_DOUBLE_EQ(ate->max_m, 4.0);
    EXPECT_DOUBLE_EQ(ate->min_m, 1.0);
    EXPECT_EQ(ate->errors_m, (std::vector<double>{4, 1, 3, 2}));
    const Result<AteResult> odd =
        computeAte({est.begin(), est.begin() + 3}, {gt.begin(), gt.begin() + 3}, AteOptions{false});
    EXPECT_DOUBLE_EQ(odd->median_m, 3.0);
}

TEST(Ate, MirroredEstimateStillGetsAProperRotationMatchingUmeyama) {
    // A mirrored estimate: the best orthogonal map is a reflection; Horn must return the best
    // rotation instead, as Eigen::umeyama(with_scaling = false) does.
    std::mt19937_64 rng(5);
    std::normal_distribution<double> n(0.0, 1.0);
    for (bool mirrored : {false, true}) {
        std::vector<Eigen::Vector3d> est, gt;
        Eigen::Matrix3Xd src(3, 200), dst(3, 200);
        for (int k = 0; k < 200; ++k) {
            const Eigen::Vector3d p(3.0 * n(rng), n(rng), 0.3 * n(rng));
            const Eigen::Vector3d q =
                mirrored ? Eigen::Vector3d(p.x(), p.y(), -p.z()) : knownTransform() * p;
            est.push_back(q + 0.01 * Eigen::Vector3d(n(rng), n(rng), n(rng)));
            gt.push_back(p);
            src.col(k) = est.back();
            dst.col(k) = p;
        }
        const Eigen::Isometry3d T = alignRigid(est, gt);
        EXPECT_NEAR(T.linear().determinant(), 1.0, 1e-12);
        const Eigen::Matrix4d oracle = Eigen::umeyama(src, dst, false);
        EXPECT_LT((T.matrix() - oracle).cwiseAbs().maxCoeff(), 1e-9) << "mirrored " << mirrored;
    }
}

TEST(Ate, RejectsUnusableInput) {
    const std::vector<Eigen::Vector3d> two(2, Eigen::Vector3d::Zero());
    const std::vector<Eigen::Vector3d> three(3, Eigen::Vector3d::Zero());
    EXPECT_EQ(computeAte(two, three).status().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(computeAte({}, {}).status().code(), StatusCode::kInvalidArgument);
    EXPECT_FALSE(computeAte(two, two).isOk());  // too few to align
    EXPECT_TRUE(computeAte(two, two, AteOptions{false}).isOk());
    std::vector<Eigen::Vector3d> nan = three;
    nan[1].y() = std::nan("");
    const auto bad = computeAte(nan, three);
    ASSERT_FALSE(bad.isOk());
    EXPECT_NE(bad.status().message().find("position 1 of the estimate"), std::string::npos);
}

TEST(Rpe, ZeroForTheSameMotionInAnotherWorldFrame) {
    const io::Trajectory gt = walk(300, 0.0, 0.1, 6);
    std::vector<Eigen::Isometry3d> est;
    for (const Eigen::Isometry3d& T : poses(gt)) est.push_back(knownTransform() * T);
    const Result<RpeResult> rpe = computeRpe(est, poses(gt), {});
    ASSERT_TRUE(rpe.isOk()) << rpe.status().toString();
    EXPECT_EQ(rpe->num_pairs, 299u);
    EXPECT_LT(rpe->trans_max_m, 1e-9);
    EXPECT_LT(rpe->rot_max_rad, 1e-7);
}

TEST(Rpe, AJumpShowsUpOnceWithItsExactSize) {
    // The estimate jumps by J (5 cm and 0.1 rad, in the world frame) between poses 49 and 50:
    // only the motion pair (49, 50) is wrong, by G_49^-1 J G_49 (|t| = 5 cm, angle 0.1 rad).
    const io::Trajectory gt = walk(100, 0.0, 0.1, 7);
    Eigen::Isometry3d J = Eigen::Isometry3d::Identity();
    J.linear() = lie::expSO3(Eigen::Vector3d(0.0, 0.0, 0.1));
    J.translation() = Eigen::Vector3d(0.03, 0.0, 0.04);
    const Eigen::Isometry3d expected = gt[49].T_W_C.inverse() * J * gt[49].T_W_C;
    std::vector<Eigen::Isometry3d> est = poses(gt);
    for (size_t k = 50; k < est.size(); ++k) est[k] = J * est[k];

    const Result<RpeResult> rpe = computeRpe(est, poses(gt), {});
    ASSERT_TRUE(rpe.isOk());
    EXPECT_EQ(rpe->num_pairs, 99u);
    EXPECT_NEAR(rpe->trans_errors_m[49], expected.translation().norm(), 1e-12);
    EXPECT_NEAR(rpe->rot_errors_rad[49], 0.1, 1e-9);
    EXPECT_NEAR(rpe->rot_max_rad, 0.1, 1e-9);
    EXPECT_NEAR(rpe->rot_rmse_rad, 0.1 / std::sqrt(99.0), 1e-9);
    EXPECT_LT(rpe->rot_median_rad, 1e-9);
    EXPECT_LT(rpe->trans_median_m, 1e-9);
}

TEST(Rpe, TimeDeltaPicksTheClosestStamp) {
    const io::Trajectory gt = walk(100, 5.0, 0.1, 8);
    io::Trajectory noisy = gt;
    std::mt19937_64 rng(9);
    std::normal_distribution<double> n(0.0, 0.01);
    for (io::StampedPose& p : noisy) p.T_W_C.translation() += Eigen::Vector3d(n(rng), n(rng), 0.0);
    std::vector<double> stamps;
    for (const io::StampedPose& p : gt) stamps.push_back(p.timestamp_s);

    const Result<RpeResult> by_frames = computeRpe(poses(noisy), poses(gt), {}, {5.0});
    const Result<RpeResult> by_time =
        computeRpe(poses(noisy), poses(gt), stamps, {0.5, DeltaUnit::kSeconds});
    ASSERT_TRUE(by_frames.isOk());
    ASSERT_TRUE(by_time.isOk()) << by_time.status().toString();
    EXPECT_EQ(by_frames->num_pairs, 95u);
    EXPECT_EQ(by_time->num_pairs, 95u);
    EXPECT_EQ(by_time->trans_errors_m, by_frames->trans_errors_m);
    // Two independent 1 cm (x, y) position errors: translational RPE RMSE ~ 2 cm.
    EXPECT_NEAR(by_frames->trans_rmse_m, 0.02, 0.004);

    EXPECT_EQ(computeRpe(poses(gt), poses(gt), {}, {100.0}).status().code(),
              StatusCode::kOutOfRange);
    EXPECT_EQ(computeRpe(poses(gt), poses(gt), {}, {1.5}).status().code(),
              StatusCode::kInvalidArgument);
    EXPECT_EQ(computeRpe(poses(gt), poses(gt), {}, {0.0}).status().code(),
              StatusCode::kInvalidArgument);
}

TEST(EvaluateTrajectories, AssociatesByTimeThenMeasures) {
    // Ground truth at 100 Hz; the estimate at 33 Hz takes every third gt pose, moved into
    // another world frame, stamped up to 4.5 ms late by a clock 50 s behind. With the right
    // offset every estimate finds its own gt pose, so ATE and RPE are ~0.
    const io::Trajectory gt = walk(1000, 1000.0, 0.01, 10);
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> jitter(0.0, 0.0045);
    io::Trajectory est;
    for (size_t k = 0; k < gt.size(); k += 3) {
        est.push_back({gt[k].timestamp_s + jitter(rng) - 50.0, knownTransform() * gt[k].T_W_C});
    }
    TrajectoryEvalConfig config;
    config.offset_s = 50.0;
    const Result<TrajectoryEvaluation> e = evaluateTrajectories(est, gt, config);
    ASSERT_TRUE(e.isOk()) << e.status().toString();
    EXPECT_EQ(e->num_est, 334u);
    EXPECT_EQ(e->num_gt, 1000u);
    ASSERT_EQ(e->pairs.size(), 334u);
    for (size_t k = 0; k < e->pairs.size(); ++k) {
        EXPECT_EQ(e->pairs[k], std::make_pair(3 * k, k));
    }
    EXPECT_LT(e->ate.rmse_m, 1e-9);
    ASSERT_TRUE(e->rpe.has_value());
    EXPECT_EQ(e->rpe->num_pairs, 333u);
    EXPECT_LT(e->rpe->trans_max_m, 1e-9);

    // Exact stamps (frame indices) give exactly zero.
    io::Trajectory same = gt;
    for (io::StampedPose& p : same) p.T_W_C = knownTransform() * p.T_W_C;
    const auto exact = evaluateTrajectories(same, gt, 0.02, 0.0);
    ASSERT_TRUE(exact.isOk());
    EXPECT_EQ(exact->pairs.size(), 1000u);
    EXPECT_LT(exact->ate.rmse_m, 1e-9);
    EXPECT_LT(exact->rpe->trans_rmse_m, 1e-9);

    // Without the offset nothing associates, and the message says why.
    const auto none = evaluateTrajectories(est, gt, 0.02, 0.0);
    ASSERT_FALSE(none.isOk());
    EXPECT_NE(none.status().message().find("no estimated pose is within 0.02 s"), std::string::npos)
        << none.status().message();
}

}  // namespace
}  // namespace plumb::eval
