// SPDX-License-Identifier: Apache-2.0
#include "common/cloud/voxel_groups.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <utility>

#include "common/core/status.hpp"

namespace plumb {
namespace {

using Key = std::array<int64_t, 3>;

/// floor(x) as an integer, clamped to +-2^62 (coordinates that far out share the outermost key).
int64_t floorKey(double x) {
    constexpr double kLimit = 4611686018427387904.0;  // 2^62
    return static_cast<int64_t>(std::floor(std::clamp(x, -kLimit, kLimit)));
}

/// A point's packed key and its index.
struct Packed {
    uint64_t word;
    uint32_t index;
};

/// Stable LSD radix sort of `items` by the low `bits` bits of their words, 11 bits a pass; a
/// pass whose digit is the same for every item is skipped.
void radixSort(std::vector<Packed>& items, int bits) {
    constexpr int kDigitBits = 11;
    constexpr size_t kBuckets = size_t{1} << kDigitBits;
    std::vector<Packed> buffer(items.size());
    std::vector<uint32_t> count(kBuckets);
    for (int shift = 0; shift < bits; shift += kDigitBits) {
        std::fill(count.begin(), count.end(), 0U);
        for (const Packed& p : items) ++count[(p.word >> shift) & (kBuckets - 1)];
        if (std::find(count.begin(), count.end(), items.size()) != count.end()) continue;
        uint32_t sum = 0;
        for (uint32_t& c : count) {
            const uint32_t n = c;
            c = sum;
            sum += n;
        }
        for (const Packed& p : items) buffer[count[(p.word >> shift) & (kBuckets - 1)]++] = p;
        items.swap(buffer);
    }
}

}  // namespace

VoxelGroups groupByVoxel(const std::vector<Eigen::Vector3f>& points, double voxel_m) {
    PLUMB_CHECK(voxel_m > 0.0) << "voxel edge " << voxel_m;
    PLUMB_CHECK(points.size() < std::numeric_limits<uint32_t>::max()) << points.size();
    const double inv = 1.0 / voxel_m;
    const auto keyOf = [inv](const Eigen::Vector3f& p) {
        return Key{floorKey(p.x() * inv), floorKey(p.y() * inv), floorKey(p.z() * inv)};
    };
    Key lo{std::numeric_limits<int64_t>::max(), std::numeric_limits<int64_t>::max(),
           std::numeric_limits<int64_t>::max()};
    Key hi{std::numeric_limits<int64_t>::min(), std::numeric_limits<int64_t>::min(),
           std::numeric_limits<int64_t>::min()};
    size_t finite = 0;
    for (const Eigen::Vector3f& p : points) {
        if (!p.allFinite()) continue;
        const Key k = keyOf(p);
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], k[a]);
            hi[a] = std::max(hi[a], k[a]);
        }
        ++finite;
    }
    VoxelGroups out;
    out.order.resize(finite);
    if (finite == 0) {
        out.start.push_back(0);
        return out;
    }
    std::array<int, 3> width{};
    for (int a = 0; a < 3; ++a)
        width[a] = std::bit_width(static_cast<uint64_t>(hi[a]) - static_cast<uint64_t>(lo[a]));
    const int bits = width[0] + width[1] + width[2];
    // Voxel boundaries: where the key changes along the sorted order.
    std::vector<bool> first(finite, false);
    if (bits <= 64) {
        // Offsets from the smallest key, x in the high bits: the word orders as the key triple.
        std::vector<Packed> packed;
        packed.reserve(finite);
        for (size_t i = 0; i < points.size(); ++i) {
            if (!points[i].allFinite()) continue;
            const Key k = keyOf(points[i]);
            uint64_t word = 0;
            for (int a = 0; a < 3; ++a) {
                if (width[a] == 0) continue;
                word = (word << width[a]) |
                       (static_cast<uint64_t>(k[a]) - static_cast<uint64_t>(lo[a]));
            }
            packed.push_back({word, static_cast<uint32_t>(i)});  // ties stay in index order
        }
        radixSort(packed, bits);
        for (size_t i = 0; i < packed.size(); ++i) {
            out.order[i] = packed[i].index;
            first[i] = i == 0 || packed[i].word != packed[i - 1].word;
        }
    } else {
        std::vector<std::pair<Key, uint32_t>> keyed;
        keyed.reserve(finite);
        for (size_t i = 0; i < points.size(); ++i)
            if (points[i].allFinite())
                keyed.emplace_back(keyOf(points[i]), static_cast<uint32_t>(i));
        std::sort(keyed.begin(), keyed.end());
        for (size_t i = 0; i < keyed.size(); ++i) {
            out.order[i] = keyed[i].second;
            first[i] = i == 0 || keyed[i].first != keyed[i - 1].first;
        }
    }
    for (size_t i = 0; i < first.size(); ++i)
        if (first[i]) out.start.push_back(static_cast<uint32_t>(i));
    out.start.push_back(static_cast<uint32_t>(first.size()));
    return out;
}

}  // namespace plumb
