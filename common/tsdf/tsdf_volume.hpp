// SPDX-License-Identifier: Apache-2.0
#pragma once

// Voxel-hashed truncated signed distance volume (reference §2.3, §2.5). Space is cut into blocks of
// 8^3 voxels; only blocks near observed surfaces exist. A voxel holds a float TSDF value in [-1, 1]
// (signed distance / truncation, positive in free space) and a float weight: 8 bytes. A volume
// fused with colour (reference §7b.2) also holds, beside every voxel, an 8-bit RGB running average
// and its weight (VoxelColour, 4 bytes); a volume fused from depth alone allocates none.
//
// Grid convention: voxel g = (i, j, k) (global integer index) has its centre at g * voxel_size_m in
// the volume's frame V (the world frame of the poses passed to integrate()). Block key b holds the
// voxels g with floor(g / 8) == b. Trilinear samples at a point p use the 8 voxels around p /
// voxel_size_m.
//
// Thread-safety: const member functions may run concurrently; integrate() and clear() need
// exclusive access. Results never depend on the thread count.

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/core/status.hpp"
#include "common/image/image.hpp"
#include "common/io/state_archive.hpp"
#include "common/tsdf/block_hash.hpp"

namespace plumb::tsdf {

constexpr int kBlockSide = 8;                                       ///< voxels per block edge
constexpr int kBlockVoxels = kBlockSide * kBlockSide * kBlockSide;  ///< voxels per block

struct Voxel {
    float tsdf = 1.0f;    ///< signed distance / truncation, in [-1, 1]; positive = free space
    float weight = 0.0f;  ///< accumulated observation weight; 0 = never observed
};
static_assert(sizeof(Voxel) == 8, "a voxel must stay 8 bytes");

/// Colour of a voxel near the surface: running average C <- (W C + c) / (W + 1), rounded.
struct VoxelColour {
    uint8_t r = 0;
    uint8_t g = 0;
    uint8_t b = 0;
    uint8_t weight = 0;  ///< observations averaged (saturating at TsdfConfig::max_weight); 0 = none
};
static_assert(sizeof(VoxelColour) == 4, "a voxel colour must stay 4 bytes");

/// One channel of the colour running average, round((w avg + sample) / (w + 1)) with halves
/// rounded up, for w, avg, sample in [0, 255], in float: the numerator is an integer below 2^16
/// (exact), the division is correctly rounded, and a quotient is either exactly k + 1/2 (which
/// float holds) or at least 1 / (2 (w + 1)) >= 1/512 away from it, far more than its rounding
/// error, so floor(q + 1/2) is exact. The integration's four-lane blend does the same operations
/// lane by lane.
inline uint8_t blendColourChannel(uint32_t avg, uint32_t w, uint32_t sample) {
    const float q = (static_cast<float>(w) * static_cast<float>(avg) + static_cast<float>(sample)) /
                    (static_cast<float>(w) + 1.0f);
    return static_cast<uint8_t>(q + 0.5f);
}

class BlockCache;

/// What a trilinear sample found (TsdfVolume::sample).
enum class Sample {
    kUnallocated,  ///< the block holding p does not exist
    kUnobserved,   ///< a voxel of p's cell is missing or has weight below the minimum
    kObserved,     ///< the sample holds a value
};

struct TsdfConfig {
    /// Edge length of a voxel, metres (KinFu: 3 m / 512 = 5.86 mm).
    float voxel_size_m = 3.0f / 512.0f;
    /// Truncation distance mu, metres: the band [-mu, +mu] around surfaces that is fused.
    float truncation_m = 0.04f;
    /// Depth readings beyond this are ignored during integration, metres.
    float max_depth_m = 4.0f;
    /// Depth readings below this are ignored during integration, metres.
    float min_depth_m = 0.1f;
    /// Weights saturate here (KinFu W_max = 128), so old observations can be overruled.
    float max_weight = 128.0f;
    /// Maximum number of allocated blocks (4 KiB each); 0 = unlimited. integrate() refuses a frame
    /// whose new blocks would exceed it (the caller closes the fragment).
    size_t max_blocks = 0;
    /// Pixel stride of block allocation (1 = every pixel). Blocks are 8 voxels wide, so a stride
    /// of 2 still touches every block a surface passes through at normal range.
    int allocation_stride_px = 2;
    /// Colour is fused into voxels within this fraction of the truncation from the measured
    /// surface (|sdf| <= colour_band * truncation_m): the voxels that surface points and mesh
    /// vertices interpolate, not the free space in front or the far side.
    float colour_band = 0.25f;
    /// Worker threads (0 = TBB default). Results do not depend on it.
    int num_threads = 0;

    Status validate() const;
};

/// What one integrate() call did.
struct IntegrationStats {
    size_t blocks_visible = 0;    ///< blocks touched by the frame's truncation band (integrated)
    size_t blocks_allocated = 0;  ///< of these, newly created
    size_t blocks_total = 0;      ///< allocated blocks after the call
};

class TsdfVolume {
  public:
    explicit TsdfVolume(const TsdfConfig& config = {});

    const TsdfConfig& config() const { return config_; }
    float voxelSize() const { return config_.voxel_size_m; }
    float blockSize() const { return config_.voxel_size_m * kBlockSide; }

    /// Fuses a depth image (metres, 0 = invalid) seen by `camera` at pose T_V_C (camera -> volume).
    /// Allocates the blocks crossed by each pixel's segment [d - mu, d + mu] (exact 3-D DDA), then
    /// updates every voxel of those blocks with the projective distance of §2.3:
    /// sdf = D(u) - z_C, skipped when sdf < -mu; F <- (W F + min(1, sdf/mu)) / (W + 1).
    /// Fails with kFailedPrecondition (volume unchanged) when the block budget would be exceeded,
    /// and with kInvalidArgument when the image size does not match the camera.
    /// With `colour` (registered to `depth`, same size) voxels within the colour band of the
    /// measured surface also average the pixel's colour; the TSDF values are the same as without.
    Result<IntegrationStats> integrate(const DepthImage& depth, const PinholeCamera& camera,
                                       const Eigen::Isometry3d& T_V_C,
                                       const ColourImage* colour = nullptr);

    /// Number of blocks the frame would add to the volume (for budget checks), without changing it.
    size_t countNewBlocks(const DepthImage& depth, const PinholeCamera& camera,
                          const Eigen::Isometry3d& T_V_C) const;

    /// Index of block `key`, creating it (all voxels unobserved) when missing. Returns -1 when the
    /// block budget is reached. For tests and for writers of analytic fields.
    int32_t allocateBlock(const BlockKey& key);

    /// Removes every block.
    void clear();

    /// Appends the whole state (blocks in index order, voxels, colours, per-block stamps) to
    /// `out`. loadState() restores it into a volume of the same configuration, after which
    /// every call behaves exactly as on the saved volume. kCorrupt for a damaged state or one
    /// saved with another voxel size or block budget (the volume is then cleared).
    void saveState(io::StateWriter& out) const;
    Status loadState(io::StateReader& in);

    size_t numBlocks() const { return block_keys_.size(); }
    size_t memoryBytes() const {
        return voxels_.size() * sizeof(Voxel) + colours_.size() * sizeof(VoxelColour);
    }
    /// True once a frame with colour was fused (until clear()).
    bool hasColour() const { return has_colour_; }
    const std::vector<BlockKey>& blockKeys() const { return block_keys_; }

    /// Index of block `key` or -1.
    int32_t findBlock(const BlockKey& key) const { return hash_.find(key); }
    /// The 512 voxels of block `index` (x fastest, then y, then z).
    const Voxel* blockVoxels(int32_t index) const {
        return voxels_.data() + static_cast<size_t>(index) * kBlockVoxels;
    }
    Voxel* blockVoxels(int32_t index) {
        return voxels_.data() + static_cast<size_t>(index) * kBlockVoxels;
    }

    /// The 512 voxel colours of block `index`, or nullptr when the volume has no colour.
    const VoxelColour* blockColours(int32_t index) const {
        return has_colour_ ? colours_.data() + static_cast<size_t>(index) * kBlockVoxels : nullptr;
    }

    /// Trilinear colour at p (volume frame, metres) over the voxels of p's cell that hold colour,
    /// RGB in [0, 255]. False when the volume has no colour or no voxel of the cell has any.
    bool interpolateColour(const Eigen::Vector3f& p, Eigen::Vector3f* rgb) const;

    /// The voxel at global index g, or nullptr when its block does not exist.
    const Voxel* voxel(const Eigen::Vector3i& g) const;

    /// Trilinear TSDF at point p (volume frame, metres). False when a block is missing or one of
    /// the 8 voxels has weight < min_weight (pass min_weight > 0: weight 0 = never observed).
    bool interpolate(const Eigen::Vector3f& p, float min_weight, float* tsdf) const;
    /// The same, with the block lookups going through a thread's `cache` of this volume, and
    /// telling apart a missing block at p from other unobserved voxels of p's cell.
    Sample sample(const Eigen::Vector3f& p, float min_weight, BlockCache* cache, float* tsdf) const;
    /// The same, also giving the gradient of the trilinear interpolant at p (units 1/m) from the
    /// same 8 voxels: within one cell, the exact derivative of the sampled field.
    Sample sample(const Eigen::Vector3f& p, float min_weight, BlockCache* cache, float* tsdf,
                  Eigen::Vector3f* grad) const;

    /// Gradient of the trilinear TSDF at p by central differences one voxel apart (units 1/m),
    /// from one gather of the 32 voxels the six shifted cells read.
    /// False when a sample is unavailable.
    bool gradient(const Eigen::Vector3f& p, float min_weight, Eigen::Vector3f* grad) const;
    /// The same, with the block lookups going through a thread's `cache` of this volume.
    bool gradient(const Eigen::Vector3f& p, float min_weight, BlockCache* cache,
                  Eigen::Vector3f* grad) const;

  private:
    /// Walks the blocks crossed by the frame's truncation band: existing blocks get
    /// stamps_[i] = stamp (unless stamp == 0); returns the sorted, unique keys of missing ones.
    std::vector<BlockKey> collectBlocks(const DepthImage& depth, const PinholeCamera& camera,
                                        const Eigen::Isometry3d& T_V_C, uint32_t stamp) const;

    TsdfConfig config_;
    BlockHashMap hash_;
    std::vector<BlockKey> block_keys_;  ///< key of block i
    std::vector<Voxel> voxels_;         ///< block i occupies [i * 512, (i + 1) * 512)
    std::vector<VoxelColour> colours_;  ///< as voxels_ when has_colour_, else empty
    bool has_colour_ = false;
    /// Per block: the integrate() call (frame_stamp_) that last saw it. Written by
    /// collectBlocks() under integrate()'s exclusive access only.
    mutable std::vector<uint32_t> stamps_;
    uint32_t frame_stamp_ = 0;
    std::vector<int32_t> visible_;  ///< scratch: visible blocks of the current frame
};

/// A small direct-mapped cache in front of a volume's block hash, for one thread working through
/// nearby points (a row of rays): the 8 x 8 x 8 blocks around the last lookups are found without
/// touching the hash table, which for a room is megabytes and misses the core's caches. Blocks
/// that are not allocated are cached as such. Not thread-safe; the volume must not change while a
/// cache of it is in use.
class BlockCache {
  public:
    explicit BlockCache(const TsdfVolume& volume);

    /// The 512 voxels of block (x, y, z), or nullptr when it is not allocated.
    const Voxel* find(int x, int y, int z) {
        Slot& s = slots_[static_cast<size_t>((x & 7) | ((y & 7) << 3) | ((z & 7) << 6))];
        if (s.x != x || s.y != y || s.z != z) {
            const int32_t b = volume_->findBlock(BlockKey(x, y, z));
            s = Slot{x, y, z, b == BlockHashMap::kNotFound ? nullptr : volume_->blockVoxels(b)};
        }
        return s.voxels;
    }

  private:
    struct Slot {
        int32_t x, y, z;  ///< block key; x = INT32_MIN: empty (no block key reaches it)
        const Voxel* voxels;
    };
    const TsdfVolume* volume_;
    std::array<Slot, 512> slots_;
};

/// Block key holding global voxel g.
inline BlockKey blockOf(const Eigen::Vector3i& g) {
    return {g.x() >> 3, g.y() >> 3, g.z() >> 3};  // arithmetic shift = floor division by 8
}
/// Index of voxel g inside its block.
inline int voxelIndexInBlock(const Eigen::Vector3i& g) {
    return (g.x() & 7) + 8 * (g.y() & 7) + 64 * (g.z() & 7);
}

}  // namespace plumb::tsdf
