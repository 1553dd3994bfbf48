// SPDX-License-Identifier: Apache-2.0
#pragma once

// Ray casting of a TsdfVolume into vertex and normal maps (reference §2.4), the model prediction
// that frame-to-model ICP aligns against. Unbiased on planes: the zero crossing is found between
// two trilinear samples and refined by one secant step; trilinear interpolation reproduces a
// linear field exactly, so a planar TSDF gives the plane to float precision.
//
// Thread-safety: raycasting only reads the volume; raycasts of one volume may run concurrently
// while nothing integrates into it.

#include <Eigen/Geometry>
#include <cmath>
#include <limits>

#include "common/camera/pinhole.hpp"
#include "common/image/image.hpp"
#include "common/tsdf/tsdf_volume.hpp"

namespace plumb::tsdf {

/// Per-pixel 3-D vectors (points or unit normals); invalid pixels hold NaN in every component.
using PointImage = Image<Eigen::Vector3f>;

/// True when a PointImage pixel holds a value.
inline bool isValid(const Eigen::Vector3f& p) { return !std::isnan(p.x()); }
/// The value of an invalid PointImage pixel.
inline Eigen::Vector3f invalidPoint() {
    return Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());
}

/// Unit normal of the point at pixel (u, v) from its 4-neighbourhood,
/// (P(u+1) - P(u-1)) x (P(v+1) - P(v-1)), unoriented. False on the image border, where the pixel
/// or a neighbour has no depth (<= 0), or where a neighbour's depth differs by more than
/// max_depth_jump (a depth edge). `points` and `depth` are images of the same size.
inline bool neighbourNormal(const PointImage& points, const Image<float>& depth, int u, int v,
                            float max_depth_jump, Eigen::Vector3f* n) {
    if (u < 1 || v < 1 || u + 1 >= depth.width() || v + 1 >= depth.height()) return false;
    const float z = depth(u, v);
    if (!(z > 0.0f)) return false;
    for (const float zn : {depth(u - 1, v), depth(u + 1, v), depth(u, v - 1), depth(u, v + 1)}) {
        if (!(zn > 0.0f) || std::abs(zn - z) > max_depth_jump) return false;
    }
    *n = (points(u + 1, v) - points(u - 1, v)).cross(points(u, v + 1) - points(u, v - 1));
    const float len = n->norm();
    if (!(len > 0.0f)) return false;
    *n /= len;
    return true;
}

/// The normal a raycast gives each hit.
enum class RaycastNormals {
    /// The TSDF gradient at the hit by central differences one voxel apart (KinectFusion §3.4):
    /// 32 more voxels a hit.
    kGradient,
    /// The gradient of the trilinear interpolant in the cell of the last sample at the crossing,
    /// from the 8 voxels that sample read (no further voxels), summed over the hits of the 3x3
    /// pixels around whose depth is within max_normal_depth_jump_m (one cell's differences span
    /// one voxel, the central ones two: alone they are about twice as noisy).
    kCell,
    /// The cross product of the neighbouring hits, (P(u+1) - P(u-1)) x (P(v+1) - P(v-1)), as for
    /// the measured frames: the neighbours span two pixels. Hits on the image border or next to
    /// a depth jump (max_normal_depth_jump_m) get no normal and are dropped.
    kNeighbours,
};

struct RaycastConfig {
    /// Marching starts at this z-depth in the camera frame, metres.
    float min_depth_m = 0.1f;
    /// Marching stops at this z-depth, metres.
    float max_depth_m = 4.0f;
    /// Step in free space = step_fraction * truncation * F (at least one voxel), §2.4. Within
    /// two voxels in front of a surface (F * truncation, the fused views' projective distance)
    /// the step instead aims half a voxel past the crossing that distance predicts, so the next
    /// sample mostly brackets it.
    float step_fraction = 0.8f;
    /// With a start hint: rays first march from this many voxels in front of the hinted depth,
    /// and from one truncation in front only when that sample is not observed free space
    /// (0 = always from one truncation in front).
    float hint_near_voxels = 2.0f;
    /// With a start hint: a ray with no hinted depth under it starts from the nearest hinted
    /// depth within this many hint pixels, and is not cast when there is none (the hinted frame
    /// saw nothing around it; nor, from nearly the same pose, will the frame being tracked).
    /// Negative: such rays march in full, from the nearest block.
    int hint_hole_radius_px = 2;
    /// With a start hint: a ray whose hinted depth lies beyond the end of its march (max_depth_m,
    /// or the farthest block along it) is not cast: the hinted frame saw free space along all of
    /// it. False: such rays march in full, from the nearest block.
    bool skip_hints_beyond_end = false;
    /// A sample that the last one aimed at the surface (F mu within two voxels) and that lands
    /// within half a voxel of it gives the hit by one secant step through the two, without
    /// bracketing the crossing first and refining it: two samples a ray from a hinted start
    /// instead of four. Exact where the field is linear along the ray.
    bool secant_hits = false;
    /// Voxels with a smaller weight count as unobserved.
    float min_weight = 1.0f;
    /// Where the hits' normals come from (RaycastNormals).
    RaycastNormals normals = RaycastNormals::kGradient;
    /// With RaycastNormals::kNeighbours (kCell): a neighbour whose depth differs by more than
    /// this, metres, is across a depth edge: no normal (not summed). The frames'
    /// preprocess.max_normal_depth_jump_m.
    float max_normal_depth_jump_m = 0.05f;
    /// Worker threads (0 = TBB default). Results do not depend on it.
    int num_threads = 0;
};

struct RaycastResult {
    PointImage points_V;   ///< surface points in the volume frame (NaN = no hit)
    PointImage normals_V;  ///< unit normals in the volume frame, facing the camera (every hit
                           ///< has one)
    DepthImage depth;      ///< z-depth of the hit in the camera frame, metres (0 = no hit)
};

/// Casts one ray per pixel of `camera` placed at T_V_C (camera -> volume). Only + to - crossings
/// (front faces) are reported; - to + crossings are ignored.
///
/// `start_hint` (optional) is depth this camera measured at this pose and fused into the volume,
/// at the camera's resolution or an integer multiple of it: the frame tracking has just
/// integrated. Each ray then marches from hint_near_voxels in front of its hinted depth (the
/// nearest of the hint pixels under it), else from one truncation and one voxel in front,
/// instead of from the nearest block, and marches the whole ray unless one of those first
/// samples is observed free space (F > 0). A surface the model still holds in front of that free
/// space (seen by older frames, not by the hinted one) is skipped. Rays over holes in the hint
/// follow hint_hole_radius_px, rays hinted beyond their end skip_hints_beyond_end.
RaycastResult raycast(const TsdfVolume& volume, const PinholeCamera& camera,
                      const Eigen::Isometry3d& T_V_C, const RaycastConfig& config = {},
                      const DepthImage* start_hint = nullptr);

}  // namespace plumb::tsdf
