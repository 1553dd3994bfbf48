// SPDX-License-Identifier: Apache-2.0
#include "backend/registration/cloud_ops.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>

#include "common/cloud/voxel_groups.hpp"

namespace plumb::registration::detail {

KdTree3::KdTree3(const std::vector<Eigen::Vector3f>& points) : tree_(points) {}

bool KdTree3::nearest(const Eigen::Vector3f& q, float max_dist_sq, uint32_t* index,
                      float* dist_sq) const {
    return nearest(q, max_dist_sq, std::numeric_limits<uint32_t>::max(), index, dist_sq);
}

bool KdTree3::nearest(const Eigen::Vector3f& q, float max_dist_sq, uint32_t hint, uint32_t* index,
                      float* dist_sq) const {
    if (size() == 0) return false;
    const float bound = tree_.searchBound(q, hint, max_dist_sq);
    uint32_t idx = 0;
    float d = 0.0f;
    nanoflann::KNNResultSet<float, uint32_t, size_t> result(1);
    result.init(&idx, &d);
    // Starting the search at the radius prunes every branch beyond it: most queries of a
    // partial overlap have no neighbour within it, and an unbounded search would walk the tree
    // far for a point it then discards (same neighbour when there is one).
    d = std::nextafter(bound, std::numeric_limits<float>::infinity());
    tree_.index().findNeighbors(result, q.data(), nanoflann::SearchParams());
    if (result.size() == 0 || d > max_dist_sq) return false;
    *index = idx;
    *dist_sq = d;
    return true;
}

size_t KdTree3::knnWithin(const Eigen::Vector3f& q, size_t k, float radius_sq, uint32_t* indices,
                          float* dists_sq) const {
    if (size() == 0 || k == 0) return 0;
    nanoflann::KNNResultSet<float, uint32_t, size_t> result(k);
    result.init(indices, dists_sq);
    // The search prunes at the worst distance so far: starting it at the radius keeps it from
    // visiting points beyond (same neighbours, same order).
    dists_sq[k - 1] = std::nextafter(radius_sq, std::numeric_limits<float>::infinity());
    tree_.index().findNeighbors(result, q.data(), nanoflann::SearchParams());
    size_t n = result.size();
    while (n > 0 && dists_sq[n - 1] > radius_sq) --n;
    return n;
}

PointCloud voxelDownsample(const PointCloud& cloud, double voxel_m) {
    PointCloud out;
    const bool with_normals = cloud.hasNormals();
    const bool with_colors = cloud.hasColors();
    const VoxelGroups groups = groupByVoxel(cloud.points, voxel_m);
    out.reserve(groups.voxels(), with_normals, with_colors);
    for (size_t v = 0; v < groups.voxels(); ++v) {
        Eigen::Vector3d sum_p = Eigen::Vector3d::Zero();
        Eigen::Vector3d sum_n = Eigen::Vector3d::Zero();
        Eigen::Vector3d sum_c = Eigen::Vector3d::Zero();
        for (uint32_t j = groups.start[v]; j < groups.start[v + 1]; ++j) {
            const uint32_t k = groups.order[j];
            sum_p += cloud.points[k].cast<double>();
            if (with_normals) sum_n += cloud.normals[k].cast<double>();
            if (with_colors) sum_c += cloud.colors[k].cast<double>();
        }
        const double count = static_cast<double>(groups.start[v + 1] - groups.start[v]);
        if (with_normals) {
            const double norm = sum_n.norm();
            if (!(norm > 1e-9)) continue;  // opposite normals cancel: skip the ambiguous voxel
            out.normals.push_back((sum_n / norm).cast<float>());
        }
        out.points.push_back((sum_p / count).cast<float>());
        if (with_colors) out.colors.push_back((sum_c / count).array().round().cast<uint8_t>());
    }
    return out;
}

}  // namespace plumb::registration::detail
