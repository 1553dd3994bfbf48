// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "common/geometry/lie.hpp"

namespace plumb::lie {
namespace {

Eigen::Vector3d randomUnit(std::mt19937_64& rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    return Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
}

Vector6d randomTwist(std::mt19937_64& rng, double max_angle) {
    std::uniform_real_distribution<double> angle(0.0, max_angle);
    std::normal_distribution<double> n(0.0, 1.0);
    Vector6d xi;
    xi.head<3>() = angle(rng) * randomUnit(rng);
    xi.tail<3>() = Eigen::Vector3d(n(rng), n(rng), n(rng));
    return xi;
}

double maxAbs(const Eigen::MatrixXd& m) { return m.cwiseAbs().maxCoeff(); }

/// R = I + sin(t) K + (1 - cos(t)) K^2 for a unit axis: an independent rotation oracle.
Eigen::Matrix3d axisAngle(const Eigen::Vector3d& axis, double angle) {
    return Eigen::AngleAxisd(angle, axis).toRotationMatrix();
}

TEST(Skew, IsTheCrossProductMatrix) {
    const Eigen::Vector3d a(0.3, -1.2, 2.5), b(-0.7, 0.4, 1.1);
    EXPECT_LT((skew(a) * b - a.cross(b)).norm(), 1e-15);
    EXPECT_LT(maxAbs(skew(a) + skew(a).transpose()), 1e-15);
}

TEST(ExpLogSO3, RoundTripForRandomAngles) {
    std::mt19937_64 rng(11);
    double worst_omega = 0.0, worst_rotation = 0.0;
    for (int k = 0; k < 2000; ++k) {
        const Eigen::Vector3d omega = randomTwist(rng, M_PI - 1e-3).head<3>();
        const Eigen::Matrix3d R = expSO3(omega);
        EXPECT_LT(maxAbs(R - axisAngle(omega.normalized(), omega.norm())), 1e-14);
        worst_omega = std::max(worst_omega, (logSO3(R) - omega).norm());
        worst_rotation = std::max(worst_rotation, maxAbs(expSO3(logSO3(R)) - R));
    }
    EXPECT_LT(worst_omega, 1e-12);
    // 1.2e-13 on aarch64, where GCC contracts multiply-adds into FMAs (x86-64 up to x86-64-v2
    // has no FMA): a few ulps of the angles near pi.
    EXPECT_LT(worst_rotation, 1e-12);
}

TEST(ExpLogSO3, TinyAnglesKeepRelativePrecision) {
    std::mt19937_64 rng(12);
    for (double angle : {1e-9, 3e-8, 1e-7, 5e-6, 2e-5}) {
        const Eigen::Vector3d omega = angle * randomUnit(rng);
        const Eigen::Matrix3d R = expSO3(omega);
        // First-order exactness: R - I = [omega]_x + O(angle^2).
        EXPECT_LT(maxAbs(R - Eigen::Matrix3d::Identity() - skew(omega)), angle * angle);
        EXPECT_LT((logSO3(R) - omega).norm(), 1e-8 * angle) << "angle " << angle;
        EXPECT_LT(maxAbs(R.transpose() * R - Eigen::Matrix3d::Identity()), 1e-15);
    }
    EXPECT_EQ(logSO3(Eigen::Matrix3d::Identity()).norm(), 0.0);
}

TEST(ExpLogSO3, AnglesNearPiRecoverAxisUpToSign) {
    std::mt19937_64 rng(13);
    for (double eps : {0.0, 1e-12, 1e-9, 1e-6, 1e-5, 1e-4, 2e-4, 1e-3}) {
        for (int k = 0; k < 50; ++k) {
            const Eigen::Vector3d axis = randomUnit(rng);
            const double angle = M_PI - eps;
            const Eigen::Matrix3d R = axisAngle(axis, angle);
            const Eigen::Vector3d omega = logSO3(R);
            EXPECT_NEAR(omega.norm(), angle, 1e-7) << "eps " << eps;
            // At exactly pi, +axis and -axis are the same rotation.
            const double axis_error =
                eps == 0.0 ? std::min((omega - angle * axis).norm(), (omega + angle * axis).norm())
                           : (omega - angle * axis).norm();
            EXPECT_LT(axis_error, 1e-6) << "eps " << eps;
            EXPECT_LT(maxAbs(expSO3(omega) - R), 1e-6) << "eps " << eps;
        }
    }
}

TEST(ExpLogSE3, RoundTrip) {
    std::mt19937_64 rng(14);
    double worst = 0.0, worst_pose = 0.0;
    for (int k = 0; k < 1000; ++k) {
        const Vector6d xi = randomTwist(rng, M_PI - 1e-3);
        const Eigen::Isometry3d T = expSE3(xi);
        EXPECT_TRUE(isValidPose(T, 1e-12));
        worst = std::max(worst, (logSE3(T) - xi).norm());
        worst_pose = std::max(worst_pose, maxAbs(expSE3(logSE3(T)).matrix() - T.matrix()));
    }
    EXPECT_LT(worst, 1e-9);
    EXPECT_LT(worst_pose, 1e-12);
    // Pure translation and tiny rotation.
    Vector6d xi;
    xi << 1e-9, -2e-9, 0.5e-9, 0.3, -0.2, 1.5;
    EXPECT_LT((logSE3(expSE3(xi)) - xi).norm(), 1e-15);
}

TEST(ExpSE3, TranslationIsLeftJacobianTimesUpsilon) {
    std::mt19937_64 rng(15);
    const Vector6d xi = randomTwist(rng, 2.0);
    const Eigen::Isometry3d T = expSE3(xi);
    EXPECT_LT((T.translation() - leftJacobianSO3(xi.head<3>()) * xi.tail<3>()).norm(), 1e-14);
    // J_l = integral_0^1 Exp(s omega) ds, checked by Simpson's rule.
    const Eigen::Vector3d omega = xi.head<3>();
    Eigen::Matrix3d integral = Eigen::Matrix3d::Zero();
    const int n = 200;
    for (int i = 0; i <= n; ++i) {
        const double w = (i == 0 || i == n) ? 1.0 : (i % 2 == 1 ? 4.0 : 2.0);
        integral += w * expSO3((static_cast<double>(i) / n) * omega);
    }
    integral /= 3.0 * n;
    EXPECT_LT(maxAbs(integral - leftJacobianSO3(omega)), 1e-9);
}

TEST(PointJacobian, MatchesCentralDifferencesOfLeftPerturbation) {
    std::mt19937_64 rng(16);
    const double h = 1e-6;
    for (int k = 0; k < 20; ++k) {
        const Eigen::Vector3d x = 3.0 * randomUnit(rng);
        Eigen::Matrix<double, 3, 6> numeric;
        for (int c = 0; c < 6; ++c) {
            Vector6d d = Vector6d::Zero();
            d(c) = h;
            numeric.col(c) = (expSE3(d) * x - expSE3(-d) * x) / (2.0 * h);
        }
        EXPECT_LT(maxAbs(numeric - pointJacobian(x)), 1e-8);
    }
}

TEST(LeftJacobian, MatchesFiniteDifferencesOfExpSO3) {
    // Exp(omega + d) = Exp(J_l(omega) d) Exp(omega) + O(d^2), so column c of J_l is
    // vee(log(Exp(omega + h e_c) Exp(omega)^T)) / h in the limit (central differences below).
    std::mt19937_64 rng(17);
    const double h = 1e-6;
    for (double max_angle : {1e-6, 0.5, 2.0, 3.0}) {
        for (int k = 0; k < 10; ++k) {
            const Eigen::Vector3d omega = randomTwist(rng, max_angle).head<3>();
            const Eigen::Matrix3d R = expSO3(omega);
            Eigen::Matrix3d numeric;
            for (int c = 0; c < 3; ++c) {
                const Eigen::Vector3d d = h * Eigen::Vector3d::Unit(c);
                numeric.col(c) = (logSO3(expSO3(omega + d) * R.transpose()) -
                                  logSO3(expSO3(omega - d) * R.transpose())) /
                                 (2.0 * h);
            }
            const Eigen::Matrix3d J = leftJacobianSO3(omega);
            EXPECT_LT(maxAbs(numeric - J), 1e-8) << "angle " << omega.norm();
            EXPECT_LT(maxAbs(leftJacobianInverseSO3(omega) * J - Eigen::Matrix3d::Identity()),
                      1e-12);
        }
    }
}

TEST(Interpolate, EndpointsMidpointAndConstantVelocity) {
    std::mt19937_64 rng(18);
    for (int k = 0; k < 50; ++k) {
        const Eigen::Isometry3d a = expSE3(randomTwist(rng, 3.0));
        const Eigen::Isometry3d b = a * expSE3(randomTwist(rng, 2.5));
        EXPECT_LT(maxAbs(interpolate(a, b, 0.0).matrix() - a.matrix()), 1e-12);
        EXPECT_LT(maxAbs(interpolate(a, b, 1.0).matrix() - b.matrix()), 1e-9);
        // Constant velocity: the half step applied twice gives b.
        const Eigen::Isometry3d m = interpolate(a, b, 0.5);
        const Eigen::Isometry3d half = a.inverse() * m;
        EXPECT_LT(maxAbs((a * half * half).matrix() - b.matrix()), 1e-9);
        // The midpoint is equidistant in rotation angle from both ends.
        EXPECT_NEAR(rotationAngle(a.inverse() * m), rotationAngle(m.inverse() * b), 1e-9);
    }
}

TEST(IsValidPose, RejectsNanAndNonOrthonormal) {
    std::mt19937_64 rng(19);
    Eigen::Isometry3d T = expSE3(randomTwist(rng, 3.0));
    EXPECT_TRUE(isValidPose(T));
    Eigen::Isometry3d nan_pose = T;
    nan_pose.translation().x() = std::nan("");
    EXPECT_FALSE(isValidPose(nan_pose));
    Eigen::Isometry3d inf_pose = T;
    inf_pose.linear()(1, 2) = std::numeric_limits<double>::infinity();
    EXPECT_FALSE(isValidPose(inf_pose));
    Eigen::Isometry3d scaled = T;
    scaled.linear() *= 1.01;
    EXPECT_FALSE(isValidPose(scaled));
    Eigen::Isometry3d reflection = T;
    reflection.linear().col(0) *= -1.0;  // orthonormal but det -1
    EXPECT_FALSE(isValidPose(reflection));
    Eigen::Isometry3d sheared = T;
    sheared.linear()(0, 1) += 1e-3;
    EXPECT_FALSE(isValidPose(sheared));
    EXPECT_TRUE(isValidPose(sheared, 1e-2));
    // orthonormalized() repairs a small perturbation to a valid rotation near the original.
    const Eigen::Isometry3d repaired = orthonormalized(sheared);
    EXPECT_TRUE(isValidPose(repaired, 1e-12));
    EXPECT_LT(maxAbs(repaired.linear() - T.linear()), 2e-3);
}

TEST(RotationAngle, EqualsTheAxisAngle) {
    std::mt19937_64 rng(20);
    for (double angle : {0.0, 1e-8, 0.3, 1.7, M_PI - 1e-6}) {
        Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
        T.linear() = axisAngle(randomUnit(rng), angle);
        EXPECT_NEAR(rotationAngle(T), angle, 1e-9) << angle;
    }
}

}  // namespace
}  // namespace plumb::lie
