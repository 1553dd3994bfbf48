// SPDX-License-Identifier: Apache-2.0
#include "backend/registration/cloud_ops.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>

namespace plumb::registration::detail {

KdTree3::KdTree3(const std::vector<Eigen::Vector3f>& points) : tree_(points) {}

bool KdTree3::nearest(const Eigen::Vector3f& q, float max_dist_sq, uint32_t* index,
                      float* dist_sq) const {
    if (size() == 0) return false;
    uint32_t idx = 0;
    float d = 0.0f;
    nanoflann::KNNResultSet<float, uint32_t, size_t> result(1);
    result.init(&idx, &d);
    // Starting the search at the radius prunes every branch beyond it: most queries of a
    // partial overlap have no neighbour within it, and an unbounded search would walk the tree
    // far for a point it then discards (same neighbour when there is one).
    d = std::nextafter(max_dist_sq, std::numeric_limits<float>::infinity());
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

namespace {

/// A voxel key and the point in it, sorted by key then index.
struct Keyed {
    std::array<int64_t, 3> key;
    uint32_t index;
};

/// Sorts `keyed` by (key, index). When every coordinate fits in 21 bits, by one 64-bit word that
/// orders as the triple does (each coordinate offset to be non-negative): the same order.
void sortKeyed(std::vector<Keyed>& keyed) {
    constexpr int64_t kHalf = int64_t{1} << 20;
    const bool packable = std::all_of(keyed.begin(), keyed.end(), [](const Keyed& k) {
        return std::all_of(k.key.begin(), k.key.end(),
                           [](int64_t c) { return c >= -kHalf && c < kHalf; });
    });
    if (!packable) {
        std::sort(keyed.begin(), keyed.end(), [](const Keyed& a, const Keyed& b) {
            return a.key != b.key ? a.key < b.key : a.index < b.index;
        });
        return;
    }
    struct Packed {
        uint64_t word;
        uint32_t slot;
    };
    std::vector<Packed> packed(keyed.size());
    for (size_t i = 0; i < keyed.size(); ++i) {
        const auto& k = keyed[i].key;
        packed[i] = {static_cast<uint64_t>(k[0] + kHalf) << 42 |
                         static_cast<uint64_t>(k[1] + kHalf) << 21 |
                         static_cast<uint64_t>(k[2] + kHalf),
                     static_cast<uint32_t>(i)};
    }
    // Slots follow the points' order, so ties on the word sort by index as before.
    std::sort(packed.begin(), packed.end(), [](const Packed& a, const Packed& b) {
        return a.word != b.word ? a.word < b.word : a.slot < b.slot;
    });
    std::vector<Keyed> sorted(keyed.size());
    for (size_t i = 0; i < packed.size(); ++i) sorted[i] = keyed[packed[i].slot];
    keyed = std::move(sorted);
}

}  // namespace

PointCloud voxelDownsample(const PointCloud& cloud, double voxel_m) {
    PointCloud out;
    const bool with_normals = cloud.hasNormals();
    const bool with_colors = cloud.hasColors();
    const double inv = 1.0 / voxel_m;
    std::vector<Keyed> keyed;
    keyed.reserve(cloud.size());
    for (size_t i = 0; i < cloud.size(); ++i) {
        const Eigen::Vector3f& p = cloud.points[i];
        if (!p.allFinite()) continue;
        keyed.push_back({{static_cast<int64_t>(std::floor(p.x() * inv)),
                          static_cast<int64_t>(std::floor(p.y() * inv)),
                          static_cast<int64_t>(std::floor(p.z() * inv))},
                         static_cast<uint32_t>(i)});
    }
    sortKeyed(keyed);
    out.reserve(keyed.size() / 4 + 1, with_normals, with_colors);
    size_t i = 0;
    while (i < keyed.size()) {
        size_t j = i;
        Eigen::Vector3d sum_p = Eigen::Vector3d::Zero();
        Eigen::Vector3d sum_n = Eigen::Vector3d::Zero();
        Eigen::Vector3d sum_c = Eigen::Vector3d::Zero();
        while (j < keyed.size() && keyed[j].key == keyed[i].key) {
            const uint32_t k = keyed[j].index;
            sum_p += cloud.points[k].cast<double>();
            if (with_normals) sum_n += cloud.normals[k].cast<double>();
            if (with_colors) sum_c += cloud.colors[k].cast<double>();
            ++j;
        }
        const double count = static_cast<double>(j - i);
        if (with_normals) {
            const double norm = sum_n.norm();
            if (!(norm > 1e-9)) {  // opposite normals cancel: skip the ambiguous voxel
                i = j;
                continue;
            }
            out.normals.push_back((sum_n / norm).cast<float>());
        }
        out.points.push_back((sum_p / count).cast<float>());
        if (with_colors) out.colors.push_back((sum_c / count).array().round().cast<uint8_t>());
        i = j;
    }
    return out;
}

}  // namespace plumb::registration::detail
