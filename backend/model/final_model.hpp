// SPDX-License-Identifier: Apache-2.0
#pragma once

// The final model: once the fragment poses are optimised, every frame's pose is
// T_W_C = T_W_F * T_F_C. When the raw frames are available (datasets, simulator, logs with raw
// depth) they are all re-integrated with those poses into one TSDF and meshed. Otherwise (a live
// scan where only fragments crossed the wire) each fragment's oriented surface points are rendered
// back into the depth images of the frames that made them (z-buffered splats, back-faces culled)
// and those synthetic frames are integrated instead: the same volumetric averaging, so overlapping
// fragments merge into one surface rather than a stack of shifted copies. Colour goes along
// either way (the raw frames' colour, or the fragments' point colours): the mesh is coloured
// when the scan is.
//
// Thread-safety: the functions keep no state between calls and may run concurrently on different
// inputs; each parallelises internally over num_threads.

#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/cloud/point_cloud.hpp"
#include "common/config/schema.hpp"
#include "common/core/progress_callback.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "common/frame/frame_source.hpp"
#include "common/image/image.hpp"
#include "common/io/trajectory.hpp"

namespace plumb::backend {

struct FinalModelConfig {
    /// Voxel edge of the final volume, metres. Coarser than the device's 5.86 mm: the final volume
    /// spans the whole room and 1 cm keeps a 900-frame scan well inside a minute.
    double voxel_size_m = 0.01;
    /// Truncation distance, metres (4 voxels).
    double truncation_m = 0.04;
    /// Depth beyond this is not integrated, metres (noise grows with z^2).
    double max_depth_m = 4.0;
    /// Integrate every k-th frame of the source (1 = all); raw frames in between are skipped
    /// without being decoded or rendered where the source allows (FrameSource::skip). Larger
    /// strides trade reconstruction error for time; the default keeps every frame.
    int frame_stride = 1;
    /// Fragment surfaces only: every k-th tracked frame of each fragment (its first included)
    /// is rendered and integrated. The synthetic frames of one fragment are views of one
    /// surface, not independent measurements, so most of them repeat each other: 4 loses no
    /// accuracy against 1 on the simulated scans (BENCHMARKS.md) at a quarter of the work.
    int surface_frame_stride = 4;
    /// plumb-backend: the raw frames the device streamed (stream.raw_frame_every) and the ingest
    /// kept are re-integrated instead of the fragment surfaces when every fragment has at least
    /// this share of its tracked frames among them (1 = all; 0.2 admits raw_frame_every = 4,
    /// the fragment surfaces' own stride, of which a 50-frame fragment holds 12 or 13); else
    /// the surfaces are fused and the log says why.
    double min_raw_frame_share = 0.2;
    /// Raw frames without colour (a device streaming depth only, stream.raw_frame_colour =
    /// false) of a scan whose fragments carry colour: each vertex of the mesh takes the colour
    /// of the nearest fragment point within this distance, metres, at the variant's poses (mid
    /// grey beyond it), so that the mesh keeps the scan's colour. 3 voxels: the fragments'
    /// points lie on the surface the raw frames re-measure, well within it. 0: left uncoloured.
    double fragment_colour_radius_m = 0.03;
    /// Pixel stride of block allocation. The final volume's blocks are 8 cm wide, where a pixel
    /// spans 2 to 8 mm at 1 to 4 m: every fourth pixel still samples each block the surface
    /// passes through, and the allocation walk costs a quarter of every pixel's.
    int allocation_stride_px = 4;
    /// Voxels observed fewer times are not meshed.
    double min_weight = 1.0;
    /// Splat radius (pixels) when rendering fragment points into synthetic depth frames.
    int splat_radius_px = 1;
    /// Worker threads for integration and meshing (0 = all). Results do not depend on it.
    int num_threads = 0;

    Status validate() const;
};
void describe(config::Schema& s, FinalModelConfig& c);

/// Camera->world pose of every frame of every fragment, T_W_C = T_W_F[i] * T_F_C, stamped with the
/// frame's timestamp, in fragment then frame order. Frames whose tracking failed are left out.
io::Trajectory frameTrajectory(const std::vector<Fragment>& fragments,
                               const std::vector<Eigen::Isometry3d>& T_W_F);

/// Renders `points_F` (oriented, in frame F) as seen by `camera` at T_F_C: nearest depth per pixel
/// over a (2r+1)^2 splat, points facing away from the camera skipped. 0 = no data. An oriented
/// point's splat lies in its tangent plane (each pixel's depth is where its ray meets the plane,
/// within 4 splat widths of the point's depth), so slanted surfaces come out where they are
/// rather than as steps towards the camera; points without normals splat at their own depth.
/// With `colour` and a coloured cloud, *colour receives the nearest point's colour per pixel
/// (else it is left empty).
DepthImage renderPointsToDepth(const PointCloud& points_F, const PinholeCamera& camera,
                               const Eigen::Isometry3d& T_F_C, int splat_radius_px,
                               ColourImage* colour = nullptr);

/// Colours `mesh` (world frame) from the coloured points of `fragments` placed at T_W_F: each
/// vertex takes the colour of the nearest point within `radius_m` (mid grey beyond it, as a
/// volume without colour gives). Fragments without colour contribute no points; when none has
/// colour, or the mesh is empty, the mesh is left as it is and the result is false.
/// Deterministic whatever num_threads (0 = all).
bool colourFromFragmentPoints(const std::vector<Fragment>& fragments,
                              const std::vector<Eigen::Isometry3d>& T_W_F, double radius_m,
                              int num_threads, TriangleMesh* mesh);

struct FinalModel {
    TriangleMesh mesh;             ///< marching cubes of the final volume, world frame
    size_t frames_integrated = 0;  ///< depth images fused
    size_t blocks = 0;             ///< TSDF blocks allocated
    bool from_raw_frames = false;  ///< true: raw frames re-integrated; false: fragment surfaces
    /// Raw frames only: none had colour and the mesh took the fragments' point colours
    /// (FinalModelConfig::fragment_colour_radius_m).
    bool colour_from_fragments = false;
};

/// Re-integrates the raw frames of `source` (read from the start until it ends, once) at the
/// poses of every variant in `T_W_F` (one set of fragment poses per variant, e.g. the full method
/// and the baseline; each set keyed by Frame::index through `frameTrajectory`'s order: fragments'
/// frame indices), one volume per variant: the result has one model per variant, in order.
/// Frames without an optimised pose are skipped. While a frame is integrated the next one is
/// read. When no frame has colour and the fragments do, each mesh is coloured from them
/// (colourFromFragmentPoints). Fails when the source's frames do not match the fragments (no frame
/// index in common).
Result<std::vector<FinalModel>> integrateRawFrames(
    FrameSource& source, const std::vector<Fragment>& fragments,
    const std::vector<std::vector<Eigen::Isometry3d>>& T_W_F, const FinalModelConfig& config,
    const ProgressCallback& progress = {});

/// Fuses the fragments' surfaces through synthetic depth frames (see the file comment), one
/// volume per variant of `T_W_F` (as integrateRawFrames); each synthetic frame is rendered once
/// (it lies in its fragment's frame) and integrated into every volume.
Result<std::vector<FinalModel>> fuseFragmentSurfaces(
    const std::vector<Fragment>& fragments,
    const std::vector<std::vector<Eigen::Isometry3d>>& T_W_F, const PinholeCamera& camera,
    const FinalModelConfig& config, const ProgressCallback& progress = {});

}  // namespace plumb::backend
