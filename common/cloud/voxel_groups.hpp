// SPDX-License-Identifier: Apache-2.0
#pragma once

// Points grouped by the voxel they fall in: the step every voxel downsampling shares. A point p
// lies in the voxel of integer key (floor(p.x / s), floor(p.y / s), floor(p.z / s)), computed in
// double precision as p * (1 / s). Voxels come in the lexicographic order of their keys (x,
// then y, then z) and the points of a voxel in increasing index, so that sums over a voxel's
// points are taken in one fixed order: the grouping is what a comparison sort of (key, index)
// pairs gives, found here by a radix sort of the keys packed into one word (a comparison sort
// when the keys span more than 64 bits together).
//
// Thread-safety: a pure function of its input.

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace plumb {

struct VoxelGroups {
    /// Indices of the points, voxel by voxel; non-finite points are left out.
    std::vector<uint32_t> order;
    /// Voxel k holds order[start[k] .. start[k + 1]); start.size() = voxels + 1.
    std::vector<uint32_t> start;

    size_t voxels() const { return start.empty() ? 0 : start.size() - 1; }
};

/// Groups `points` by voxels of edge `voxel_m` (> 0; see the file comment for the order).
/// At most 2^32 - 1 points.
VoxelGroups groupByVoxel(const std::vector<Eigen::Vector3f>& points, double voxel_m);

}  // namespace plumb
