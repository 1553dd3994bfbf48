// SPDX-License-Identifier: Apache-2.0
#include "common/geometry/lie.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

namespace plumb::lie {
namespace {

constexpr double kSmallAngle = 1e-5;

}  // namespace

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
    Eigen::Matrix3d m;
    m << 0.0, -v.z(), v.y(),  //
        v.z(), 0.0, -v.x(),   //
        -v.y(), v.x(), 0.0;
    return m;
}

Eigen::Matrix3d expSO3(const Eigen::Vector3d& omega) {
    const double theta2 = omega.squaredNorm();
    const double theta = std::sqrt(theta2);
    const Eigen::Matrix3d W = skew(omega);
    double a, b;  // R = I + a W + b W^2
    if (theta < kSmallAngle) {
        a = 1.0 - theta2 / 6.0;
        b = 0.5 - theta2 / 24.0;
    } else {
        a = std::sin(theta) / theta;
        b = (1.0 - std::cos(theta)) / theta2;
    }
    return Eigen::Matrix3d::Identity() + a * W + b * W * W;
}

Eigen::Vector3d logSO3(const Eigen::Matrix3d& R) {
    // R = cos(t) I + sin(t) [a]_x + (1 - cos(t)) a a^T, so vee(R - R^T) = 2 sin(t) a and
    // trace(R) = 1 + 2 cos(t). atan2 keeps t accurate near 0 and near pi, where acos is not.
    const Eigen::Vector3d vee(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));
    const double cos_theta = std::clamp(0.5 * (R.trace() - 1.0), -1.0, 1.0);
    const double theta = std::atan2(0.5 * vee.norm(), cos_theta);
    if (theta < kSmallAngle) {
        // sin(theta)/theta ~ 1 - theta^2/6: omega = vee / (2 sinc(theta)).
        return 0.5 * (1.0 + theta * theta / 6.0) * vee;
    }
    if (M_PI - theta < 1e-4) {
        // Near pi the vee part vanishes; take the axis from the symmetric part,
        // (R + R^T)/2 - cos(t) I = (1 - cos(t)) a a^T exactly, using its best-conditioned column
        // and the sign of vee (meaningless only at t = pi exactly, where both signs are right).
        const Eigen::Matrix3d A =
            (0.5 * (R + R.transpose()) - cos_theta * Eigen::Matrix3d::Identity()) /
            (1.0 - cos_theta);
        int k = 0;
        A.diagonal().maxCoeff(&k);
        Eigen::Vector3d axis = A.col(k) / std::sqrt(std::max(A(k, k), 1e-300));
        axis.normalize();
        if (axis.dot(vee) < 0.0) axis = -axis;
        return theta * axis;
    }
    return theta / (2.0 * std::sin(theta)) * vee;
}

Eigen::Matrix3d leftJacobianSO3(const Eigen::Vector3d& omega) {
    const double theta2 = omega.squaredNorm();
    const double theta = std::sqrt(theta2);
    const Eigen::Matrix3d W = skew(omega);
    double a, b;  // J = I + a W + b W^2
    if (theta < kSmallAngle) {
        a = 0.5 - theta2 / 24.0;
        b = 1.0 / 6.0 - theta2 / 120.0;
    } else {
        a = (1.0 - std::cos(theta)) / theta2;
        b = (theta - std::sin(theta)) / (theta2 * theta);
    }
    return Eigen::Matrix3d::Identity() + a * W + b * W * W;
}

Eigen::Matrix3d leftJacobianInverseSO3(const Eigen::Vector3d& omega) {
    const double theta2 = omega.squaredNorm();
    const double theta = std::sqrt(theta2);
    const Eigen::Matrix3d W = skew(omega);
    double b;  // J^-1 = I - W/2 + b W^2
    if (theta < kSmallAngle) {
        b = 1.0 / 12.0 + theta2 / 720.0;
    } else {
        b = (1.0 - theta * std::sin(theta) / (2.0 * (1.0 - std::cos(theta)))) / theta2;
    }
    return Eigen::Matrix3d::Identity() - 0.5 * W + b * W * W;
}

Eigen::Isometry3d expSE3(const Vector6d& xi) {
    const Eigen::Vector3d omega = xi.head<3>();
    const Eigen::Vector3d upsilon = xi.tail<3>();
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = expSO3(omega);
    T.translation() = leftJacobianSO3(omega) * upsilon;
    return T;
}

Vector6d logSE3(const Eigen::Isometry3d& T) {
    const Eigen::Vector3d omega = logSO3(T.linear());
    Vector6d xi;
    xi.head<3>() = omega;
    xi.tail<3>() = leftJacobianInverseSO3(omega) * T.translation();
    return xi;
}

Matrix6d adjointSE3(const Eigen::Isometry3d& T) {
    Matrix6d A = Matrix6d::Zero();
    const Eigen::Matrix3d R = T.linear();
    A.topLeftCorner<3, 3>() = R;
    A.bottomRightCorner<3, 3>() = R;
    A.bottomLeftCorner<3, 3>() = skew(T.translation()) * R;
    return A;
}

Matrix6d adSE3(const Vector6d& xi) {
    Matrix6d a = Matrix6d::Zero();
    const Eigen::Matrix3d W = skew(xi.head<3>());
    a.topLeftCorner<3, 3>() = W;
    a.bottomRightCorner<3, 3>() = W;
    a.bottomLeftCorner<3, 3>() = skew(xi.tail<3>());
    return a;
}

Eigen::Matrix<double, 3, 6> pointJacobian(const Eigen::Vector3d& x) {
    Eigen::Matrix<double, 3, 6> J;
    J.leftCols<3>() = -skew(x);
    J.rightCols<3>().setIdentity();
    return J;
}

Eigen::Isometry3d interpolate(const Eigen::Isometry3d& T_a, const Eigen::Isometry3d& T_b,
                              double alpha) {
    const Vector6d xi = logSE3(T_a.inverse() * T_b);
    return T_a * expSE3(alpha * xi);
}

Eigen::Isometry3d orthonormalized(const Eigen::Isometry3d& T) {
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(T.linear(), Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d R = svd.matrixU() * svd.matrixV().transpose();
    if (R.determinant() < 0.0) {
        Eigen::Matrix3d U = svd.matrixU();
        U.col(2) *= -1.0;
        R = U * svd.matrixV().transpose();
    }
    Eigen::Isometry3d out = T;
    out.linear() = R;
    return out;
}

double rotationAngle(const Eigen::Isometry3d& T) { return logSO3(T.linear()).norm(); }

bool isValidPose(const Eigen::Isometry3d& T, double tolerance) {
    if (!T.matrix().allFinite()) return false;
    const Eigen::Matrix3d R = T.linear();
    if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > tolerance) {
        return false;
    }
    const Eigen::RowVector4d last = T.matrix().row(3);
    return (last - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() <= tolerance &&
           std::abs(R.determinant() - 1.0) <= tolerance;
}

}  // namespace plumb::lie
