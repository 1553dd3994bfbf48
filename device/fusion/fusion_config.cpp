// SPDX-License-Identifier: Apache-2.0
#include "device/fusion/fusion_config.hpp"

#include "common/config/registry.hpp"
#include "common/tsdf/tsdf_config.hpp"
#include "device/fusion/fragment_builder.hpp"

namespace plumb::device {

void describe(config::Schema& s, PreprocessConfig& c) {
    s.field("min_depth_m", c.min_depth_m, "depth below this is invalid", "m").min(0.0);
    s.field("max_depth_m", c.max_depth_m, "depth beyond this is invalid", "m").positive();
    s.field("bilateral", c.bilateral, "apply the masked bilateral filter to the tracking depth");
    s.field("bilateral_radius_px", c.bilateral_radius_px,
            "half window of the bilateral filter (3 = 7x7)", "px")
        .range(0, 10);
    s.field("bilateral_sigma_space_px", c.bilateral_sigma_space_px,
            "spatial sigma of the bilateral filter at 640 px width (scaled with the width)", "px")
        .positive();
    s.field("bilateral_sigma_depth_m", c.bilateral_sigma_depth_m,
            "range sigma of the bilateral filter; neighbours beyond 3 sigma are ignored", "m")
        .positive();
    s.field("num_levels", c.num_levels, "pyramid levels (each next level half the size)")
        .range(1, 5);
    s.field("min_level_width_px", c.min_level_width_px,
            "coarser pyramid levels are built only while at least this wide (a 160 px camera "
            "gets 2 levels)",
            "px")
        .min(1);
    s.field("max_normal_depth_jump_m", c.max_normal_depth_jump_m,
            "a normal is invalid when a neighbour's depth differs by more than this", "m")
        .positive();
    s.field("num_threads", c.num_threads, "worker threads (0 = all); results do not depend on it")
        .min(0);
}

void describe(config::Schema& s, IcpConfig& c) {
    s.field("iterations_fine", c.iterations[0],
            "Gauss-Newton iterations at full resolution (KinFu 10)")
        .range(0, 100);
    s.field("iterations_mid", c.iterations[1],
            "Gauss-Newton iterations at half resolution (KinFu 5)")
        .range(0, 100);
    s.field("iterations_coarse", c.iterations[2],
            "Gauss-Newton iterations at quarter resolution, run first (KinFu 4)")
        .range(0, 100);
    s.field("max_distance_m", c.max_distance_m, "correspondences further apart are rejected", "m")
        .positive();
    s.field("max_normal_angle_deg", c.max_normal_angle_deg,
            "correspondences whose normals differ more are rejected", "deg")
        .greaterThan(0.0)
        .max(90.0);
    s.field("min_update_norm", c.min_update_norm, "a level stops when |xi| falls below this")
        .min(0.0);
    s.field("min_inlier_fraction", c.min_inlier_fraction,
            "tracking fails with fewer inliers than this fraction of the valid pixels")
        .range(0.0, 1.0);
    s.field("max_translation_m", c.max_translation_m,
            "tracking fails when the camera moved further than this in one frame", "m")
        .positive();
    s.field("max_rotation_deg", c.max_rotation_deg,
            "tracking fails when the camera turned more than this in one frame", "deg")
        .positive();
    s.field("min_normalized_eigenvalue", c.min_normalized_eigenvalue,
            "directions whose eigenvalue of J^T J / inliers is below this keep the predicted pose "
            "(solution remapping)")
        .min(0.0);
    s.field("min_normal_spread", c.min_normal_spread,
            "a translation t is unconstrained when mean (n.t)^2 over the inliers is below this; "
            "the pose then keeps the prediction along t (walking down a corridor, along a wall) "
            "instead of following the few pixels that face t (0 = never)")
        .min(0.0)
        .max(1.0);
    s.field("max_degenerate_directions", c.max_degenerate_directions,
            "tracking fails when more translations than this are unconstrained (a single plane "
            "leaves 2, a wall meeting the floor 1); unconstrained directions follow the "
            "constant-velocity prediction")
        .range(0, 3);
    s.field("weak_motion_decay", c.weak_motion_decay,
            "along directions below min_normalized_eigenvalue the pose takes the predicted motion "
            "scaled by this (1 = the constant-velocity prediction); a roll about the normal of the "
            "only plane in view then dies out instead of being carried on")
        .range(0.0, 1.0);
    s.field("num_threads", c.num_threads, "worker threads (0 = all); results do not depend on it")
        .min(0);
}

void describe(config::Schema& s, PhotometricConfig& c) {
    s.field("colour", c.enabled,
            "track with the photometric term when the source has colour (off: depth only)");
    s.field("weight", c.weight,
            "relative weight lambda of the photometric term: sum (r_icp / depth_sigma_m)^2 + "
            "lambda sum huber(r_I / intensity_sigma)^2 is minimised (unit-free)")
        .min(0.0);
    s.field("depth_sigma_m", c.depth_sigma_m,
            "scale of the point-to-plane residual the intensity residual is weighed against", "m")
        .positive();
    s.field("intensity_sigma", c.intensity_sigma,
            "scale of the intensity residual (intensities in [0, 1])")
        .positive();
    s.field("huber_delta", c.huber_delta,
            "Huber threshold of the intensity residual; also what counts as an inlier")
        .positive();
    s.field("max_residual", c.max_residual,
            "intensity residuals above this (occlusions, highlights) are left out")
        .positive();
    s.field("min_gradient", c.min_gradient,
            "reference pixels are used where |grad I| is at least this (intensity per pixel)")
        .min(0.0);
    s.field("max_points", c.max_points,
            "at most this many reference points per pyramid level, taken evenly (bounds the cost; "
            "the sums are scaled to all selected pixels)")
        .min(1);
    s.field("min_points", c.min_points,
            "with fewer textured reference pixels the frame is tracked by depth only (too little "
            "texture)")
        .min(0);
    s.field("min_inlier_fraction", c.min_inlier_fraction,
            "when fewer visible reference points than this fraction agree at the final pose "
            "(exposure jump, blur, motion) the frame is tracked again by depth only")
        .range(0.0, 1.0);
    s.field("affine_brightness", c.affine_brightness,
            "estimate a gain and offset of each frame's intensity against its reference");
    s.field("smoothing_sigma_px", c.smoothing_sigma_px,
            "Gaussian smoothing of the full-resolution intensity before gradients", "px")
        .range(0.0, 5.0);
}

void describe(config::Schema& s, FusionConfig& c) {
    s.field("frames_per_fragment", c.frames_per_fragment,
            "a fragment is cut every this many frames (paper: 50)", "frames")
        .min(1);
    s.field("constant_velocity", c.constant_velocity,
            "start tracking from a constant-velocity prediction (else from the last pose)");
    s.field("handover_frames", c.handover_frames,
            "after a cut, track this many frames of the new fragment against the previous "
            "fragment's volume (0 = against the new fragment's own volume)",
            "frames")
        .min(0);
    s.section("tsdf", c.tsdf, "the voxel-hashed TSDF volume of each fragment");
    s.field("model_level", c.model_level,
            "pyramid level the tracking model is raycast at for frames tracked by depth alone (0 "
            "= full resolution, 1 = half: 4x fewer rays); finer frame levels associate against "
            "it")
        .range(0, 4);
    s.field("model_level_rgbd", c.model_level_rgbd,
            "the same for frames tracked with colour (the photometric term)")
        .range(0, 4);
    s.field("min_model_width_px", c.min_model_width_px,
            "the model is cast no coarser than the finest level at least this wide, whatever "
            "model_level and model_level_rgbd ask (640x480 casts at 320x240, 320x240 at full "
            "resolution)",
            "px")
        .min(1);
    s.field("raycast_from_last_depth", c.raycast_from_last_depth,
            "model rays march from the depth last fused from the same pose (a truncation in "
            "front of it) instead of from the nearest block");
    s.field("raycast_interval", c.raycast_interval,
            "frames tracked against one model raycast (1 = cast for every frame; 2 = the "
            "prediction cast after a frame is integrated also tracks the frame after next), for "
            "frames tracked by depth alone",
            "frames")
        .min(1);
    s.field("raycast_interval_rgbd", c.raycast_interval_rgbd,
            "the same for frames tracked with colour (the photometric term)", "frames")
        .min(1);
    s.field("max_integration_hz", c.max_integration_hz,
            "frames arriving faster are tracked but fused at about this rate (a frame is fused "
            "when 0.75 / max_integration_hz s have passed since the last one fused: a 60 Hz "
            "camera fuses every other frame, a 30 Hz one every frame); 0 = fuse every frame",
            "Hz")
        .min(0.0);
    s.section("raycast", c.raycast, "model prediction (raycast) for tracking");
    s.section("surface", c.surface, "oriented surface points of a closed fragment");
    s.section("preprocess", c.preprocess, "per-frame filtering, vertex/normal maps, pyramid");
    s.section("icp", c.icp, "frame-to-model projective point-to-plane ICP and its failure tests");
    s.field("fuse_colour", c.fuse_colour,
            "fuse the frames' colour into the fragment volumes (coloured fragment points) when "
            "the source has colour");
    s.section("tracking", c.tracking,
              "RGB-D tracking: the photometric term against the last tracked frame, on when the "
              "source has colour");
}

PLUMB_PROGRAM_CONFIG(fusion, "fusion", FusionConfig,
                     "on-device tracking and fusion into fragments (plumb fuse, plumb-device)");

}  // namespace plumb::device
