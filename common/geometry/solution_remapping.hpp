// SPDX-License-Identifier: Apache-2.0
#pragma once

// Solution remapping (Zhang, Kaess, Singh, ICRA 2016) for point-to-plane Gauss-Newton in twist
// coordinates xi = (omega, v): translations the geometry does not constrain are left out of the
// solve. Used by the tracker's frame-to-model ICP and by the backend's fragment ICP.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

namespace plumb::remapping {

/// A 6 x k basis of twist directions, k <= 6, with no heap allocation.
using Basis = Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, 6>;

/// The directions solved for: the three rotations, then the translations along the eigenvectors
/// of `spread` (sum n n^T / correspondences, whose eigenvalues are the mean (n.t)^2 along them)
/// with an eigenvalue of at least min_normal_spread. A twist [0, t] translates by t.
inline Basis solvedDirections(const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>& spread,
                              double min_normal_spread) {
    Basis basis = Basis::Zero(6, 6);
    int k = 0;
    for (int i = 0; i < 3; ++i) basis(i, k++) = 1.0;
    for (int i = 0; i < 3; ++i) {
        if (!(spread.eigenvalues()(i) >= min_normal_spread)) continue;
        basis.block<3, 1>(3, k++) = spread.eigenvectors().col(i);
    }
    basis.conservativeResize(6, k);
    return basis;
}

}  // namespace plumb::remapping
