// SPDX-License-Identifier: Apache-2.0
#include "backend/global/residuals.hpp"

#include <cmath>

namespace plumb::global {

double fragResidual(const Eigen::Isometry3d& T_W_i, const Eigen::Isometry3d& T_W_j,
                    const Eigen::Vector3d& p_i, const Eigen::Vector3d& q_j,
                    const Eigen::Vector3d& n_q_j, RowJacobian* J_i, RowJacobian* J_j) {
    return fragResidualWorld(T_W_i * p_i, T_W_j * q_j, T_W_j.linear() * n_q_j, J_i, J_j);
}

double fragResidualWorld(const Eigen::Vector3d& x_i, const Eigen::Vector3d& x_j,
                         const Eigen::Vector3d& m, RowJacobian* J_i, RowJacobian* J_j) {
    // Eq. (9): r = (x_i - x_j)^T m.
    const double r = (x_i - x_j).dot(m);
    if (J_i != nullptr || J_j != nullptr) {
        RowJacobian J;
        J.head<3>() = x_i.cross(m).transpose();
        J.tail<3>() = m.transpose();
        if (J_i != nullptr) *J_i = J;
        if (J_j != nullptr) *J_j = -J;
    }
    return r;
}

double layoutResidual(const Eigen::Isometry3d& T_W_i, const Eigen::Vector3d& p_i,
                      const HessianPlane& plane_W, RowJacobian* J_i) {
    const Eigen::Vector3d x = T_W_i * p_i;
    // Eq. (8) with the layout normal: r = n_L^T x + d_L.
    const double r = plane_W.signedDistance(x);
    if (J_i != nullptr) {
        J_i->head<3>() = x.cross(plane_W.normal).transpose();
        J_i->tail<3>() = plane_W.normal.transpose();
    }
    return r;
}

Matrix6d rightJacobianInverseSE3(const Vector6d& xi) {
    // Jr = sum_n (-ad)^n / (n+1)!; the terms shrink like |xi|^n / (n+1)!, so the sum is exact to
    // machine precision after a few dozen terms for any |xi| this is used with (pose errors).
    const Matrix6d minus_ad = -lie::adSE3(xi);
    Matrix6d Jr = Matrix6d::Identity();
    Matrix6d term = Matrix6d::Identity();
    for (int n = 1; n < 60; ++n) {
        term = term * minus_ad / static_cast<double>(n + 1);
        Jr += term;
        if (term.cwiseAbs().maxCoeff() < 1e-18) break;
    }
    return Jr.inverse();
}

Vector6d pairResidual(const Eigen::Isometry3d& T_W_i, const Eigen::Isometry3d& T_W_j,
                      const Eigen::Isometry3d& T_i_j, Matrix6d* J_i, Matrix6d* J_j) {
    // Eq. (10) in Choi's form: E = T_i_j^-1 T_i^-1 T_j, e = Log(E).
    const Eigen::Isometry3d E = T_i_j.inverse() * T_W_i.inverse() * T_W_j;
    const Vector6d e = lie::logSE3(E);
    if (J_i != nullptr || J_j != nullptr) {
        const Matrix6d Jj = rightJacobianInverseSE3(e) * lie::adjointSE3(T_W_j.inverse());
        if (J_j != nullptr) *J_j = Jj;
        if (J_i != nullptr) *J_i = -Jj;
    }
    return e;
}

}  // namespace plumb::global
