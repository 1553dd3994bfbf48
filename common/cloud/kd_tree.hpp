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

  private:
    Adaptor adaptor_;
    Index index_;
};

}  // namespace plumb
