// SPDX-License-Identifier: Apache-2.0
#include "common/eval/surface_distance.hpp"

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <nanoflann.hpp>

namespace plumb::eval {
namespace {

struct CloudAdaptor {
    const std::vector<Eigen::Vector3f>& points;

    size_t kdtree_get_point_count() const { return points.size(); }  // NOLINT
    float kdtree_get_pt(size_t i, size_t dim) const {                // NOLINT
        return points[i][static_cast<Eigen::Index>(dim)];
    }
    template <class BoundingBox>
    bool kdtree_get_bbox(BoundingBox& /*bb*/) const {  // NOLINT
        return false;
    }
};

using KdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, CloudAdaptor>,
                                        CloudAdaptor, 3, uint32_t>;

}  // namespace

Result<std::vector<double>> pointToSurfaceDistances(const std::vector<Eigen::Vector3f>& queries,
                                                    const PointCloud& reference,
                                                    double max_point_distance_m, int num_threads) {
    if (reference.points.empty()) return invalidArgument("surface distance: empty reference");
    for (size_t i = 0; i < queries.size(); ++i) {
        if (!queries[i].allFinite()) {
            return invalidArgument(fmt::format("surface distance: query {} is not finite", i));
        }
    }
    for (size_t i = 0; i < reference.points.size(); ++i) {
        if (!reference.points[i].allFinite()) {
            return invalidArgument(fmt::format("surface distance: reference {} is not finite", i));
        }
    }
    const bool normals = reference.hasNormals();
    const CloudAdaptor adaptor{reference.points};
    const KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
    std::vector<double> out(queries.size(), 0.0);
    auto body = [&] {
        tbb::parallel_for(
            tbb::blocked_range<size_t>(0, queries.size(), 1024),
            [&](const tbb::blocked_range<size_t>& r) {
                for (size_t i = r.begin(); i != r.end(); ++i) {
                    uint32_t index = 0;
                    float dist_sq = 0.0f;
                    tree.knnSearch(queries[i].data(), 1, &index, &dist_sq);
                    const double point_dist = std::sqrt(double{dist_sq});
                    if (!normals ||
                        (max_point_distance_m > 0.0 && point_dist > max_point_distance_m)) {
                        out[i] = point_dist;
                        continue;
                    }
                    const Eigen::Vector3f d = queries[i] - reference.points[index];
                    out[i] = std::abs(static_cast<double>(reference.normals[index].dot(d)));
                }
            });
    };
    if (num_threads > 0) {
        tbb::task_arena arena(num_threads);
        arena.execute(body);
    } else {
        body();
    }
    return out;
}

double median(std::vector<double> values) {
    if (values.empty()) return 0.0;
    const size_t n = values.size();
    std::nth_element(values.begin(), values.begin() + n / 2, values.end());
    const double hi = values[n / 2];
    if (n % 2 == 1) return hi;
    const double lo = *std::max_element(values.begin(), values.begin() + n / 2);
    return 0.5 * (lo + hi);
}

}  // namespace plumb::eval
