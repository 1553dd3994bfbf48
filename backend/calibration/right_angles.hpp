// SPDX-License-Identifier: Apache-2.0
#pragma once

// Self-calibration of the part of the depth distortion that keeps planes planes, from the right
// angles of the room (reference §7c). A factor whose inverse is affine in the pixel,
//
//   1 / z_measured = 1 / z + delta . (x, y, 1),                                            (Eq. 1)
//
// (x, y) the pinhole-normalised image coordinates, maps every plane to a plane, so planarity
// (planar_distortion.hpp) cannot see it, and the poses of a reconstruction bend to fit it. It does
// move every plane: a plane n . P = h, written as its vector pi = n / h (1 / z = pi . (x, y, 1)
// on it), is measured as
//
//   pi_measured = pi + delta,                                                               (Eq. 2)
//
// one translation for all planes of all frames. Angles between planes therefore change, by an
// amount that depends on each plane's distance: a wall and the floor of one frame are no longer
// perpendicular once measured, and the floor and a table top no longer parallel. Rooms are built
// of right angles (walls stand on the floor, most meet at 90 degrees); the pairs of one frame's
// planes within max_off_deg of perpendicular or parallel are taken to be exactly so, and delta is
// the robust least-squares fit of
//
//   perpendicular:  cos angle(pi_1 - delta, pi_2 - delta) = 0,                              (Eq. 3)
//   parallel:       sin angle(pi_1 - delta, pi_2 - delta) = 0 (its cross-product direction),
//
// by Gauss-Newton with Huber weights (huber_deg). The scale of the depth (delta's partner a in
// a / z) changes no angle: it stays with the estimate against the reconstruction.
//
// A sensor's offset need not be one for all depths (a table estimated at tracked poses, which
// bent to fit it, tilts one way at 1 m and the other at 3 m). With depth_dependent, delta is
// interpolated in depth like the table, from delta_near at its 1 m bin to delta_far at its 3 m
// bin (constant beyond both), and each plane moves by delta at its mean depth: planes of one
// depth stay planes, and the planar stage sees what bends those spanning depths.
//
// Thread-safety: free functions of their arguments.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "backend/calibration/planar_distortion.hpp"
#include "common/calibration/distortion_table.hpp"
#include "common/camera/pinhole.hpp"
#include "common/config/schema.hpp"
#include "common/core/status.hpp"

namespace plumb::calibration {

struct RightAngleConfig {
    /// Whether the self-calibration's planar stages remove the offset the right angles show ...
    bool enabled = false;
    /// ... also `plumb reconstruct --self-calibrate`'s first one, of the raw depth (off: only
    /// the last, after the table refined at poses, and `plumb calibrate --planar-only`'s).
    bool first_pass = false;
    /// Two planes of one frame within this of perpendicular (or of parallel) are taken to be
    /// exactly so; degrees. The bend of Eq. 1 moves angles by tenths of a degree.
    double max_off_deg = 3.0;
    /// Parallel pairs are used when their distances from the camera differ by at least this,
    /// metres (Eq. 2 moves parallel planes apart in angle only when they are).
    double min_parallel_gap_m = 0.3;
    /// Planes of fewer blocks are not used.
    int min_blocks = 60;
    /// Estimate delta at the 1 m and the 3 m bin apart (linear in depth between them) instead
    /// of one delta for all depths.
    bool depth_dependent = false;
    /// Estimate delta's third component, the offset of the disparity over the whole image (a
    /// scale of the depth that grows with depth), too; off: only its tilts across the image
    /// (the first two), and the depth's scale stays with the estimate against the model.
    bool estimate_uniform = true;
    /// Huber threshold on a pair's angle residual, degrees.
    double huber_deg = 0.1;
    /// Gauss-Newton iterations.
    int iterations = 10;
    /// At least this many perpendicular pairs, and each direction of delta observed by all the
    /// pairs (the smallest eigenvalue of the normal equations at least min_observation of the
    /// largest), or the estimate fails.
    int min_pairs = 30;
    double min_observation = 0.01;
};

void describe(config::Schema& s, RightAngleConfig& c);
/// OK, or kInvalidArgument naming the first field out of range.
Status validate(const RightAngleConfig& c);

/// Eq. 1's delta, (x, y, 1) coefficients, 1 / metre: `near` at 1 m, `far` at 3 m, linear in
/// depth between them and constant beyond.
struct DisparityOffset {
    static constexpr double kNearM = 1.0;
    static constexpr double kFarM = 3.0;
    Eigen::Vector3d near = Eigen::Vector3d::Zero();
    Eigen::Vector3d far = Eigen::Vector3d::Zero();
    Eigen::Vector3d at(double z) const;
};

struct RightAngleEstimate {
    DisparityOffset delta;
    size_t frames = 0;         ///< frames with at least one pair
    size_t perpendicular = 0;  ///< pairs used
    size_t parallel = 0;
    /// RMS of the pairs' angle residuals (Huber-weighted), degrees, with delta = 0 and with the
    /// estimate.
    double rms_before_deg = 0.0;
    double rms_after_deg = 0.0;
    /// Smallest over largest eigenvalue of the final normal equations.
    double observation = 0.0;
};

/// Fits Eq. 3 to the planes of each frame (SegmentPlane, in a camera frame whose pinhole
/// normalised coordinates are those of Eq. 1). kFailedPrecondition when the pairs are too few or
/// leave a direction of delta unobserved (the message says which).
Result<RightAngleEstimate> estimateRightAngles(const std::vector<std::vector<SegmentPlane>>& frames,
                                               const RightAngleConfig& config);

/// `table` with Eq. 1's delta removed from the depth it undistorts: each cell's factor at bin
/// centre z multiplied by 1 + z delta(z) . (x, y, 1) (the table is read at the undistorted depth z,
/// and 1 / z = 1 / z_table - delta . (x, y, 1) is z = z_table (1 + z delta . (x, y, 1))),
/// (x, y) the cell centre through `camera` (scaled to the table's 640x480 grid). Cells without
/// data stay so.
DistortionTable removeDisparityOffset(const DistortionTable& table, const DisparityOffset& delta,
                                      const PinholeCamera& camera);

}  // namespace plumb::calibration
