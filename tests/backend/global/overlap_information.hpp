// SPDX-License-Identifier: Apache-2.0
#pragma once

// The information matrix of a pair prior from two prepared clouds, as the tests that build priors
// from ground truth need it (the global-registration and layout tests).

#include <Eigen/Geometry>
#include <cstdint>

#include "backend/global/global_registration.hpp"
#include "common/geometry/lie.hpp"

namespace plumb::testing {

/// Choi's information of a pair prior: sum of G^T G over the points q of cloud j with a neighbour
/// in cloud i within `max_distance_m` at the relative pose T_i_j (symmetrised).
inline Matrix6d overlapInformation(const global::GlobalCloud& cloud_i,
                                   const global::GlobalCloud& cloud_j,
                                   const Eigen::Isometry3d& T_i_j, double max_distance_m) {
    Matrix6d information = Matrix6d::Zero();
    for (const Eigen::Vector3d& q : cloud_j.points()) {
        uint32_t idx = 0;
        double d_sq = 0.0;
        if (!cloud_i.nearest(T_i_j * q, &idx, &d_sq) || d_sq > max_distance_m * max_distance_m) {
            continue;
        }
        const Eigen::Matrix<double, 3, 6> G = lie::pointJacobian(q);
        information += G.transpose() * G;
    }
    return 0.5 * (information + information.transpose());
}

}  // namespace plumb::testing
