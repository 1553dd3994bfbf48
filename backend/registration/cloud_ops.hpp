// SPDX-License-Identifier: Apache-2.0
#pragma once

// Internal helpers of the registration stage (not part of the public API): a nanoflann k-d tree
// over Eigen float points, deterministic voxel downsampling, and a chunked parallel reduction whose
// result does not depend on the thread count.

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "common/cloud/kd_tree.hpp"
#include "common/cloud/point_cloud.hpp"
#include "common/core/parallel.hpp"

namespace plumb::registration::detail {

/// A 3-D k-d tree over `points` (kept by pointer: the vector must outlive the tree and not move).
/// Queries are const and thread-safe.
class KdTree3 {
  public:
    explicit KdTree3(const std::vector<Eigen::Vector3f>& points);
    KdTree3(const KdTree3&) = delete;
    KdTree3& operator=(const KdTree3&) = delete;

    /// Nearest point to `q`; false when the tree is empty or it is farther than sqrt(max_dist_sq).
    bool nearest(const Eigen::Vector3f& q, float max_dist_sq, uint32_t* index,
                 float* dist_sq) const;
    /// The same, given a point `hint` (an index; out of range: none) that may be near `q`, as
    /// the previous iteration's nearest point is in ICP: the search starts from the hint's
    /// distance (when within the limit; widened by 1e-4 of itself, far beyond the rounding of
    /// the tree's box distances) rather than the limit, and prunes what lies beyond. The result
    /// is nearest()'s: the points at the smallest distance are met in the same order (the
    /// tree's branches are visited in an order that depends on `q` only) and the first is kept
    /// either way.
    bool nearest(const Eigen::Vector3f& q, float max_dist_sq, uint32_t hint, uint32_t* index,
                 float* dist_sq) const;
    /// Up to `k` nearest points within sqrt(radius_sq), closest first; returns the count.
    size_t knnWithin(const Eigen::Vector3f& q, size_t k, float radius_sq, uint32_t* indices,
                     float* dists_sq) const;
    size_t size() const { return tree_.size(); }

  private:
    PointKdTree<float> tree_;
};

/// Averages points (and normals, renormalised, when present) per voxel of edge `voxel_m`. Output
/// order is the lexicographic order of the voxel keys (x, then y, then z), so the result is
/// independent of the input order of points within a voxel only up to float summation order
/// (the input order is kept). Points with a non-finite coordinate are skipped.
PointCloud voxelDownsample(const PointCloud& cloud, double voxel_m);

using plumb::parallelFor;  // common/core/parallel.hpp

/// Deterministic reduction: [0, n) is cut into fixed chunks of `chunk` items (independent of the
/// thread count); chunk c accumulates into its own Acc (fn(acc, i)), and the chunk results are
/// summed in chunk order with `combine(total, part)`.
template <typename Acc, typename Fn, typename Combine>
Acc chunkedReduce(int num_threads, size_t n, size_t chunk, const Acc& zero, const Fn& fn,
                  const Combine& combine) {
    const size_t num_chunks = (n + chunk - 1) / chunk;
    std::vector<Acc> parts(num_chunks, zero);
    parallelFor(num_threads, num_chunks, [&](size_t c) {
        const size_t end = std::min(n, (c + 1) * chunk);
        for (size_t i = c * chunk; i < end; ++i) fn(parts[c], i);
    });
    Acc total = zero;
    for (const Acc& p : parts) combine(total, p);
    return total;
}

}  // namespace plumb::registration::detail
