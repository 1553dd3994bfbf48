// SPDX-License-Identifier: Apache-2.0
#pragma once

// The one nanoflann adaptor: an exact 3-D k-d tree over a vector of Eigen points, for nearest-
// neighbour queries in evaluation and registration.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <nanoflann.hpp>
#include <vector>

namespace plumb {

/// nanoflann dataset adaptor over `count` points starting at `points` (no copy).
template <typename Scalar>
struct PointsAdaptor {
    const Eigen::Matrix<Scalar, 3, 1>* points = nullptr;
    size_t count = 0;

    size_t kdtree_get_point_count() const { return count; }  // NOLINT
    Scalar kdtree_get_pt(size_t i, size_t dim) const {       // NOLINT
        return points[i][static_cast<Eigen::Index>(dim)];
    }
    template <class BoundingBox>
    bool kdtree_get_bbox(BoundingBox& /*bb*/) const {  // NOLINT
        return false;
    }
};

/// A k-d tree (leaves of up to 10 points, squared Euclidean distances of type Scalar, uint32_t
/// indices) over `points`. It keeps the points' buffer, not a copy: the vector must outlive the
/// tree and must not change (moving the vector keeps its buffer and is fine). Built in the
/// constructor; queries through index() (nanoflann's knnSearch, findNeighbors, radiusSearch) are
/// const and thread-safe.
template <typename Scalar>
class PointKdTree {
  public:
    using Adaptor = PointsAdaptor<Scalar>;
    using Index = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<Scalar, Adaptor>,
                                                      Adaptor, 3, uint32_t>;

    explicit PointKdTree(const std::vector<Eigen::Matrix<Scalar, 3, 1>>& points)
        : adaptor_{points.data(), points.size()},
          index_(3, adaptor_, nanoflann::KDTreeSingleIndexAdaptorParams(10)) {}
    PointKdTree(const PointKdTree&) = delete;  // the index refers to adaptor_
    PointKdTree& operator=(const PointKdTree&) = delete;

    const Index& index() const { return index_; }
    size_t size() const { return adaptor_.count; }
    /// Point i of the tree's buffer.
    const Eigen::Matrix<Scalar, 3, 1>& point(size_t i) const { return adaptor_.points[i]; }

    /// Where a nearest-point search for `query` limited to `max_dist_sq` can start, given a
    /// `hint` (a point index, any larger value for none) known to be near: the hint's squared
    /// distance, summed in nanoflann's order ((x^2 + y^2) + z^2) and widened by far more than
    /// the rounding of nanoflann's incremental box distances (a few ulps), so that no branch
    /// holding the nearest point is pruned for them. The nearest point is the one a search
    /// from `max_dist_sq` finds. `max_dist_sq` when that is smaller or there is no hint.
    Scalar searchBound(const Eigen::Matrix<Scalar, 3, 1>& query, uint32_t hint,
                       Scalar max_dist_sq) const {
        if (hint >= size()) return max_dist_sq;
        const Eigen::Matrix<Scalar, 3, 1>& p = point(hint);
        const Scalar dx = query.x() - p.x(), dy = query.y() - p.y(), dz = query.z() - p.z();
        Scalar to_hint = dx * dx;
        to_hint += dy * dy;
        to_hint += dz * dz;
        const Scalar widened = to_hint * (Scalar(1) + Scalar(1e-4)) + Scalar(1e-12);
        return widened < max_dist_sq ? widened : max_dist_sq;
    }

  private:
    Adaptor adaptor_;
    Index index_;
};

}  // namespace plumb
