// SPDX-License-Identifier: Apache-2.0
#include "common/eval/surface_distance.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "common/cloud/kd_tree.hpp"
#include "common/core/parallel.hpp"

namespace plumb::eval {

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
    const PointKdTree<float> tree(reference.points);
    std::vector<double> out(queries.size(), 0.0);
    parallelFor(num_threads, queries.size(), [&](size_t i) {
        uint32_t index = 0;
        float dist_sq = 0.0f;
        tree.index().knnSearch(queries[i].data(), 1, &index, &dist_sq);
        const double point_dist = std::sqrt(double{dist_sq});
        if (!normals || (max_point_distance_m > 0.0 && point_dist > max_point_distance_m)) {
            out[i] = point_dist;
            return;
        }
        const Eigen::Vector3f d = queries[i] - reference.points[index];
        out[i] = std::abs(static_cast<double>(reference.normals[index].dot(d)));
    });
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
