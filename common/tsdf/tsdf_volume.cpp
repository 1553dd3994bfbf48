// SPDX-License-Identifier: Apache-2.0
#include "common/tsdf/tsdf_volume.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <climits>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "common/core/parallel.hpp"
#include "common/core/simd.hpp"
#include "common/geometry/lie.hpp"

namespace plumb::tsdf {
namespace {

/// Four float or int lanes (GCC vector extensions: SSE2 on x86-64, NEON on aarch64).
using Float4 = float __attribute__((vector_size(16)));
using Int4 = int32_t __attribute__((vector_size(16)));
using UInt4 = uint32_t __attribute__((vector_size(16)));
#if defined(__x86_64__) && defined(__GNUC__)
#define PLUMB_TSDF_AVX2 1
/// Eight lanes, for the AVX2 variant only (used inside target("avx2") functions).
using Float8 = float __attribute__((vector_size(32)));
using Int8 = int32_t __attribute__((vector_size(32)));
#endif

/// What one integration pass needs per voxel row, in the camera frame.
struct RowIntegrator {
    const float* depth;
    int width, height;
    float fx, fy, cx, cy;
    float mu, inv_mu, min_d, max_d, max_w;
    const Rgb8* colour = nullptr;  ///< registered to depth; null: depth only
    float colour_band_m = 0.0f;    ///< colour where |sdf| <= this

    /// Fuses kRows consecutive rows of 8 voxels, row[0 .. 8 kRows - 1], where voxel k of row j
    /// has its centre at p[j] + k dx, §2.3: the projective distance sdf = D(u) - z, truncated to
    /// min(1, sdf / mu), skipped below -mu, running average with unit weight saturating at
    /// max_w. The rows' groups of 4 lanes go through each step together, so their long
    /// dependency chains (a division, the depth lookup, another division) overlap. One branch:
    /// rows with no lane to update are neither averaged nor written back.
    /// With `colours` (the rows' voxel colours) lanes that pass and lie within the colour band
    /// also average the pixel's colour (§7b.2); the TSDF values are the same either way.
    template <int kRows>
    void fuseRows(Voxel* row, const Eigen::Vector3f* p, const Eigen::Vector3f& dx,
                  VoxelColour* colours = nullptr) const {
        constexpr int kGroups = 2 * kRows;  // group g: voxels 4 (g & 1) .. + 3 of row g / 2
        const Float4 lanes[2] = {{0.0f, 1.0f, 2.0f, 3.0f}, {4.0f, 5.0f, 6.0f, 7.0f}};
        const Float4 zero = {0.0f, 0.0f, 0.0f, 0.0f};
        Float4 pz[kGroups], d[kGroups];
        Int4 in[kGroups], pixels[kGroups];
        for (int g = 0; g < kGroups; ++g) {
            const Eigen::Vector3f& o = p[g / 2];
            const Float4 px = o.x() + lanes[g & 1] * dx.x();
            const Float4 py = o.y() + lanes[g & 1] * dx.y();
            pz[g] = o.z() + lanes[g & 1] * dx.z();
            const Float4 inv_z = 1.0f / pz[g];
            const Float4 uf = fx * px * inv_z + cx + 0.5f;
            const Float4 vf = fy * py * inv_z + cy + 0.5f;
            // In front of the camera and inside the image (uf, vf >= 0: truncation is floor).
            in[g] = (pz[g] > 0.0f) & (uf >= 0.0f) & (vf >= 0.0f) &
                    (uf < static_cast<float>(width)) & (vf < static_cast<float>(height));
            // Pixel indices in lanes (exact in float below 2^24 pixels); lanes outside the
            // image read pixel 0 and are masked by `in`.
            const Float4 u =
                __builtin_convertvector(__builtin_convertvector(in[g] ? uf : zero, Int4), Float4);
            const Float4 v =
                __builtin_convertvector(__builtin_convertvector(in[g] ? vf : zero, Int4), Float4);
            const Int4 pixel = __builtin_convertvector(v * static_cast<float>(width) + u, Int4);
            pixels[g] = pixel;
            d[g] = Float4{depth[pixel[0]], depth[pixel[1]], depth[pixel[2]], depth[pixel[3]]};
            d[g] = in[g] ? d[g] : zero;
        }
        Int4 ok[kGroups];
        Int4 any = {0, 0, 0, 0};
        for (int g = 0; g < kGroups; ++g) {
            ok[g] = in[g] & (d[g] >= min_d) & (d[g] <= max_d) & (d[g] - pz[g] >= -mu);
            any |= ok[g];
        }
        // Rows wholly behind the surface, outside the image or without depth are left untouched
        // (not even written back: most voxels of a block the band crosses are such).
        if ((any[0] | any[1] | any[2] | any[3]) == 0) return;
        Float4 vox[2 * kGroups];  // {t0, w0, t1, w1}, {t2, w2, t3, w3}, ... in memory order
        std::memcpy(vox, row, sizeof(vox));
        for (int g = 0; g < kGroups; ++g) {
            const Float4 sdf = d[g] - pz[g];  // + in front of the surface
            const Float4 f_raw = sdf * inv_mu;
            const Float4 f = f_raw < 1.0f ? f_raw : 1.0f;
            const Float4 tsdf = __builtin_shuffle(vox[2 * g], vox[2 * g + 1], Int4{0, 2, 4, 6});
            const Float4 w = __builtin_shuffle(vox[2 * g], vox[2 * g + 1], Int4{1, 3, 5, 7});
            const Float4 w1 = w + 1.0f;
            const Float4 new_tsdf = ok[g] ? (w * tsdf + f) / w1 : tsdf;
            const Float4 new_w = ok[g] ? (max_w < w1 ? Float4{max_w, max_w, max_w, max_w} : w1) : w;
            vox[2 * g] = __builtin_shuffle(new_tsdf, new_w, Int4{0, 4, 1, 5});
            vox[2 * g + 1] = __builtin_shuffle(new_tsdf, new_w, Int4{2, 6, 3, 7});
            if (colours != nullptr) {
                const Float4 abs_sdf = sdf < 0.0f ? -sdf : sdf;
                const Int4 near = ok[g] & (abs_sdf <= colour_band_m);
                if ((near[0] | near[1] | near[2] | near[3]) != 0) {
                    blendColours(near, pixels[g], &colours[4 * g]);
                }
            }
        }
        std::memcpy(static_cast<void*>(row), vox, sizeof(vox));
    }

#ifdef PLUMB_TSDF_AVX2
    /// fuseRows<2> with a row of 8 voxels in one 8-lane vector, for CPUs with AVX2 (no FMA): the
    /// same operations lane by lane and in the same order, so the same voxels and colours bit for
    /// bit (common/core/simd.hpp); the colours go through the same four-lane blend.
    __attribute__((target("avx2"))) void fuseTwoRowsAvx2(Voxel* row, const Eigen::Vector3f* p,
                                                         const Eigen::Vector3f& dx,
                                                         VoxelColour* colours) const {
        constexpr int kRows = 2;
        const Float8 lanes = {0.0f, 1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f};
        const Float8 zero = {};
        Float8 pz[kRows], d[kRows];
        Int8 ok[kRows], pixels[kRows];
        Int8 any = {};
        for (int g = 0; g < kRows; ++g) {
            const Eigen::Vector3f& o = p[g];
            const Float8 px = o.x() + lanes * dx.x();
            const Float8 py = o.y() + lanes * dx.y();
            pz[g] = o.z() + lanes * dx.z();
            const Float8 inv_z = 1.0f / pz[g];
            const Float8 uf = fx * px * inv_z + cx + 0.5f;
            const Float8 vf = fy * py * inv_z + cy + 0.5f;
            const Int8 in = (pz[g] > 0.0f) & (uf >= 0.0f) & (vf >= 0.0f) &
                            (uf < static_cast<float>(width)) & (vf < static_cast<float>(height));
            const Float8 u =
                __builtin_convertvector(__builtin_convertvector(in ? uf : zero, Int8), Float8);
            const Float8 v =
                __builtin_convertvector(__builtin_convertvector(in ? vf : zero, Int8), Float8);
            const Int8 pixel = __builtin_convertvector(v * static_cast<float>(width) + u, Int8);
            pixels[g] = pixel;
            d[g] = Float8{depth[pixel[0]], depth[pixel[1]], depth[pixel[2]], depth[pixel[3]],
                          depth[pixel[4]], depth[pixel[5]], depth[pixel[6]], depth[pixel[7]]};
            d[g] = in ? d[g] : zero;
            ok[g] = in & (d[g] >= min_d) & (d[g] <= max_d) & (d[g] - pz[g] >= -mu);
            any |= ok[g];
        }
        bool touched = false;
        for (int k = 0; k < 8; ++k) touched = touched || any[k] != 0;
        if (!touched) return;
        Float8 vox[2 * kRows];  // {t0, w0, .., t3, w3}, {t4, w4, .., t7, w7} per row
        std::memcpy(vox, row, sizeof(vox));
        for (int g = 0; g < kRows; ++g) {
            const Float8 sdf = d[g] - pz[g];
            const Float8 f_raw = sdf * inv_mu;
            const Float8 f = f_raw < 1.0f ? f_raw : 1.0f;
            const Float8 tsdf =
                __builtin_shuffle(vox[2 * g], vox[2 * g + 1], Int8{0, 2, 4, 6, 8, 10, 12, 14});
            const Float8 w =
                __builtin_shuffle(vox[2 * g], vox[2 * g + 1], Int8{1, 3, 5, 7, 9, 11, 13, 15});
            const Float8 w1 = w + 1.0f;
            const Float8 new_tsdf = ok[g] ? (w * tsdf + f) / w1 : tsdf;
            const Float8 cap = {max_w, max_w, max_w, max_w, max_w, max_w, max_w, max_w};
            const Float8 new_w = ok[g] ? (max_w < w1 ? cap : w1) : w;
            vox[2 * g] = __builtin_shuffle(new_tsdf, new_w, Int8{0, 8, 1, 9, 2, 10, 3, 11});
            vox[2 * g + 1] = __builtin_shuffle(new_tsdf, new_w, Int8{4, 12, 5, 13, 6, 14, 7, 15});
            if (colours != nullptr) {
                const Float8 abs_sdf = sdf < 0.0f ? -sdf : sdf;
                const Int8 near = ok[g] & (abs_sdf <= colour_band_m);
                for (int half = 0; half < 2; ++half) {
                    const int b = 4 * half;
                    const Int4 near4 = {near[b], near[b + 1], near[b + 2], near[b + 3]};
                    if ((near4[0] | near4[1] | near4[2] | near4[3]) == 0) continue;
                    const Int4 pixels4 = {pixels[g][b], pixels[g][b + 1], pixels[g][b + 2],
                                          pixels[g][b + 3]};
                    blendColours(near4, pixels4, &colours[8 * g + b]);
                }
            }
        }
        std::memcpy(static_cast<void*>(row), vox, sizeof(vox));
    }
#endif

    /// C <- (W C + c) / (W + 1) per channel, W saturating at max_w, for the four voxel colours
    /// v[0..3] whose lane in `near` is set, from the colour pixels `pixels` (valid indices in
    /// every lane): blendColourChannel's float operations in lanes, so each lane gets exactly its
    /// result. The other lanes keep their colour.
    void blendColours(Int4 near, Int4 pixels, VoxelColour* v) const {
        UInt4 packed;
        static_assert(sizeof(packed) == 4 * sizeof(VoxelColour));
        static_assert(std::endian::native == std::endian::little, "r, g, b, weight from bit 0");
        std::memcpy(&packed, v, sizeof(packed));
        const Rgb8 c[4] = {colour[pixels[0]], colour[pixels[1]], colour[pixels[2]],
                           colour[pixels[3]]};
        const UInt4 sample_r = {c[0].r, c[1].r, c[2].r, c[3].r};
        const UInt4 sample_g = {c[0].g, c[1].g, c[2].g, c[3].g};
        const UInt4 sample_b = {c[0].b, c[1].b, c[2].b, c[3].b};
        const UInt4 w = packed >> 24;
        const Float4 wf = __builtin_convertvector(w, Float4);
        const Float4 w1 = wf + 1.0f;
        const auto channel = [&](UInt4 avg, UInt4 sample) {
            const Float4 q = (wf * __builtin_convertvector(avg, Float4) +
                              __builtin_convertvector(sample, Float4)) /
                             w1;
            return __builtin_convertvector(q + 0.5f, UInt4);
        };
        const UInt4 r = channel(packed & 0xffu, sample_r);
        const UInt4 g = channel((packed >> 8) & 0xffu, sample_g);
        const UInt4 b = channel((packed >> 16) & 0xffu, sample_b);
        const Int4 grows = (w1 <= max_w) & (w < 255u);
        const UInt4 new_w = grows ? w + 1u : w;
        const UInt4 blended = r | (g << 8) | (b << 16) | (new_w << 24);
        packed = near ? blended : packed;
        std::memcpy(static_cast<void*>(v), &packed, sizeof(packed));
    }
};

bool keyLess(const BlockKey& a, const BlockKey& b) {
    if (a.z() != b.z()) return a.z() < b.z();
    if (a.y() != b.y()) return a.y() < b.y();
    return a.x() < b.x();
}

void sortUnique(std::vector<BlockKey>* keys) {
    std::sort(keys->begin(), keys->end(), keyLess);
    keys->erase(std::unique(keys->begin(), keys->end()), keys->end());
}

Eigen::Vector3i floorVec(const Eigen::Vector3f& p) {
    return {static_cast<int>(std::floor(p.x())), static_cast<int>(std::floor(p.y())),
            static_cast<int>(std::floor(p.z()))};
}

/// Calls visit(cell) for every block cell the segment a -> b (in block units) passes through
/// (Amanatides & Woo 3-D DDA), in order from a to b.
template <typename Visit>
void traverseSegment(const Eigen::Vector3f& a, const Eigen::Vector3f& b, Visit&& visit) {
    const Eigen::Vector3f dir = b - a;
    Eigen::Vector3i cell = floorVec(a);
    const Eigen::Vector3i last = floorVec(b);
    int step[3];
    float t_max[3];
    float t_delta[3];
    constexpr float kInf = std::numeric_limits<float>::infinity();
    for (int i = 0; i < 3; ++i) {
        if (dir[i] > 0.0f) {
            step[i] = 1;
            t_max[i] = (static_cast<float>(cell[i] + 1) - a[i]) / dir[i];
            t_delta[i] = 1.0f / dir[i];
        } else if (dir[i] < 0.0f) {
            step[i] = -1;
            t_max[i] = (a[i] - static_cast<float>(cell[i])) / -dir[i];
            t_delta[i] = -1.0f / dir[i];
        } else {
            step[i] = 0;
            t_max[i] = kInf;
            t_delta[i] = kInf;
        }
    }
    const int max_steps = (last - cell).cwiseAbs().sum() + 1;
    for (int s = 0; s <= max_steps; ++s) {
        visit(cell);
        if (cell == last) break;
        int axis = 0;
        if (t_max[1] < t_max[axis]) axis = 1;
        if (t_max[2] < t_max[axis]) axis = 2;
        if (t_max[axis] > 1.0f) break;
        cell[axis] += step[axis];
        t_max[axis] += t_delta[axis];
    }
}

/// A small direct-mapped cache of recently seen block keys: neighbouring pixels cross the same
/// blocks, so most cells are filtered here before a hash-map lookup.
class RecentKeys {
  public:
    RecentKeys() { slots_.fill(Eigen::Vector3i(INT32_MIN, INT32_MIN, INT32_MIN)); }
    /// True when `k` was seen recently; otherwise remembers it and returns false.
    bool seen(const BlockKey& k) {
        Eigen::Vector3i& slot = slots_[hashBlockKey(k.x(), k.y(), k.z()) & (kSlots - 1)];
        if (slot == k) return true;
        slot = k;
        return false;
    }

  private:
    static constexpr uint32_t kSlots = 256;
    std::array<Eigen::Vector3i, kSlots> slots_;
};

}  // namespace

Status TsdfConfig::validate() const {
    if (!(voxel_size_m > 0.0f) || !std::isfinite(voxel_size_m)) {
        return invalidArgument("tsdf: voxel_size_m must be positive, got " +
                               std::to_string(voxel_size_m));
    }
    if (!(truncation_m >= voxel_size_m)) {
        return invalidArgument("tsdf: truncation_m must be at least one voxel, got " +
                               std::to_string(truncation_m));
    }
    if (!(max_depth_m > min_depth_m) || !(min_depth_m >= 0.0f)) {
        return invalidArgument("tsdf: need 0 <= min_depth_m < max_depth_m");
    }
    if (!(max_weight >= 1.0f)) return invalidArgument("tsdf: max_weight must be >= 1");
    if (allocation_stride_px < 1 || allocation_stride_px > 8) {
        return invalidArgument("tsdf: allocation_stride_px must be in [1, 8]");
    }
    if (!(colour_band > 0.0f && colour_band <= 1.0f)) {
        return invalidArgument("tsdf: colour_band must be in (0, 1]");
    }
    if (num_threads < 0) return invalidArgument("tsdf: num_threads must be >= 0");
    return Status::ok();
}

TsdfVolume::TsdfVolume(const TsdfConfig& config) : config_(config) {
    const Status s = config_.validate();
    PLUMB_CHECK(s.isOk()) << s.toString();
}

void TsdfVolume::clear() {
    hash_.clear();
    block_keys_.clear();
    voxels_.clear();
    colours_.clear();
    has_colour_ = false;
    stamps_.clear();
}

void TsdfVolume::saveState(io::StateWriter& out) const {
    out.value(config_.voxel_size_m);
    out.value<uint64_t>(config_.max_blocks);
    out.array(block_keys_);
    out.array(voxels_);
    out.value<uint8_t>(has_colour_ ? 1 : 0);
    out.array(colours_);
    out.array(stamps_);
    out.value(frame_stamp_);
}

Status TsdfVolume::loadState(io::StateReader& in) {
    clear();
    float voxel_size_m = 0.0f;
    uint64_t max_blocks = 0;
    std::vector<BlockKey> keys;
    uint8_t has_colour = 0;
    if (!in.value(&voxel_size_m) || !in.value(&max_blocks) || !in.array(&keys) ||
        !in.array(&voxels_) || !in.value(&has_colour) || !in.array(&colours_) ||
        !in.array(&stamps_) || !in.value(&frame_stamp_)) {
        clear();
        return corrupt("TSDF volume state: truncated");
    }
    const bool sizes_match = voxels_.size() == keys.size() * kBlockVoxels &&
                             stamps_.size() == keys.size() &&
                             colours_.size() == (has_colour ? voxels_.size() : 0);
    if (voxel_size_m != config_.voxel_size_m || max_blocks != config_.max_blocks || !sizes_match ||
        has_colour > 1) {
        clear();
        return corrupt("TSDF volume state: saved with another configuration or damaged");
    }
    has_colour_ = has_colour == 1;
    for (size_t i = 0; i < keys.size(); ++i) {
        if (hash_.find(keys[i]) != BlockHashMap::kNotFound) {
            clear();
            return corrupt("TSDF volume state: a block is listed twice");
        }
        hash_.insert(keys[i], static_cast<int32_t>(i));
    }
    block_keys_ = std::move(keys);
    return Status::ok();
}

std::vector<BlockKey> TsdfVolume::collectBlocks(const DepthImage& depth,
                                                const PinholeCamera& camera,
                                                const Eigen::Isometry3d& T_V_C,
                                                uint32_t stamp) const {
    const int height = depth.height();
    const int width = depth.width();
    const int stride = config_.allocation_stride_px;
    const float mu = config_.truncation_m;
    const float inv_block = 1.0f / blockSize();
    const Eigen::Matrix3f R = T_V_C.linear().cast<float>();
    const Eigen::Vector3f t = T_V_C.translation().cast<float>();
    // Fixed chunks of rows, independent of the thread count; merged in chunk order.
    constexpr int kRowsPerChunk = 16;
    const int num_chunks = (height + kRowsPerChunk - 1) / kRowsPerChunk;
    std::vector<std::vector<BlockKey>> chunk_keys(static_cast<size_t>(num_chunks));
    parallelFor(config_.num_threads, num_chunks, [&](int c) {
        std::vector<BlockKey>& fresh = chunk_keys[static_cast<size_t>(c)];
        RecentKeys recent;
        auto visit = [&](const BlockKey& key) {
            if (recent.seen(key)) return;
            const int32_t index = hash_.find(key);
            if (index == BlockHashMap::kNotFound) {
                fresh.push_back(key);
            } else if (stamp != 0) {
                // Every writer stores the same value: the outcome is order-independent.
                std::atomic_ref<uint32_t>(stamps_[static_cast<size_t>(index)])
                    .store(stamp, std::memory_order_relaxed);
            }
        };
        const int v_end = std::min(height, (c + 1) * kRowsPerChunk);
        for (int v = c * kRowsPerChunk; v < v_end; ++v) {
            if (v % stride != 0) continue;
            for (int u = 0; u < width; u += stride) {
                const float d = depth(u, v);
                if (!(d >= config_.min_depth_m && d <= config_.max_depth_m)) continue;
                const Eigen::Vector3f ray = camera.ray(u, v).cast<float>();
                const float z0 = std::max(d - mu, 0.5f * config_.min_depth_m);
                const Eigen::Vector3f a = (R * (ray * z0) + t) * inv_block;
                const Eigen::Vector3f b = (R * (ray * (d + mu)) + t) * inv_block;
                traverseSegment(a, b, visit);
            }
        }
        sortUnique(&fresh);
    });
    std::vector<BlockKey> all;
    size_t total = 0;
    for (const auto& k : chunk_keys) total += k.size();
    all.reserve(total);
    for (const auto& k : chunk_keys) all.insert(all.end(), k.begin(), k.end());
    sortUnique(&all);
    return all;
}

size_t TsdfVolume::countNewBlocks(const DepthImage& depth, const PinholeCamera& camera,
                                  const Eigen::Isometry3d& T_V_C) const {
    return collectBlocks(depth, camera, T_V_C, 0).size();
}

Result<IntegrationStats> TsdfVolume::integrate(const DepthImage& depth, const PinholeCamera& camera,
                                               const Eigen::Isometry3d& T_V_C,
                                               const ColourImage* colour) {
    if (depth.width() != camera.width || depth.height() != camera.height) {
        return invalidArgument("tsdf integrate: depth is " + std::to_string(depth.width()) + "x" +
                               std::to_string(depth.height()) + " but the camera is " +
                               camera.toString());
    }
    if (colour != nullptr &&
        (colour->width() != depth.width() || colour->height() != depth.height())) {
        return invalidArgument("tsdf integrate: colour is " + std::to_string(colour->width()) +
                               "x" + std::to_string(colour->height()) + " but depth is " +
                               std::to_string(depth.width()) + "x" +
                               std::to_string(depth.height()));
    }
    if (!lie::isValidPose(T_V_C, 1e-4)) {
        return invalidArgument("tsdf integrate: camera pose is not a finite rigid transform");
    }
    if (depth.size() >= (size_t{1} << 24)) {  // pixel indices are computed in float lanes
        return invalidArgument("tsdf integrate: depth images of 2^24 pixels or more (" +
                               std::to_string(depth.width()) + "x" +
                               std::to_string(depth.height()) + ") are not supported");
    }
    // Stamp the existing blocks the frame's truncation band crosses; collect the new ones.
    ++frame_stamp_;
    if (frame_stamp_ == 0) {  // wrapped: clear old stamps so none can match by accident
        std::fill(stamps_.begin(), stamps_.end(), 0u);
        frame_stamp_ = 1;
    }
    const std::vector<BlockKey> fresh = collectBlocks(depth, camera, T_V_C, frame_stamp_);
    const size_t num_new = fresh.size();
    if (config_.max_blocks > 0 && block_keys_.size() + num_new > config_.max_blocks) {
        return failedPrecondition("tsdf integrate: block budget of " +
                                  std::to_string(config_.max_blocks) + " blocks reached (" +
                                  std::to_string(block_keys_.size()) + " allocated, frame needs " +
                                  std::to_string(num_new) + " more)");
    }
    if (colour != nullptr && !has_colour_) {
        has_colour_ = true;  // from now on every block carries colour; older voxels have none
        colours_.assign(voxels_.size(), VoxelColour{});
    }
    const size_t needed = voxels_.size() + num_new * kBlockVoxels;
    if (needed > voxels_.capacity()) voxels_.reserve(std::max(needed, 2 * voxels_.capacity()));
    if (has_colour_ && needed > colours_.capacity()) {
        colours_.reserve(std::max(needed, 2 * colours_.capacity()));
    }
    for (const BlockKey& key : fresh) {
        const int32_t index = allocateBlock(key);
        stamps_[static_cast<size_t>(index)] = frame_stamp_;
    }
    // Visible blocks in allocation order (deterministic).
    visible_.clear();
    for (size_t i = 0; i < stamps_.size(); ++i) {
        if (stamps_[i] == frame_stamp_) visible_.push_back(static_cast<int32_t>(i));
    }
    IntegrationStats stats;
    stats.blocks_visible = visible_.size();
    stats.blocks_allocated = num_new;
    stats.blocks_total = block_keys_.size();
    const std::vector<int32_t>& indices = visible_;

    // Camera <- volume transform in float; voxel centres are g * voxel_size.
    const Eigen::Isometry3d T_C_V = T_V_C.inverse();
    const Eigen::Matrix3f R = T_C_V.linear().cast<float>();
    const Eigen::Vector3f t = T_C_V.translation().cast<float>();
    const float vs = config_.voxel_size_m;
    const Eigen::Vector3f dx = R.col(0) * vs;
    const Eigen::Vector3f dy = R.col(1) * vs;
    const Eigen::Vector3f dz = R.col(2) * vs;
    RowIntegrator fuse;
    fuse.depth = depth.data();
    fuse.width = depth.width();
    fuse.height = depth.height();
    fuse.fx = static_cast<float>(camera.fx);
    fuse.fy = static_cast<float>(camera.fy);
    fuse.cx = static_cast<float>(camera.cx);
    fuse.cy = static_cast<float>(camera.cy);
    fuse.mu = config_.truncation_m;
    fuse.inv_mu = 1.0f / config_.truncation_m;
    fuse.min_d = config_.min_depth_m;
    fuse.max_d = config_.max_depth_m;
    fuse.max_w = config_.max_weight;
    fuse.colour = colour != nullptr ? colour->data() : nullptr;
    fuse.colour_band_m = config_.colour_band * config_.truncation_m;
    static_assert(kBlockSide == 8, "rows are fused 8 voxels at a time");
    [[maybe_unused]] const bool avx2 = simd::best() == simd::Level::kAvx2;

    parallelFor(config_.num_threads, static_cast<int>(indices.size()), [&](int i) {
        const int32_t index = indices[static_cast<size_t>(i)];
        const BlockKey& key = block_keys_[static_cast<size_t>(index)];
        Voxel* voxels = blockVoxels(index);
        VoxelColour* colours = colour != nullptr
                                   ? colours_.data() + static_cast<size_t>(index) * kBlockVoxels
                                   : nullptr;
        const Eigen::Vector3f origin_V = (key * kBlockSide).cast<float>() * vs;
        const Eigen::Vector3f base = R * origin_V + t;
        // Local copies: the voxel stores (floats) could otherwise alias the parameters, which
        // would then be reloaded from memory for every 4 voxels.
        const RowIntegrator f = fuse;
        const Eigen::Vector3f step_x = dx, step_y = dy, step_z = dz;
        constexpr int kRows = 2;  // rows fused together
        for (int z = 0; z < kBlockSide; ++z) {
            for (int y = 0; y < kBlockSide; y += kRows) {
                Eigen::Vector3f p[kRows];
                for (int j = 0; j < kRows; ++j) {
                    p[j] =
                        base + static_cast<float>(z) * step_z + static_cast<float>(y + j) * step_y;
                }
                Voxel* rows = voxels + z * 64 + y * 8;
                VoxelColour* row_colours = colours != nullptr ? colours + z * 64 + y * 8 : nullptr;
#ifdef PLUMB_TSDF_AVX2
                if (avx2) {
                    f.fuseTwoRowsAvx2(rows, p, step_x, row_colours);
                    continue;
                }
#endif
                f.fuseRows<kRows>(rows, p, step_x, row_colours);
            }
        }
    });
    return stats;
}

int32_t TsdfVolume::allocateBlock(const BlockKey& key) {
    const int32_t found = hash_.find(key);
    if (found != BlockHashMap::kNotFound) return found;
    if (config_.max_blocks > 0 && block_keys_.size() >= config_.max_blocks) return -1;
    const auto index = static_cast<int32_t>(block_keys_.size());
    hash_.insert(key, index);
    block_keys_.push_back(key);
    stamps_.push_back(0);
    voxels_.resize(voxels_.size() + kBlockVoxels);
    if (has_colour_) colours_.resize(voxels_.size());
    return index;
}

const Voxel* TsdfVolume::voxel(const Eigen::Vector3i& g) const {
    const int32_t b = hash_.find(blockOf(g));
    if (b == BlockHashMap::kNotFound) return nullptr;
    return blockVoxels(b) + voxelIndexInBlock(g);
}

namespace {

/// Block lookups straight from the volume's hash.
struct HashFind {
    const TsdfVolume* volume;
    const Voxel* operator()(int x, int y, int z) const {
        const int32_t b = volume->findBlock(BlockKey(x, y, z));
        return b == BlockHashMap::kNotFound ? nullptr : volume->blockVoxels(b);
    }
};

/// Block lookups through a thread's cache.
struct CacheFind {
    BlockCache* cache;
    const Voxel* operator()(int x, int y, int z) const { return cache->find(x, y, z); }
};

template <typename Find>
Sample interpolateWith(const Eigen::Vector3f& p, float voxel_size, float min_weight, Find&& find,
                       float* tsdf, Eigen::Vector3f* grad = nullptr) {
    const Eigen::Vector3f q = p / voxel_size;
    const Eigen::Vector3f f = q.array().floor();
    const Eigen::Vector3i g = f.cast<int>();
    const Eigen::Vector3f a = q - f;
    float c[8];
    if ((g.x() & 7) < 7 && (g.y() & 7) < 7 && (g.z() & 7) < 7) {
        // Fast path: all 8 voxels in one block.
        const BlockKey b = blockOf(g);
        const Voxel* block = find(b.x(), b.y(), b.z());
        if (block == nullptr) return Sample::kUnallocated;
        const Voxel* base = block + voxelIndexInBlock(g);
        bool observed = true;
        for (int i = 0; i < 8; ++i) {
            const Voxel& v = base[(i & 1) + ((i >> 1) & 1) * 8 + ((i >> 2) & 1) * 64];
            observed &= v.weight >= min_weight;
            c[i] = v.tsdf;
        }
        if (!observed) return Sample::kUnobserved;
    } else {
        // The cell straddles block faces: look up each of its (2, 4 or 8) blocks once.
        const Eigen::Vector3i b0 = blockOf(g);
        const Eigen::Vector3i step((g.x() & 7) == 7, (g.y() & 7) == 7, (g.z() & 7) == 7);
        const Voxel* blocks[8];
        for (int i = 0; i < 8; ++i) {
            const Eigen::Vector3i d(i & 1, (i >> 1) & 1, (i >> 2) & 1);
            if ((d.array() > step.array()).any()) continue;  // same block as an earlier corner
            blocks[i] = find(b0.x() + d.x(), b0.y() + d.y(), b0.z() + d.z());
            if (blocks[i] == nullptr) return i == 0 ? Sample::kUnallocated : Sample::kUnobserved;
        }
        for (int i = 0; i < 8; ++i) {
            const Eigen::Vector3i corner = g + Eigen::Vector3i(i & 1, (i >> 1) & 1, (i >> 2) & 1);
            const Eigen::Vector3i d = blockOf(corner) - b0;
            const Voxel& v = blocks[d.x() + 2 * d.y() + 4 * d.z()][voxelIndexInBlock(corner)];
            if (!(v.weight >= min_weight)) return Sample::kUnobserved;
            c[i] = v.tsdf;
        }
    }
    const float c00 = c[0] + a.x() * (c[1] - c[0]);
    const float c10 = c[2] + a.x() * (c[3] - c[2]);
    const float c01 = c[4] + a.x() * (c[5] - c[4]);
    const float c11 = c[6] + a.x() * (c[7] - c[6]);
    const float c0 = c00 + a.y() * (c10 - c00);
    const float c1 = c01 + a.y() * (c11 - c01);
    *tsdf = c0 + a.z() * (c1 - c0);
    if (grad != nullptr) {
        // The trilinear interpolant's own derivatives at p: along x the bilinear blend of the
        // four x-edges' differences, along y that of the two y-differences of the x-blends,
        // along z the difference of the two xy-blends.
        const float inv_h = 1.0f / voxel_size;
        const float dx0 = (c[1] - c[0]) + a.y() * ((c[3] - c[2]) - (c[1] - c[0]));
        const float dx1 = (c[5] - c[4]) + a.y() * ((c[7] - c[6]) - (c[5] - c[4]));
        const float dy = (c10 - c00) + a.z() * ((c11 - c01) - (c10 - c00));
        *grad = Eigen::Vector3f(dx0 + a.z() * (dx1 - dx0), dy, c1 - c0) * inv_h;
    }
    return Sample::kObserved;
}

template <typename Find>
bool gradientWith(const Eigen::Vector3f& p, float voxel_size, float min_weight, Find&& find,
                  Eigen::Vector3f* grad) {
    // Central differences of the trilinear interpolant, (F(p + h e_i) - F(p - h e_i)) / 2h. The
    // six shifted cells share the fractional offset of p's cell g and together read 32 voxels of
    // the 4^3 neighbourhood [g - 1, g + 2]: gather those once, looking each block up once (at
    // most 2 per axis), instead of six independent interpolations.
    const float h = voxel_size;
    const Eigen::Vector3f q = p / h;
    const Eigen::Vector3f fl = q.array().floor();
    const Eigen::Vector3i g = fl.cast<int>();
    const Eigen::Vector3f a = q - fl;
    const Eigen::Vector3i lo = g - Eigen::Vector3i::Ones();
    const BlockKey b_lo = blockOf(lo);
    // Per axis and neighbourhood coordinate i in [0, 3]: the block step from b_lo (0 or 1) and the
    // voxel offset inside that block, so a voxel's address is two table reads away.
    int step[3][4], offset[3][4];
    for (int axis = 0; axis < 3; ++axis) {
        for (int i = 0; i < 4; ++i) {
            const int c = lo[axis] + i;
            step[axis][i] = (c >> 3) - b_lo[axis];
            offset[axis][i] = (c & 7) << (3 * axis);
        }
    }
    // The blocks the neighbourhood reaches, by block step sx + 2 sy + 4 sz; a missing one reads as
    // unobserved voxels, so every load below is valid and one weight test covers them all.
    static const std::array<Voxel, kBlockVoxels> kUnobserved{};
    const Voxel* blocks[8];
    for (int k = 0; k < 8; ++k) {
        const int sx = k & 1, sy = (k >> 1) & 1, sz = k >> 2;
        const Voxel* b = nullptr;
        if (sx <= step[0][3] && sy <= step[1][3] && sz <= step[2][3]) {
            b = find(b_lo.x() + sx, b_lo.y() + sy, b_lo.z() + sz);
        }
        blocks[k] = b != nullptr ? b : kUnobserved.data();
    }
    // n[x][y][z]: TSDF at lo + (x, y, z), x, y, z in [0, 3]; only the 32 voxels used are filled.
    float n[4][4][4];
    bool observed = true;
    const auto load = [&](int x, int y, int z) {
        const Voxel& vx = blocks[step[0][x] + 2 * step[1][y] + 4 * step[2][z]]
                                [offset[0][x] + offset[1][y] + offset[2][z]];
        observed &= vx.weight >= min_weight;
        n[x][y][z] = vx.tsdf;
    };
    // The voxels with at most one coordinate outside the central cell {1, 2}^3: the central
    // 2 x 2 x 2 and one voxel beyond each of its faces along each axis.
    for (int i = 0; i < 4; ++i) {
        for (int j = 1; j < 3; ++j) {
            for (int k = 1; k < 3; ++k) {
                load(i, j, k);
                if (i == 1 || i == 2) continue;  // the centre, loaded once, along x
                load(j, i, k);
                load(j, k, i);
            }
        }
    }
    if (!observed) return false;
    // Trilinear interpolation in the cell whose lowest corner is (x, y, z) of the neighbourhood.
    const auto cell = [&](int x, int y, int z) {
        const float c00 = n[x][y][z] + a.x() * (n[x + 1][y][z] - n[x][y][z]);
        const float c10 = n[x][y + 1][z] + a.x() * (n[x + 1][y + 1][z] - n[x][y + 1][z]);
        const float c01 = n[x][y][z + 1] + a.x() * (n[x + 1][y][z + 1] - n[x][y][z + 1]);
        const float c11 =
            n[x][y + 1][z + 1] + a.x() * (n[x + 1][y + 1][z + 1] - n[x][y + 1][z + 1]);
        const float c0 = c00 + a.y() * (c10 - c00);
        const float c1 = c01 + a.y() * (c11 - c01);
        return c0 + a.z() * (c1 - c0);
    };
    const float inv_2h = 1.0f / (2.0f * h);
    (*grad)[0] = (cell(2, 1, 1) - cell(0, 1, 1)) * inv_2h;
    (*grad)[1] = (cell(1, 2, 1) - cell(1, 0, 1)) * inv_2h;
    (*grad)[2] = (cell(1, 1, 2) - cell(1, 1, 0)) * inv_2h;
    return true;
}

}  // namespace

bool TsdfVolume::interpolateColour(const Eigen::Vector3f& p, Eigen::Vector3f* rgb) const {
    if (!has_colour_) return false;
    const Eigen::Vector3f q = p / config_.voxel_size_m;
    const Eigen::Vector3i g0 = floorVec(q);
    const Eigen::Vector3f f = q - g0.cast<float>();
    Eigen::Vector3f sum = Eigen::Vector3f::Zero();
    float wsum = 0.0f;
    for (int k = 0; k < 8; ++k) {
        const Eigen::Vector3i g = g0 + Eigen::Vector3i(k & 1, (k >> 1) & 1, (k >> 2) & 1);
        const int32_t b = findBlock(blockOf(g));
        if (b == BlockHashMap::kNotFound) continue;
        const VoxelColour& c = colours_[static_cast<size_t>(b) * kBlockVoxels +
                                        static_cast<size_t>(voxelIndexInBlock(g))];
        if (c.weight == 0) continue;
        const float w = ((k & 1) ? f.x() : 1.0f - f.x()) * ((k & 2) ? f.y() : 1.0f - f.y()) *
                        ((k & 4) ? f.z() : 1.0f - f.z());
        sum += w * Eigen::Vector3f(c.r, c.g, c.b);
        wsum += w;
    }
    if (!(wsum > 1e-6f)) return false;
    *rgb = sum / wsum;
    return true;
}

bool TsdfVolume::interpolate(const Eigen::Vector3f& p, float min_weight, float* tsdf) const {
    return interpolateWith(p, config_.voxel_size_m, min_weight, HashFind{this}, tsdf) ==
           Sample::kObserved;
}

Sample TsdfVolume::sample(const Eigen::Vector3f& p, float min_weight, BlockCache* cache,
                          float* tsdf) const {
    return interpolateWith(p, config_.voxel_size_m, min_weight, CacheFind{cache}, tsdf);
}

Sample TsdfVolume::sample(const Eigen::Vector3f& p, float min_weight, BlockCache* cache,
                          float* tsdf, Eigen::Vector3f* grad) const {
    return interpolateWith(p, config_.voxel_size_m, min_weight, CacheFind{cache}, tsdf, grad);
}

bool TsdfVolume::gradient(const Eigen::Vector3f& p, float min_weight, Eigen::Vector3f* grad) const {
    return gradientWith(p, config_.voxel_size_m, min_weight, HashFind{this}, grad);
}

bool TsdfVolume::gradient(const Eigen::Vector3f& p, float min_weight, BlockCache* cache,
                          Eigen::Vector3f* grad) const {
    return gradientWith(p, config_.voxel_size_m, min_weight, CacheFind{cache}, grad);
}

BlockCache::BlockCache(const TsdfVolume& volume) : volume_(&volume) {
    for (Slot& s : slots_) s.x = std::numeric_limits<int32_t>::min();
}

}  // namespace plumb::tsdf
