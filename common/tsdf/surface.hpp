// SPDX-License-Identifier: Apache-2.0
#pragma once

// Surface extraction from a TsdfVolume (reference §2.6): oriented surface points at the zero
// crossings of voxel edges ("marching-cubes vertices without triangles") and marching-cubes
// triangle meshes over those same vertices, shared across block borders (watertight where the
// surface is observed).
//
// Thread-safety: extraction only reads the volume; it may run concurrently with other readers
// while nothing integrates into it.

#include "common/cloud/point_cloud.hpp"
#include "common/tsdf/tsdf_volume.hpp"

namespace plumb::tsdf {

struct SurfaceConfig {
    /// Voxels with a smaller weight are ignored (§2.6: >= 2 observations for fragments).
    float min_weight = 2.0f;
    /// Sign changes across an edge whose two TSDF values differ by more than this are not surface
    /// (they are the +1 / -1 seams behind occluding contours). A true crossing differs by about
    /// voxel / (truncation * cos(view angle)).
    float max_tsdf_jump = 1.0f;
    /// Worker threads (0 = TBB default). Results do not depend on it.
    int num_threads = 0;
};

/// Every zero crossing on a voxel edge between two observed voxels, linearly interpolated, with
/// the unit TSDF gradient as normal (pointing into free space). Points whose gradient cannot be
/// evaluated (an unobserved neighbour) are left out. Order: block allocation order, then voxel,
/// then axis: deterministic. A volume with colour gives every point the colour of its edge's two
/// voxels, interpolated like the position (mid grey where neither voxel holds colour).
PointCloud extractSurfacePoints(const TsdfVolume& volume, const SurfaceConfig& config = {});

/// Marching-cubes mesh whose vertices are exactly extractSurfacePoints(volume, config).
/// Triangles are counter-clockwise seen from free space. Ambiguous cube faces always separate the
/// inside (negative) corners, so neighbouring cubes agree on every shared face.
TriangleMesh extractMesh(const TsdfVolume& volume, const SurfaceConfig& config = {});

}  // namespace plumb::tsdf
