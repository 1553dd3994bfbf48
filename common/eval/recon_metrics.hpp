// SPDX-License-Identifier: Apache-2.0
#pragma once

// Reconstruction error (reference §6.1, the paper's "average / median distance from each
// reconstructed point to the closest ground-truth point", in metres here, cm in reports), plus
// RMS, 90th percentile, maximum, and the two coverage fractions:
//  - accuracy fraction: reconstructed points within `completeness_threshold_m` of the ground truth;
//  - completeness: ground-truth points within `completeness_threshold_m` of the reconstruction.
// Nearest neighbours are exact (nanoflann k-d tree, k = 1). Both point sets must be in the same
// frame; mapping the estimate into the ground-truth frame is the caller's job.
//
// Thread safety: the functions are pure; they run queries in parallel with TBB but every query
// writes its own slot and all reductions are serial in point order, so results are bit-identical
// for any thread count.

#include <Eigen/Core>
#include <cstddef>
#include <memory>
#include <vector>

#include "common/core/status.hpp"

namespace plumb {
template <typename Scalar>
class PointKdTree;
}  // namespace plumb

namespace plumb::eval {

struct ReconMetricsConfig {
    /// Distance below which a point counts as matched, for both the accuracy fraction and the
    /// completeness, metres.
    double completeness_threshold_m = 0.02;
    /// Worker threads for the nearest-neighbour queries; 0 = TBB's default. Results do not
    /// depend on it.
    int num_threads = 0;
};

/// Summary of a set of distances, metres. Percentiles interpolate linearly between order
/// statistics (position q (n - 1) in the sorted list, as numpy's default).
struct DistanceStats {
    size_t count = 0;
    double mean_m = 0.0;
    double median_m = 0.0;
    double rms_m = 0.0;
    double p90_m = 0.0;
    double max_m = 0.0;
};

struct ReconMetrics {
    size_t num_reconstructed = 0;  ///< reconstructed points evaluated
    size_t num_ground_truth = 0;   ///< ground-truth points
    double threshold_m = 0.0;      ///< the threshold used for the two fractions
    /// Reconstructed point -> closest ground-truth point (the paper's error).
    DistanceStats accuracy;
    /// Ground-truth point -> closest reconstructed point.
    DistanceStats completeness_distances;
    double accuracy_fraction = 0.0;  ///< share of reconstructed points within threshold_m of GT
    double completeness = 0.0;       ///< share of GT points within threshold_m of a recon point
};

/// A reference point set with its k-d tree, built once and then queried by any number of
/// callers, concurrently if they like (a run's ground truth, shared by every variant evaluated
/// against it and by the report's error map). It keeps the points' buffer, not a copy: the
/// vector must outlive it and must not change.
class ClosestPoints {
  public:
    /// kInvalidArgument when `reference` is empty or holds a point that is not finite.
    static Result<std::shared_ptr<const ClosestPoints>> build(
        const std::vector<Eigen::Vector3f>& reference);
    ~ClosestPoints();
    ClosestPoints(const ClosestPoints&) = delete;
    ClosestPoints& operator=(const ClosestPoints&) = delete;

    /// Distance from every query point to its closest reference point, metres, in query order
    /// (exact, k = 1). kInvalidArgument when a query is not finite.
    Result<std::vector<double>> distances(const std::vector<Eigen::Vector3f>& queries,
                                          int num_threads = 0) const;
    const std::vector<Eigen::Vector3f>& points() const { return *points_; }

  private:
    explicit ClosestPoints(const std::vector<Eigen::Vector3f>& reference);
    const std::vector<Eigen::Vector3f>* points_;
    std::unique_ptr<const PointKdTree<float>> tree_;
};

/// Distance from every query point to its closest reference point, metres, in query order.
/// kInvalidArgument when the reference is empty or a point is not finite.
Result<std::vector<double>> closestPointDistances(const std::vector<Eigen::Vector3f>& queries,
                                                  const std::vector<Eigen::Vector3f>& reference,
                                                  int num_threads = 0);

/// Statistics of a list of distances (empty list: all zero).
DistanceStats summarize(const std::vector<double>& distances_m);

/// Deterministic dense samples of a triangle mesh's surface, for ground truth given as a mesh
/// (reference §6.1 asks for <= 5 mm spacing). Each triangle gets the barycentric grid
/// a + (i/n)(b - a) + (j/n)(c - a), i + j <= n, with n = ceil(longest edge / spacing_m) (so
/// neighbouring samples are at most spacing_m apart; shared edges are sampled by both
/// triangles). kInvalidArgument for a non-positive spacing, an index out of range, or when more
/// than `max_points` samples would be needed.
Result<std::vector<Eigen::Vector3f>> sampleMeshSurface(
    const std::vector<Eigen::Vector3f>& vertices, const std::vector<Eigen::Vector3i>& triangles,
    double spacing_m, size_t max_points = 50'000'000);

/// Evaluates reconstructed points (or mesh vertices) against ground-truth points.
/// kInvalidArgument when either set is empty, a point is not finite, or the threshold is not
/// positive.
Result<ReconMetrics> evaluateReconstruction(const std::vector<Eigen::Vector3f>& reconstructed,
                                            const std::vector<Eigen::Vector3f>& ground_truth,
                                            const ReconMetricsConfig& config = {});

/// As above against a ground truth whose tree is already built. With `to_ground_truth_m`, it
/// also receives each reconstructed point's distance to the ground truth (the accuracy's
/// distances, in point order).
Result<ReconMetrics> evaluateReconstruction(const std::vector<Eigen::Vector3f>& reconstructed,
                                            const ClosestPoints& ground_truth,
                                            const ReconMetricsConfig& config = {},
                                            std::vector<double>* to_ground_truth_m = nullptr);

}  // namespace plumb::eval
