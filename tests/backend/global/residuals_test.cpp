// SPDX-License-Identifier: Apache-2.0
// Analytic Jacobians of the global-registration residuals against central finite differences on
// left perturbations Exp(h e_k) T (reference §5.8).

#include <gtest/gtest.h>

#include <random>

#include "backend/global/residuals.hpp"
#include "common/geometry/lie.hpp"

namespace plumb::global {
namespace {

Eigen::Isometry3d randomPose(std::mt19937_64& rng, double angle, double dist) {
    std::normal_distribution<double> g(0.0, 1.0);
    Vector6d xi;
    for (int k = 0; k < 3; ++k) xi(k) = angle * g(rng);
    for (int k = 3; k < 6; ++k) xi(k) = dist * g(rng);
    return lie::expSE3(xi);
}

Eigen::Isometry3d perturbed(const Eigen::Isometry3d& T, int k, double h) {
    Vector6d xi = Vector6d::Zero();
    xi(k) = h;
    return lie::expSE3(xi) * T;
}

constexpr double kH = 1e-6;

TEST(GlobalResiduals, FragJacobiansMatchFiniteDifferences) {
    std::mt19937_64 rng(1);
    for (int trial = 0; trial < 20; ++trial) {
        const Eigen::Isometry3d Ti = randomPose(rng, 0.5, 2.0);
        const Eigen::Isometry3d Tj = randomPose(rng, 0.5, 2.0);
        const Eigen::Vector3d p = Eigen::Vector3d::Random() * 2.0;
        const Eigen::Vector3d q = Eigen::Vector3d::Random() * 2.0;
        const Eigen::Vector3d n = Eigen::Vector3d::Random().normalized();
        RowJacobian Ji, Jj;
        fragResidual(Ti, Tj, p, q, n, &Ji, &Jj);
        for (int k = 0; k < 6; ++k) {
            const double fd_i = (fragResidual(perturbed(Ti, k, kH), Tj, p, q, n) -
                                 fragResidual(perturbed(Ti, k, -kH), Tj, p, q, n)) /
                                (2 * kH);
            const double fd_j = (fragResidual(Ti, perturbed(Tj, k, kH), p, q, n) -
                                 fragResidual(Ti, perturbed(Tj, k, -kH), p, q, n)) /
                                (2 * kH);
            EXPECT_NEAR(Ji(k), fd_i, 1e-6) << "trial " << trial << " k " << k;
            EXPECT_NEAR(Jj(k), fd_j, 1e-6) << "trial " << trial << " k " << k;
        }
    }
}

TEST(GlobalResiduals, LayoutJacobianMatchesFiniteDifferences) {
    std::mt19937_64 rng(2);
    for (int trial = 0; trial < 20; ++trial) {
        const Eigen::Isometry3d Ti = randomPose(rng, 0.5, 2.0);
        const Eigen::Vector3d p = Eigen::Vector3d::Random() * 3.0;
        HessianPlane plane;
        plane.normal = Eigen::Vector3d::Random().normalized();
        plane.d = 1.7 * (trial - 10) / 10.0;
        RowJacobian J;
        const double r = layoutResidual(Ti, p, plane, &J);
        EXPECT_NEAR(r, plane.normal.dot(Ti * p) + plane.d, 1e-12);
        for (int k = 0; k < 6; ++k) {
            const double fd = (layoutResidual(perturbed(Ti, k, kH), p, plane) -
                               layoutResidual(perturbed(Ti, k, -kH), p, plane)) /
                              (2 * kH);
            EXPECT_NEAR(J(k), fd, 1e-6) << "trial " << trial << " k " << k;
        }
    }
}

TEST(GlobalResiduals, PairJacobiansMatchFiniteDifferences) {
    std::mt19937_64 rng(3);
    for (int trial = 0; trial < 20; ++trial) {
        const Eigen::Isometry3d Ti = randomPose(rng, 0.7, 3.0);
        const Eigen::Isometry3d Tj = randomPose(rng, 0.7, 3.0);
        // A prior near the current relative pose, off by up to ~0.3 rad / 0.3 m (so e0 != 0
        // and the inverse right Jacobian matters).
        const Eigen::Isometry3d T_ij = (Ti.inverse() * Tj) * randomPose(rng, 0.15, 0.15);
        Matrix6d Ji, Jj;
        const Vector6d e0 = pairResidual(Ti, Tj, T_ij, &Ji, &Jj);
        EXPECT_GT(e0.norm(), 1e-3);
        for (int k = 0; k < 6; ++k) {
            const Vector6d fd_i = (pairResidual(perturbed(Ti, k, kH), Tj, T_ij) -
                                   pairResidual(perturbed(Ti, k, -kH), Tj, T_ij)) /
                                  (2 * kH);
            const Vector6d fd_j = (pairResidual(Ti, perturbed(Tj, k, kH), T_ij) -
                                   pairResidual(Ti, perturbed(Tj, k, -kH), T_ij)) /
                                  (2 * kH);
            EXPECT_LT((Ji.col(k) - fd_i).cwiseAbs().maxCoeff(), 1e-6)
                << "trial " << trial << " k " << k;
            EXPECT_LT((Jj.col(k) - fd_j).cwiseAbs().maxCoeff(), 1e-6)
                << "trial " << trial << " k " << k;
        }
    }
}

TEST(GlobalResiduals, PairResidualIsZeroWhenConsistent) {
    std::mt19937_64 rng(4);
    const Eigen::Isometry3d Ti = randomPose(rng, 0.5, 1.0);
    const Eigen::Isometry3d Tj = randomPose(rng, 0.5, 1.0);
    EXPECT_LT(pairResidual(Ti, Tj, Ti.inverse() * Tj).norm(), 1e-12);
}

TEST(GlobalResiduals, AdjointConjugatesTheExponential) {
    std::mt19937_64 rng(5);
    const Eigen::Isometry3d T = randomPose(rng, 0.8, 2.0);
    Vector6d xi;
    xi << 0.1, -0.2, 0.3, 0.5, -0.4, 0.2;
    const Eigen::Isometry3d lhs = lie::expSE3(lie::adjointSE3(T) * xi);
    const Eigen::Isometry3d rhs = T * lie::expSE3(xi) * T.inverse();
    EXPECT_LT((lhs.matrix() - rhs.matrix()).cwiseAbs().maxCoeff(), 1e-12);
}

}  // namespace
}  // namespace plumb::global
