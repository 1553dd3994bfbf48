// SPDX-License-Identifier: Apache-2.0
#pragma once

// Per-frame preprocessing for tracking (reference §2.1): range gating, a masked bilateral filter,
// a depth pyramid and per-level vertex and normal maps in the camera frame.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/core/simd.hpp"
#include "common/core/status.hpp"
#include "common/image/image.hpp"
#include "common/tsdf/raycast.hpp"

namespace plumb::device {

using tsdf::PointImage;

struct PreprocessConfig {
    /// Depth below this is invalid, metres.
    float min_depth_m = 0.1f;
    /// Depth beyond this is invalid, metres.
    float max_depth_m = 4.0f;
    /// Apply the masked bilateral filter to the tracking depth.
    bool bilateral = true;
    /// Half window of the bilateral filter in pixels (3 = 7x7).
    int bilateral_radius_px = 3;
    /// Spatial sigma of the bilateral filter at 640 px width, pixels; scaled with the width.
    float bilateral_sigma_space_px = 4.5f;
    /// Range sigma of the bilateral filter, metres. Neighbours further than 3 sigma are ignored.
    float bilateral_sigma_depth_m = 0.03f;
    /// Most pyramid levels (level 0 = full resolution, each next level half the size); see
    /// min_level_width_px.
    int num_levels = 3;
    /// Coarser levels are only built while they stay at least this wide, pixels. Below about 80
    /// px the coarsest ICP level has too few valid normals on far views and can pull the first
    /// estimate out of the basin (a 160x120 camera gets 2 levels: 160 and 80 px).
    int min_level_width_px = 80;
    /// A normal is invalid when a neighbour's depth differs by more than this, metres.
    float max_normal_depth_jump_m = 0.05f;
    /// Worker threads (0 = TBB default). Results do not depend on it.
    int num_threads = 0;

    Status validate() const;
};

struct PyramidLevel {
    PinholeCamera camera;  ///< intrinsics of this level
    DepthImage depth;      ///< filtered depth, metres, 0 = invalid
    PointImage points_C;   ///< vertex map V(u) = D(u) K^-1 [u, 1], camera frame (NaN = invalid)
    PointImage normals_C;  ///< unit normals facing the camera (NaN = invalid)
};

struct FramePyramid {
    DepthImage depth;                  ///< range-gated, unfiltered depth (for integration)
    std::vector<PyramidLevel> levels;  ///< level 0 = full resolution
};

/// Range gating: depth outside [min_depth_m, max_depth_m] or not finite becomes 0.
DepthImage gateDepth(const DepthImage& depth, const PreprocessConfig& config);

/// Masked bilateral filter: invalid neighbours and neighbours more than 3 sigma_depth away from
/// the centre are ignored; invalid pixels stay invalid.
/// Runs the best kernel this CPU has (simd::best()).
DepthImage bilateralFilter(const DepthImage& depth, const PreprocessConfig& config);
/// The same with the kernel chosen: every level gives the same image, bit for bit.
DepthImage bilateralFilter(const DepthImage& depth, const PreprocessConfig& config,
                           simd::Level simd_level);

/// Half-size depth: mean of the valid pixels of each 2x2 block within 3 sigma_depth of the
/// block's first valid pixel (KinFu style, never averaging across depth edges). `num_threads`
/// workers (0 = TBB default); the result does not depend on it.
DepthImage downsampleDepth(const DepthImage& depth, float sigma_depth_m, int num_threads = 0);

/// Vertex and normal maps of a depth image. Normals from central differences,
/// n = normalize((V(u+1,v) - V(u-1,v)) x (V(u,v+1) - V(u,v-1))), flipped to face the camera.
/// `num_threads` workers (0 = TBB default); the result does not depend on it.
void computeVertexNormalMaps(const DepthImage& depth, const PinholeCamera& camera,
                             float max_depth_jump_m, PointImage* points_C, PointImage* normals_C,
                             int num_threads = 0);

/// The whole chain. Fails when the image size does not match the camera.
Result<FramePyramid> preprocess(const DepthImage& depth, const PinholeCamera& camera,
                                const PreprocessConfig& config);

}  // namespace plumb::device
