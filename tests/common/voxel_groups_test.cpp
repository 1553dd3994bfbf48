// SPDX-License-Identifier: Apache-2.0
#include "common/cloud/voxel_groups.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <utility>
#include <vector>

namespace plumb {
namespace {

/// The grouping by definition: (key, index) pairs in a comparison sort.
VoxelGroups byComparisonSort(const std::vector<Eigen::Vector3f>& points, double voxel_m) {
    using Key = std::array<int64_t, 3>;
    std::vector<std::pair<Key, uint32_t>> keyed;
    for (size_t i = 0; i < points.size(); ++i) {
        const Eigen::Vector3f& p = points[i];
        if (!p.allFinite()) continue;
        keyed.push_back({Key{static_cast<int64_t>(std::floor(p.x() / voxel_m)),
                             static_cast<int64_t>(std::floor(p.y() / voxel_m)),
                             static_cast<int64_t>(std::floor(p.z() / voxel_m))},
                         static_cast<uint32_t>(i)});
    }
    std::sort(keyed.begin(), keyed.end());
    VoxelGroups out;
    for (size_t i = 0; i < keyed.size(); ++i) {
        out.order.push_back(keyed[i].second);
        if (i == 0 || keyed[i].first != keyed[i - 1].first)
            out.start.push_back(static_cast<uint32_t>(i));
    }
    out.start.push_back(static_cast<uint32_t>(keyed.size()));
    return out;
}

/// Points on voxel-friendly coordinates (multiples of 1/8 of the voxel, so that p / s and
/// p * (1 / s) floor alike), many to a voxel, in random order.
std::vector<Eigen::Vector3f> gridPoints(size_t n, float half_extent, double voxel_m,
                                        uint32_t seed) {
    std::mt19937 rng(seed);
    const int steps = static_cast<int>(half_extent / voxel_m * 8.0);
    std::uniform_int_distribution<int> u(-steps, steps);
    std::vector<Eigen::Vector3f> points;
    for (size_t i = 0; i < n; ++i) {
        points.emplace_back(static_cast<float>(u(rng) * voxel_m / 8.0),
                            static_cast<float>(u(rng) * voxel_m / 8.0),
                            static_cast<float>(u(rng) * voxel_m / 8.0));
    }
    return points;
}

void expectSame(const VoxelGroups& a, const VoxelGroups& b) {
    EXPECT_EQ(a.order, b.order);
    EXPECT_EQ(a.start, b.start);
}

TEST(VoxelGroups, GroupsAsAComparisonSortOfKeyThenIndex) {
    // A room-sized cloud (the radix path) with about 8 points to a voxel: every voxel's points
    // are in increasing index and the voxels in key order.
    const double voxel = 0.125;
    const std::vector<Eigen::Vector3f> points = gridPoints(20000, 3.0f, voxel, 1);
    const VoxelGroups groups = groupByVoxel(points, voxel);
    expectSame(groups, byComparisonSort(points, voxel));
    EXPECT_GT(groups.voxels(), 1000U);
    EXPECT_LT(groups.voxels(), points.size());
}

TEST(VoxelGroups, KeysSpanningMoreThanOneWordGroupTheSameWay) {
    // Coordinates 2^25 voxels apart on every axis: 78 bits of key, the comparison-sort path.
    const double voxel = 1.0 / 64.0;
    std::vector<Eigen::Vector3f> points = gridPoints(3000, 2.0f, voxel, 2);
    for (size_t i = 0; i < points.size(); i += 3) points[i] += Eigen::Vector3f::Constant(524288.0f);
    const VoxelGroups groups = groupByVoxel(points, voxel);
    expectSame(groups, byComparisonSort(points, voxel));
}

TEST(VoxelGroups, NonFinitePointsAreLeftOutAndEdgeCasesHold) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float inf = std::numeric_limits<float>::infinity();
    std::vector<Eigen::Vector3f> points = {{0.05f, 0.05f, 0.05f},
                                           {nan, 0.0f, 0.0f},
                                           {0.07f, 0.02f, 0.01f},
                                           {0.0f, inf, 0.0f},
                                           {-0.05f, 0.05f, 0.05f}};
    const VoxelGroups groups = groupByVoxel(points, 0.1);
    EXPECT_EQ(groups.order, (std::vector<uint32_t>{4, 0, 2}));  // x = -1 first, then (0, 0, 0)
    EXPECT_EQ(groups.start, (std::vector<uint32_t>{0, 1, 3}));

    const VoxelGroups one = groupByVoxel({{0.3f, 0.3f, 0.3f}, {0.31f, 0.32f, 0.33f}}, 1.0);
    EXPECT_EQ(one.voxels(), 1U);
    EXPECT_EQ(one.order, (std::vector<uint32_t>{0, 1}));

    const VoxelGroups none = groupByVoxel({{nan, nan, nan}}, 1.0);
    EXPECT_EQ(none.voxels(), 0U);
    EXPECT_TRUE(none.order.empty());
    EXPECT_EQ(groupByVoxel({}, 1.0).voxels(), 0U);
}

}  // namespace
}  // namespace plumb
