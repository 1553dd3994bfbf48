// SPDX-License-Identifier: Apache-2.0
#pragma once

// Frame-to-model projective point-to-plane ICP (reference §2.2). The model is a raycast of the TSDF
// (common/tsdf/raycast.hpp) from the previous pose, one raycast per pyramid level; the frame is its
// preprocessed pyramid (device/preprocess). Frames: M = the model's frame (the fragment frame), C =
// the current camera, P = the camera the model was raycast from.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <Eigen/Geometry>
#include <array>
#include <string>
#include <vector>

#include "common/geometry/lie.hpp"
#include "common/tsdf/raycast.hpp"
#include "common/tsdf/tsdf_volume.hpp"
#include "device/preprocess/preprocess.hpp"
#include "device/tracking/photometric.hpp"

namespace plumb::device {

struct IcpConfig {
    /// Gauss-Newton iterations per pyramid level, finest first; levels run coarse to fine
    /// (KinFu {10, 5, 4}).
    std::array<int, 3> iterations = {10, 5, 4};
    /// Correspondences further apart than this are rejected, metres.
    float max_distance_m = 0.10f;
    /// Correspondences whose normals differ by more than this are rejected, degrees.
    float max_normal_angle_deg = 20.0f;
    /// A level stops when the update twist |xi| falls below this (1e-5: 10 um and 10 urad, far
    /// below the depth noise; the finest level then takes about 3 iterations instead of 6).
    double min_update_norm = 1e-5;
    /// Failure: fewer inliers than this fraction of the valid frame pixels (finest level).
    double min_inlier_fraction = 0.15;
    /// Failure: the pose moved further than this from the previous camera (the model pose when
    /// none is given), metres.
    double max_translation_m = 0.10;
    /// Failure: the pose rotated more than this from the previous camera, degrees.
    double max_rotation_deg = 10.0;
    /// Eigen-directions of J^T J whose eigenvalue divided by the inlier count is below this are
    /// not updated from the data. Along a constrained translation t it is the mean of (n.t)^2
    /// (about 1/3 for a room corner); free directions of the geometry give ~1e-5. The roll about
    /// the normal of a wall (or of parallel box faces) seen from the front gives 1e-3 to 2.5e-3,
    /// constrained only by the rounded edges of the TSDF at depth jumps, which pull it by up to
    /// 0.5 degrees per frame; 3e-3 leaves it to the prediction. 400-frame living_room,
    /// weak_manhattan and l_shape scans, largest rotation drift of a fragment: 1.8, 0.7, 1.1
    /// degrees (1e-3: 0.5, 5.9, 0.6); largest translation drift 3.9, 7.0, 37 cm (1e-3: 4.3, 8.8,
    /// 45 cm).
    double min_normalized_eigenvalue = 3e-3;
    /// Directions below min_normalized_eigenvalue keep the predicted pose (solution remapping).
    /// A translation t is unconstrained when mean (n.t)^2 over the inliers (an eigenvalue of
    /// sum n n^T / inliers) is below min_normal_spread. The pose keeps the prediction along such
    /// a t too: looking down a corridor, the few pixels that face the camera (furniture, the
    /// ragged ends of surfaces cut by the depth range) would otherwise decide the motion along
    /// it, and their errors, fed back through the constant-velocity prediction, grew into runaway
    /// drift (a 600-frame l_shape scan: 1.2 m within 25 frames). Tracking fails when more than
    /// max_degenerate_directions translations are unconstrained (a single plane leaves 2, a wall
    /// meeting the floor 1, a room corner 0). Default 2: a wall filling the view is tracked, its
    /// free directions following the constant-velocity prediction. Declaring such frames lost
    /// cuts the scan into segments of two or three frames wherever the camera faces a wall (a
    /// 600-frame living_room loop: 39 fragments instead of 14, ATE 28.7 cm instead of 8.8 cm),
    /// which costs far more than the drift of a few frames along the wall.
    double min_normal_spread = 0.02;
    int max_degenerate_directions = 2;
    /// Along the eigen-directions below min_normalized_eigenvalue the pose takes the predicted
    /// motion scaled by this factor (1 = the prediction itself). Such a direction is usually a
    /// rotation about the normal of the only plane in view (a wall or parallel box faces seen
    /// from the front), which the hand does not keep turning about: with the full prediction a
    /// roll picked up while the direction was barely observed is carried on frame after frame
    /// (a 160x120 living_room scan: 0.5 deg per frame, 13 deg within a fragment). Unconstrained
    /// translations (min_normal_spread) keep the full prediction: walking down a corridor does
    /// go on.
    double weak_motion_decay = 0.5;
    /// Worker threads (0 = TBB default). Results do not depend on it.
    int num_threads = 0;

    Status validate() const;
};

/// Raycast prediction of the model at one pyramid level, in the model frame M.
struct ModelLevel {
    PinholeCamera camera;
    PointImage points_M;
    PointImage normals_M;
};

/// The model at every level of `frame` seen from pose T_M_P: one raycast with the camera of
/// level `raycast_level` (0 = full resolution, 1 = half: 4x fewer rays), used as it is by the
/// finer levels and 2x2-averaged for the coarser ones. `start_hint`: the full-resolution depth
/// last fused from pose T_M_P, if any (tsdf::raycast marches from it).
std::vector<ModelLevel> predictModel(const tsdf::TsdfVolume& volume, const FramePyramid& frame,
                                     const Eigen::Isometry3d& T_M_P,
                                     const tsdf::RaycastConfig& config, int raycast_level = 0,
                                     const DepthImage* start_hint = nullptr);

/// The photometric term of one frame (device/tracking/photometric.hpp): the current frame's
/// intensity pyramid and an earlier tracked frame R as the reference, seen from T_M_R.
struct PhotometricInput {
    const std::vector<IntensityLevel>* current = nullptr;  ///< levels as the frame pyramid
    const PhotometricReference* reference = nullptr;
    Eigen::Isometry3d T_M_R = Eigen::Isometry3d::Identity();
    PhotometricConfig config;
};

/// What the photometric term did for one frame.
struct PhotometricStats {
    bool used = false;             ///< the final pose is from the combined RGB-D system
    std::string fallback;          ///< why the frame was tracked by depth only (empty when used)
    size_t num_selected = 0;       ///< reference pixels with a strong gradient (full resolution)
    size_t num_visible = 0;        ///< reference points landing in the frame (finest level)
    size_t num_inliers = 0;        ///< of them with |r| <= huber_delta at the final pose
    double inlier_fraction = 0.0;  ///< num_inliers / num_visible
    double rmse = 0.0;             ///< RMS Huber-weighted intensity residual of the used points
    Brightness brightness;         ///< affine brightness of the frame against the reference
};

struct IcpResult {
    Eigen::Isometry3d T_M_C = Eigen::Isometry3d::Identity();  ///< estimated camera pose
    bool ok = false;         ///< converged and passed every failure test
    std::string failure;     ///< why not ok (empty when ok)
    int iterations = 0;      ///< total Gauss-Newton iterations over all levels
    size_t num_inliers = 0;  ///< correspondences at the finest level's last iteration
    size_t num_valid = 0;    ///< valid frame pixels (with normals) at the finest level
    double inlier_fraction = 0.0;
    double rmse_m = 0.0;                     ///< point-to-plane RMS residual of the inliers, metres
    double condition_number = 0.0;           ///< of the finest level's normal equations
    double min_normalized_eigenvalue = 0.0;  ///< smallest eigenvalue of J^T J / inliers
    int num_degenerate_directions = 0;       ///< unconstrained translations (see IcpConfig)
    /// Eigenvalues (ascending) of sum n n^T / inliers at the finest level, the mean of (n.t)^2
    /// along each axis t of translation_axes_M: how strongly the geometry pins each translation.
    Eigen::Vector3d translation_spread = Eigen::Vector3d::Zero();
    /// The matching eigenvectors (columns) in the model frame M.
    Eigen::Matrix3d translation_axes_M = Eigen::Matrix3d::Identity();
    /// J^T J at the finest level (rotation first), in point-to-plane units (1 / m^2 of the
    /// point-to-plane residual): with colour, the photometric term's share is weighed in.
    Matrix6d information = Matrix6d::Zero();
    PhotometricStats photometric;  ///< the photometric term (unused without colour)
};

/// Aligns the frame to the model. T_M_P is the pose the model was raycast from (data association
/// projects into that view); T_M_C_init is the starting estimate (usually T_M_P). Each iteration
/// solves (sum J^T J) xi = -sum J^T r with r = n^T (x - v), J = [(x x n)^T, n^T] and applies
/// T <- Exp(xi) T. Deterministic for every thread count.
///
/// With `photometric` (RGB-D tracking, reference §7b.1) every level's system becomes
/// J_g^T J_g + w J_I^T W J_I with w = lambda (depth_sigma_m / intensity_sigma)^2: the
/// intensity residuals count in metres of point-to-plane residual, so the observability tests
/// (min_normal_spread, min_normalized_eigenvalue) and `information` see what the combined system
/// constrains. The frame falls back to depth only (PhotometricStats::fallback says why) when the
/// reference has fewer than min_points textured pixels, or when at the final pose fewer than
/// min_inlier_fraction of its visible points agree (then the alignment is redone without it).
///
/// `T_M_previous` (optional) is the last tracked camera: the implausible-motion tests
/// (max_translation_m, max_rotation_deg) measure from it, else from T_M_P, which for a model
/// reused over several frames lies that many frames back.
IcpResult alignFrameToModel(const FramePyramid& frame, const std::vector<ModelLevel>& model,
                            const Eigen::Isometry3d& T_M_P, const Eigen::Isometry3d& T_M_C_init,
                            const IcpConfig& config, const PhotometricInput* photometric = nullptr,
                            const Eigen::Isometry3d* T_M_previous = nullptr);

}  // namespace plumb::device
