// SPDX-License-Identifier: Apache-2.0
#pragma once

// Internal helpers of the registration stage (not part of the public API): a nanoflann k-d tree
// over Eigen float points, deterministic voxel downsampling, and a chunked parallel reduction whose
// result does not depend on the thread count.

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <nanoflann.hpp>
#include <utility>
#include <vector>

#include "common/cloud/point_cloud.hpp"

namespace plumb::registration::detail {

/// nanoflann dataset adaptor over a vector of points (the vector must outlive the tree).
struct PointsAdaptor {
    const std::vector<Eigen::Vector3f>* points = nullptr;
    size_t kdtree_get_point_count() const { return points->size(); }
    float kdtree_get_pt(size_t i, size_t dim) const { return (*points)[i][static_cast<int>(dim)]; }
    template <class Box>
    bool kdtree_get_bbox(Box& /*bb*/) const {
        return false;
    }
};

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
    /// Up to `k` nearest points within sqrt(radius_sq), closest first; returns the count.
    size_t knnWithin(const Eigen::Vector3f& q, size_t k, float radius_sq, uint32_t* indices,
                     float* dists_sq) const;
    size_t size() const { return adaptor_.points->size(); }

  private:
    using Tree = nanoflann::KDTreeSingleIndexAdaptor<
        nanoflann::L2_Simple_Adaptor<float, PointsAdaptor, float, uint32_t>, PointsAdaptor, 3,
        uint32_t>;
    PointsAdaptor adaptor_;
    std::unique_ptr<Tree> tree_;
};

/// Averages points (and normals, renormalised, when present) per voxel of edge `voxel_m`. Output
/// order is the lexicographic order of the voxel keys (x, then y, then z), so the result is
/// independent of the input order of points within a voxel only up to float summation order
/// (the input order is kept). Points with a non-finite coordinate are skipped.
PointCloud voxelDownsample(const PointCloud& cloud, double voxel_m);

/// Calls fn(i) for i in [0, n) on up to `num_threads` workers (0 = TBB default, 1 = inline).
template <typename Fn>
void parallelFor(int num_threads, size_t n, const Fn& fn) {
    if (n == 0) return;
    if (num_threads == 1 || n == 1) {
        for (size_t i = 0; i < n; ++i) fn(i);
        return;
    }
    auto body = [&] {
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n),
                          [&](const tbb::blocked_range<size_t>& r) {
                              for (size_t i = r.begin(); i != r.end(); ++i) fn(i);
                          });
    };
    if (num_threads > 1) {
        tbb::task_arena arena(num_threads);
        arena.execute(body);
    } else {
        body();
    }
}

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
