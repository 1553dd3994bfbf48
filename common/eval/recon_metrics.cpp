// SPDX-License-Identifier: Apache-2.0
#include "common/eval/recon_metrics.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "common/cloud/kd_tree.hpp"
#include "common/core/parallel.hpp"

namespace plumb::eval {
namespace {

Status checkFinite(const std::vector<Eigen::Vector3f>& points, const char* what) {
    for (size_t i = 0; i < points.size(); ++i) {
        if (!points[i].allFinite()) {
            return invalidArgument(fmt::format("{} point {} is not finite", what, i));
        }
    }
    return Status::ok();
}

/// Linear interpolation between order statistics, q in [0, 1], of a list whose entries at the
/// two ranks around q (n - 1) hold those order statistics (a sorted list, or one partitioned
/// there).
double percentileOfOrdered(const std::vector<double>& sorted, double q) {
    if (sorted.empty()) return 0.0;
    const double pos = q * static_cast<double>(sorted.size() - 1);
    const auto lo = static_cast<size_t>(std::floor(pos));
    const size_t hi = std::min(lo + 1, sorted.size() - 1);
    const double frac = pos - static_cast<double>(lo);
    return sorted[lo] + frac * (sorted[hi] - sorted[lo]);
}

double fractionWithin(const std::vector<double>& distances, double threshold) {
    if (distances.empty()) return 0.0;
    const auto n = std::count_if(distances.begin(), distances.end(),
                                 [threshold](double d) { return d <= threshold; });
    return static_cast<double>(n) / static_cast<double>(distances.size());
}

}  // namespace

ClosestPoints::ClosestPoints(const std::vector<Eigen::Vector3f>& reference)
    : points_(&reference), tree_(std::make_unique<const PointKdTree<float>>(reference)) {}

ClosestPoints::~ClosestPoints() = default;

Result<std::shared_ptr<const ClosestPoints>> ClosestPoints::build(
    const std::vector<Eigen::Vector3f>& reference) {
    if (reference.empty()) return invalidArgument("the reference point set is empty");
    PLUMB_RETURN_IF_ERROR(checkFinite(reference, "reference"));
    return std::shared_ptr<const ClosestPoints>(new ClosestPoints(reference));
}

Result<std::vector<double>> ClosestPoints::distances(const std::vector<Eigen::Vector3f>& queries,
                                                     int num_threads) const {
    PLUMB_RETURN_IF_ERROR(checkFinite(queries, "query"));
    std::vector<double> distances(queries.size(), 0.0);
    parallelFor(num_threads, queries.size(), [&](size_t i) {
        uint32_t index = 0;
        float dist_sq = 0.0f;
        tree_->index().knnSearch(queries[i].data(), 1, &index, &dist_sq);
        distances[i] = std::sqrt(static_cast<double>(dist_sq));
    });
    return distances;
}

Result<std::vector<double>> closestPointDistances(const std::vector<Eigen::Vector3f>& queries,
                                                  const std::vector<Eigen::Vector3f>& reference,
                                                  int num_threads) {
    if (reference.empty()) return invalidArgument("the reference point set is empty");
    PLUMB_RETURN_IF_ERROR(checkFinite(queries, "query"));
    Result<std::shared_ptr<const ClosestPoints>> index = ClosestPoints::build(reference);
    if (!index.isOk()) return index.status();
    return (*index)->distances(queries, num_threads);
}

DistanceStats summarize(const std::vector<double>& distances_m) {
    DistanceStats s;
    s.count = distances_m.size();
    if (distances_m.empty()) return s;
    double sum = 0.0, sum_sq = 0.0;
    for (double d : distances_m) {  // serial, in order: bit-identical for any thread count
        sum += d;
        sum_sq += d * d;
    }
    const auto n = static_cast<double>(distances_m.size());
    s.mean_m = sum / n;
    s.rms_m = std::sqrt(sum_sq / n);
    // Only the order statistics the percentiles interpolate between are put in place (each
    // nth_element in the part after the previous one): the values a full sort leaves there.
    std::vector<double> ordered = distances_m;
    const double last = static_cast<double>(ordered.size() - 1);
    std::vector<size_t> ranks;
    for (const double q : {0.5, 0.9}) {
        const auto lo = static_cast<size_t>(std::floor(q * last));
        ranks.push_back(lo);
        ranks.push_back(std::min(lo + 1, ordered.size() - 1));
    }
    ranks.push_back(ordered.size() - 1);
    std::sort(ranks.begin(), ranks.end());
    auto from = ordered.begin();
    for (const size_t r : ranks) {
        const auto nth = ordered.begin() + static_cast<std::ptrdiff_t>(r);
        if (nth < from) continue;  // already in place (a repeated rank)
        std::nth_element(from, nth, ordered.end());
        from = nth + 1;
    }
    s.median_m = percentileOfOrdered(ordered, 0.5);
    s.p90_m = percentileOfOrdered(ordered, 0.9);
    s.max_m = ordered.back();
    return s;
}

Result<std::vector<Eigen::Vector3f>> sampleMeshSurface(
    const std::vector<Eigen::Vector3f>& vertices, const std::vector<Eigen::Vector3i>& triangles,
    double spacing_m, size_t max_points) {
    if (!(spacing_m > 0.0) || !std::isfinite(spacing_m)) {
        return invalidArgument(fmt::format("sample spacing must be positive, got {} m", spacing_m));
    }
    const auto num_vertices = static_cast<int>(vertices.size());
    // First pass: validate and count, so the budget is checked before allocating.
    std::vector<int> steps(triangles.size(), 0);
    size_t total = 0;
    for (size_t t = 0; t < triangles.size(); ++t) {
        const Eigen::Vector3i& tri = triangles[t];
        if ((tri.array() < 0).any() || (tri.array() >= num_vertices).any()) {
            return invalidArgument(
                fmt::format("triangle {} refers to a vertex outside 0..{}", t, num_vertices - 1));
        }
        const Eigen::Vector3d a = vertices[tri[0]].cast<double>();
        const Eigen::Vector3d b = vertices[tri[1]].cast<double>();
        const Eigen::Vector3d c = vertices[tri[2]].cast<double>();
        if (!a.allFinite() || !b.allFinite() || !c.allFinite()) {
            return invalidArgument(fmt::format("triangle {} has a non-finite vertex", t));
        }
        const double longest = std::max({(b - a).norm(), (c - a).norm(), (c - b).norm()});
        const double n = std::max(1.0, std::ceil(longest / spacing_m));
        const double count = (n + 1.0) * (n + 2.0) / 2.0;
        if (n > 1e6 || static_cast<double>(total) + count > static_cast<double>(max_points)) {
            return invalidArgument(fmt::format(
                "sampling the mesh at {} m needs more than {} points; use a larger spacing",
                spacing_m, max_points));
        }
        steps[t] = static_cast<int>(n);
        total += static_cast<size_t>(count);
    }
    std::vector<Eigen::Vector3f> samples;
    samples.reserve(total);
    for (size_t t = 0; t < triangles.size(); ++t) {
        const Eigen::Vector3i& tri = triangles[t];
        const Eigen::Vector3d a = vertices[tri[0]].cast<double>();
        const Eigen::Vector3d ab = vertices[tri[1]].cast<double>() - a;
        const Eigen::Vector3d ac = vertices[tri[2]].cast<double>() - a;
        const int n = steps[t];
        for (int i = 0; i <= n; ++i) {
            for (int j = 0; i + j <= n; ++j) {
                samples.push_back(
                    (a + (static_cast<double>(i) / n) * ab + (static_cast<double>(j) / n) * ac)
                        .cast<float>());
            }
        }
    }
    return samples;
}

Result<ReconMetrics> evaluateReconstruction(const std::vector<Eigen::Vector3f>& reconstructed,
                                            const std::vector<Eigen::Vector3f>& ground_truth,
                                            const ReconMetricsConfig& config) {
    if (reconstructed.empty()) return invalidArgument("the reconstruction has no points");
    if (ground_truth.empty()) return invalidArgument("the ground truth has no points");
    Result<std::shared_ptr<const ClosestPoints>> index = ClosestPoints::build(ground_truth);
    if (!index.isOk()) return index.status();
    return evaluateReconstruction(reconstructed, **index, config);
}

Result<ReconMetrics> evaluateReconstruction(const std::vector<Eigen::Vector3f>& reconstructed,
                                            const ClosestPoints& ground_truth,
                                            const ReconMetricsConfig& config,
                                            std::vector<double>* to_ground_truth_m) {
    if (reconstructed.empty()) return invalidArgument("the reconstruction has no points");
    if (!(config.completeness_threshold_m > 0.0) ||
        !std::isfinite(config.completeness_threshold_m)) {
        return invalidArgument(fmt::format("threshold must be a positive distance, got {} m",
                                           config.completeness_threshold_m));
    }
    auto to_gt = ground_truth.distances(reconstructed, config.num_threads);
    if (!to_gt.isOk()) return to_gt.status();
    auto to_recon = closestPointDistances(ground_truth.points(), reconstructed, config.num_threads);
    if (!to_recon.isOk()) return to_recon.status();
    ReconMetrics m;
    m.num_reconstructed = reconstructed.size();
    m.num_ground_truth = ground_truth.points().size();
    m.threshold_m = config.completeness_threshold_m;
    m.accuracy = summarize(*to_gt);
    m.completeness_distances = summarize(*to_recon);
    m.accuracy_fraction = fractionWithin(*to_gt, config.completeness_threshold_m);
    m.completeness = fractionWithin(*to_recon, config.completeness_threshold_m);
    if (to_ground_truth_m != nullptr) *to_ground_truth_m = std::move(*to_gt);
    return m;
}

}  // namespace plumb::eval
