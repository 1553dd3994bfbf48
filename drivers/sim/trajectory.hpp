// SPDX-License-Identifier: Apache-2.0
#pragma once

// Handheld camera trajectories through a Scene (reference §1.3). The path is a closed uniform
// cubic B-spline through control points on the room outline inset by path_inset_m (or the
// scene's own waypoints), starting at the straightest control point (mid-edge). By default the
// operator walks backwards along the walls with the camera looking back over the room at a corner
// (look_offset_deg), so that every view holds two or three non-parallel walls plus floor or ceiling
// (a view of one wall and the floor leaves ICP free to slide along the wall); a slow pitch sway
// shows floor and ceiling; speed follows the path with a yaw-rate and acceleration limit; hand
// shake adds smooth sums of sinusoids (seeded phases) to position and orientation. The loop variant
// goes around a whole number of times and ends at its start (loop closures possible) whenever
// num_frames allows a speed within [min, max] (with too few frames it is a partial lap at max
// speed); the no-loop variant covers no_loop_fraction of the loop without revisits (with more
// frames than that takes at min speed it stands at the end).
//
// Pure functions of their arguments (the seed included): thread-safe.

#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include "common/core/status.hpp"
#include "common/io/trajectory.hpp"
#include "drivers/sim/scene.hpp"

namespace plumb::sim {

struct TrajectoryConfig {
    /// true: closed loop back to the start; false: an open path without revisits.
    bool loop = true;
    /// Number of poses to generate.
    size_t num_frames = 600;
    /// Frame rate, Hz.
    double rate_hz = 30.0;
    /// Nominal walking speed bounds, m/s; the speed is chosen in this range so that the path
    /// takes num_frames (loop: truncated or repeated when it cannot).
    double min_speed_mps = 0.2;
    double max_speed_mps = 0.45;
    /// Yaw-rate limit of the smooth path (before hand shake), degrees/s.
    double max_yaw_rate_dps = 15.0;
    /// Acceleration limit along the path, m/s^2.
    double max_accel_mps2 = 0.5;
    /// Camera height above the floor and its slow sway amplitude, metres.
    double height_m = 1.4;
    double height_sway_m = 0.08;
    /// Look direction relative to the direction of travel, degrees (negative = to the right,
    /// i.e. outward on a counter-clockwise loop). 195: back along the path and 15 degrees
    /// outward, at the corner just passed and the far side of the room. Sideways views (-65)
    /// see one wall and the floor and let ICP slide along the wall; 210-225 face the wall
    /// frontally at 1.5 m while the path turns a corner.
    double look_offset_deg = 195.0;
    /// Mean pitch (negative = down) and the amplitude of its slow sway, degrees.
    double pitch_deg = -8.0;
    double pitch_sway_deg = 10.0;
    /// Amplitude of a slow roll about the optical axis (period 8 s), degrees; 0 keeps the camera
    /// level. A camera turned about its axis sees the image-fixed depth distortion along
    /// changing directions of the room (what self-calibration needs to tell it from the path).
    double roll_sway_deg = 0.0;
    /// Hand-shake amplitudes (per axis, sum of three sinusoids at 0.5-2 Hz): position, metres;
    /// rotation, degrees.
    double shake_position_m = 0.003;
    double shake_rotation_deg = 0.4;
    /// Fraction of the loop covered by the no-loop variant.
    double no_loop_fraction = 0.75;
    /// Seed of the hand-shake phases and frequencies.
    uint64_t seed = 1;
};

/// Generates num_frames poses T_W_C (camera x right, y down, z forward; world z up) with
/// timestamps k / rate_hz. Errors: a path that leaves the room or cannot be built.
Result<io::Trajectory> generateTrajectory(const Scene& scene, const TrajectoryConfig& config);

/// The closed control polygon of the path: the scene's waypoints, or its outline offset inward
/// by path_inset_m (edges subdivided to at most 1 m).
Result<std::vector<Eigen::Vector2d>> pathControlPoints(const Scene& scene);

/// Camera orientation R_W_C for a yaw (heading of the optical axis about +z, radians), pitch
/// (elevation of the optical axis, radians) and roll (about the optical axis, radians).
Eigen::Matrix3d cameraRotation(double yaw_rad, double pitch_rad, double roll_rad);

}  // namespace plumb::sim
