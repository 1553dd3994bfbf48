// SPDX-License-Identifier: Apache-2.0
#pragma once

// The three residuals of the layout-constrained global registration (Lee et al. ICCV 2017 §3.3,
// reference §5.3-5.4) with their analytic Jacobians under left perturbations T <- Exp(xi) T,
// xi = (omega, upsilon) (DESIGN.md). Exposed for the finite-difference tests and for anyone who
// wants to evaluate the objective; global_registration.cpp builds the normal equations from them.
//
// Pure functions, thread-safe.

#include <Eigen/Geometry>

#include "common/geometry/lie.hpp"
#include "common/layout/layout.hpp"

namespace plumb::global {

using RowJacobian = Eigen::Matrix<double, 1, 6>;

/// E_frag, paper Eq. (9): point-to-plane distance between a point p of fragment i and its
/// correspondence q (normal n_q) of fragment j, both in their fragment frames:
///   x_i = T_i p, x_j = T_j q, m = R_j n_q,   r = (x_i - x_j)^T m.
/// Derivation (left perturbations, x -> x + omega x x + upsilon, m -> m + omega x m):
///   dr/dxi_i = [ (x_i x m)^T , m^T ]
///   dr/dxi_j = [ -(x_j x m)^T + (m x (x_i - x_j))^T , -m^T ] = -dr/dxi_i,
/// (the residual is invariant to a common left perturbation of both poses).
double fragResidual(const Eigen::Isometry3d& T_W_i, const Eigen::Isometry3d& T_W_j,
                    const Eigen::Vector3d& p_i, const Eigen::Vector3d& q_j,
                    const Eigen::Vector3d& n_q_j, RowJacobian* J_i = nullptr,
                    RowJacobian* J_j = nullptr);
/// The same from the world points x_i = T_i p, x_j = T_j q and normal m = R_j n_q (computed once
/// per point when a point has several correspondences); fragResidual is this at T_i p, T_j q,
/// R_j n_q.
double fragResidualWorld(const Eigen::Vector3d& x_i, const Eigen::Vector3d& x_j,
                         const Eigen::Vector3d& m, RowJacobian* J_i = nullptr,
                         RowJacobian* J_j = nullptr);

/// E_layout, paper Eq. (8): distance of x = T_i p from a layout plane (n_L, d_L) in the world
/// frame. The paper writes (x - q)^T m with the virtual point q = x - (n_L.x + d_L) n_L on the
/// plane and the point normal m; we use the plane normal (reference §5.3, "cleaner variant"),
/// which is the exact point-to-plane distance and equals the paper's form when m = ±n_L (the
/// normal gate keeps m within a few degrees of n_L):
///   r = n_L^T x + d_L,   dr/dxi_i = [ (x x n_L)^T , n_L^T ].
double layoutResidual(const Eigen::Isometry3d& T_W_i, const Eigen::Vector3d& p_i,
                      const HessianPlane& plane_W, RowJacobian* J_i = nullptr);

/// E_pair, paper Eq. (10), in the pose-graph form of Choi et al. 2015 (reference §5.4, the
/// "principled alternative"; the same residual as backend/posegraph):
///   E = T_i_j^-1 T_i^-1 T_j  (the error transform acting on fragment-j points),  e = Log(E).
/// With xi_i, xi_j left perturbations, to first order
///   E(xi) = E0 Exp(Ad(T_j^-1) (xi_j - xi_i)),   e(xi) = e0 + Jr^-1(e0) Ad(T_j^-1) (xi_j - xi_i),
/// so de/dxi_j = Jr^-1(e0) Ad(T_j^-1) and de/dxi_i = -de/dxi_j.
Vector6d pairResidual(const Eigen::Isometry3d& T_W_i, const Eigen::Isometry3d& T_W_j,
                      const Eigen::Isometry3d& T_i_j, Matrix6d* J_i = nullptr,
                      Matrix6d* J_j = nullptr);

/// Inverse right Jacobian of SE(3): Log(Exp(xi) Exp(eta)) = xi + Jr^-1(xi) eta + O(|eta|^2).
/// Jr(xi) = sum_n (-ad(xi))^n / (n+1)!, summed to machine precision and inverted; valid for
/// rotation angles below pi.
Matrix6d rightJacobianInverseSE3(const Vector6d& xi);

}  // namespace plumb::global
