// SPDX-License-Identifier: Apache-2.0
#pragma once

// SO(3)/SE(3) helpers. Conventions (DESIGN.md): twists are xi = (omega, upsilon), rotation first;
// updates are left multiplications T <- Exp(xi) T. For a world point x = T p the derivative of
// Exp(xi) x at xi = 0 is [ -[x]_x | I_3 ] (pointJacobian below).
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace plumb {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

}  // namespace plumb

namespace plumb::lie {

/// [v]_x, the cross-product matrix: skew(a) * b == a.cross(b).
Eigen::Matrix3d skew(const Eigen::Vector3d& v);

/// Rodrigues' formula. Exact to machine precision for all |omega|; Taylor series near 0.
Eigen::Matrix3d expSO3(const Eigen::Vector3d& omega);

/// Inverse of expSO3, returning |omega| in [0, pi]. R must be a rotation (orthonormal, det +1).
Eigen::Vector3d logSO3(const Eigen::Matrix3d& R);

/// Left Jacobian of SO(3), J_l(omega), with Exp([omega; upsilon]) translation = J_l(omega) upsilon.
Eigen::Matrix3d leftJacobianSO3(const Eigen::Vector3d& omega);

/// Inverse of the left Jacobian of SO(3).
Eigen::Matrix3d leftJacobianInverseSO3(const Eigen::Vector3d& omega);

/// Exp: se(3) -> SE(3) for xi = (omega, upsilon).
Eigen::Isometry3d expSE3(const Vector6d& xi);

/// Log: SE(3) -> se(3), inverse of expSE3, xi = (omega, upsilon).
Vector6d logSE3(const Eigen::Isometry3d& T);

/// Adjoint of T for twists (omega, upsilon): Exp(Ad(T) xi) = T Exp(xi) T^-1,
/// Ad(T) = [[R, 0], [[t]_x R, R]]. An information matrix Λ_L of a left perturbation
/// Exp(xi_L) T is Ad(T)^T Λ_L Ad(T) for the right perturbation T Exp(xi_R).
Matrix6d adjointSE3(const Eigen::Isometry3d& T);

/// ad(xi) = [[ [omega]_x, 0 ], [ [upsilon]_x, [omega]_x ]] (the Lie bracket [xi, .]).
Matrix6d adSE3(const Vector6d& xi);

/// d(Exp(xi) x)/d xi at xi = 0 for a point x: [ -[x]_x | I_3 ] (3x6).
Eigen::Matrix<double, 3, 6> pointJacobian(const Eigen::Vector3d& x);

/// Geodesic interpolation on SE(3): T_a * Exp(alpha * Log(T_a^-1 T_b)); alpha in [0, 1] gives the
/// constant-velocity path from T_a (alpha = 0) to T_b (alpha = 1).
Eigen::Isometry3d interpolate(const Eigen::Isometry3d& T_a, const Eigen::Isometry3d& T_b,
                              double alpha);

/// Re-orthonormalises the rotation part (nearest rotation in the Frobenius sense).
Eigen::Isometry3d orthonormalized(const Eigen::Isometry3d& T);

/// Rotation angle of T in radians, in [0, pi].
double rotationAngle(const Eigen::Isometry3d& T);

/// True when every entry of T is finite and its rotation is orthonormal within `tolerance`.
bool isValidPose(const Eigen::Isometry3d& T, double tolerance = 1e-6);

}  // namespace plumb::lie
