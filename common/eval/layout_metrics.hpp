// SPDX-License-Identifier: Apache-2.0
#pragma once

// Layout errors (DESIGN.md "Measuring"): how far an estimated layout's walls, floor and ceiling
// are from the ground truth's.
//
// Both layouts are brought into one comparison frame with their own T_W_L (reference §0:
// n_B = R n_A, d_B = d_A - n_B.t): the ground-truth layout frame L_gt (default) or the world
// frame W. Planes are compared unoriented: an estimated plane whose normal points away from the
// ground truth's is flipped, (n, d) -> (-n, -d), before measuring (and reported as flipped).
//
// Matching: every (ground-truth wall, estimated wall) pair gets the cost
//   angle_rad * angle_weight_m_per_rad + |centre distance|,
// where the centre distance is the signed distance of the ground-truth wall's centre (segment
// midpoint at half the ceiling height) from the estimated plane. Pairs within the gates are
// accepted greedily by increasing cost (ties by ground-truth then estimate order), one to one.
//
// Per plane: angle error (deg, in [0, 90] after flipping), offset error d_est - d_gt in the
// comparison frame (positive: the estimated plane lies further along -n, i.e. outside the
// ground-truth wall for inward normals), and the centre distance (frame independent).
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <optional>
#include <vector>

#include "common/core/status.hpp"
#include "common/layout/layout.hpp"

namespace plumb::eval {

enum class LayoutFrame {
    kGroundTruthLayout,  ///< compare in L_gt (planes of the estimate mapped by T_W_L_gt^-1
                         ///< T_W_L_est)
    kWorld,              ///< compare in W (both layouts mapped by their T_W_L)
};

struct LayoutMetricsConfig {
    /// Frame in which offsets are compared and matched planes are reported.
    LayoutFrame frame = LayoutFrame::kGroundTruthLayout;
    /// Converts a normal angle into metres for the matching cost, metres per radian
    /// (1 m/rad: 1 degree costs as much as 1.75 cm).
    double angle_weight_m_per_rad = 1.0;
    /// Walls whose normals differ by more than this never match, degrees.
    double max_match_angle_deg = 30.0;
    /// Walls whose centre distance exceeds this never match, metres.
    double max_match_distance_m = 0.5;
};

/// The error of one estimated plane against its ground-truth plane.
struct PlaneError {
    int gt_id = 0;
    int est_id = 0;
    double angle_error_deg = 0.0;    ///< angle between the normals after orientation, degrees
    double offset_error_m = 0.0;     ///< d_est - d_gt in the comparison frame, metres
    double centre_distance_m = 0.0;  ///< estimated plane's signed distance at the GT centre, m
    bool flipped = false;            ///< the estimated normal pointed the other way
    /// The estimated plane in the comparison frame, oriented like the ground truth.
    HessianPlane estimate;
};

/// Angle between two ground-truth walls versus the angle between their matched estimates.
struct WallPairAngle {
    int gt_id_a = 0;
    int gt_id_b = 0;
    double gt_angle_deg = 0.0;   ///< angle between the ground-truth normals, [0, 180]
    double est_angle_deg = 0.0;  ///< angle between the matched, oriented estimates, [0, 180]
    double error_deg = 0.0;      ///< |est_angle_deg - gt_angle_deg|
};

struct LayoutMetrics {
    LayoutFrame frame = LayoutFrame::kGroundTruthLayout;
    size_t num_gt_walls = 0;
    size_t num_est_walls = 0;
    std::vector<PlaneError> walls;           ///< matched walls, in ground-truth order
    std::vector<int> unmatched_gt_walls;     ///< ids of ground-truth walls without a match
    std::vector<int> unmatched_est_walls;    ///< ids of estimated walls matched to nothing
    std::optional<PlaneError> floor;         ///< when both layouts have a floor
    std::optional<PlaneError> ceiling;       ///< when both layouts have a ceiling
    std::vector<WallPairAngle> wall_pairs;   ///< every pair of matched ground-truth walls
    double mean_wall_angle_error_deg = 0.0;  ///< over matched walls (0 if none)
    double max_wall_angle_error_deg = 0.0;
    double mean_abs_wall_offset_error_m = 0.0;
    double max_abs_wall_offset_error_m = 0.0;
    double max_wall_pair_angle_error_deg = 0.0;
    /// est - gt ceiling height, metres, when both are known (> 0).
    std::optional<double> ceiling_height_error_m;
};

/// Compares `estimate` against `ground_truth`. kInvalidArgument for non-finite or non-unit
/// normals, a non-rigid T_W_L or unusable gates.
Result<LayoutMetrics> evaluateLayout(const Layout& estimate, const Layout& ground_truth,
                                     const LayoutMetricsConfig& config = {});

}  // namespace plumb::eval
