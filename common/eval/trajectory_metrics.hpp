// SPDX-License-Identifier: Apache-2.0
#pragma once

// Trajectory accuracy with the TUM RGB-D benchmark conventions (reference §6.2):
//  - ATE: associate by timestamp, align the estimated positions to the ground truth with the
//    rigid (no scale) Horn / Umeyama closed form, report statistics of |R p_est + t - p_gt|.
//  - RPE: error of the relative motion over a fixed delta (frames or seconds), as TUM
//    evaluate_rpe.py with --fixed_delta.
// No I/O; pure functions, thread-safe.

#include <Eigen/Geometry>
#include <optional>
#include <vector>

#include "common/core/status.hpp"
#include "common/io/trajectory.hpp"

namespace plumb::eval {

struct AteOptions {
    /// Rigidly align the estimate to the ground truth (Horn, no scale) before measuring; false
    /// measures in the given frames (T_gt_est = identity).
    bool align = true;
};

struct AteResult {
    size_t num_pairs = 0;  ///< number of position pairs measured
    /// Alignment applied to the estimate: p_gt ~ T_gt_est * p_est (identity without align).
    Eigen::Isometry3d T_gt_est = Eigen::Isometry3d::Identity();
    double rmse_m = 0.0;           ///< sqrt(mean e^2)
    double mean_m = 0.0;           ///< mean e
    double median_m = 0.0;         ///< median e (mean of the middle two for an even count)
    double max_m = 0.0;            ///< largest e
    double min_m = 0.0;            ///< smallest e
    std::vector<double> errors_m;  ///< e_k = |T_gt_est p_est,k - p_gt,k|, in input order
};

/// Rigid alignment minimising sum |R p_est + t - p_gt|^2 (Horn / Umeyama without scale, §6.2):
/// centre both sets, W = sum (p_est - mean_est)(p_gt - mean_gt)^T, SVD W^T = U S V^T,
/// R = U diag(1, 1, det(U) det(V)) V^T (never a reflection), t = mean_gt - R mean_est.
/// Preconditions (checked): equal sizes, at least one point.
Eigen::Isometry3d alignRigid(const std::vector<Eigen::Vector3d>& positions_est,
                             const std::vector<Eigen::Vector3d>& positions_gt);

/// Absolute trajectory error of paired positions (positions_est[k] <-> positions_gt[k]).
/// Errors: different sizes, no pairs, fewer than 3 pairs when aligning, non-finite positions.
Result<AteResult> computeAte(const std::vector<Eigen::Vector3d>& positions_est,
                             const std::vector<Eigen::Vector3d>& positions_gt,
                             const AteOptions& options = {});

enum class DeltaUnit {
    kFrames,   ///< delta counts pairs (index i -> i + delta)
    kSeconds,  ///< delta is a time span on the estimate's stamps
};

struct RpeOptions {
    /// Span of each relative motion, in `delta_unit`: 1 frame by default (evaluate_rpe.py
    /// defaults to 1 s; use delta_unit = kSeconds to reproduce that). Frames must be an integer.
    double delta = 1.0;
    /// Unit of `delta`.
    DeltaUnit delta_unit = DeltaUnit::kFrames;
};

struct RpeResult {
    size_t num_pairs = 0;                ///< number of (i, j) motion pairs measured
    double trans_rmse_m = 0.0;           ///< RMSE of the translational error
    double trans_mean_m = 0.0;           ///< mean translational error
    double trans_median_m = 0.0;         ///< median translational error
    double trans_max_m = 0.0;            ///< largest translational error
    double rot_rmse_rad = 0.0;           ///< RMSE of the rotational error (angle)
    double rot_mean_rad = 0.0;           ///< mean rotational error
    double rot_median_rad = 0.0;         ///< median rotational error
    double rot_max_rad = 0.0;            ///< largest rotational error
    std::vector<double> trans_errors_m;  ///< per pair, in order of i
    std::vector<double> rot_errors_rad;  ///< per pair, in order of i
};

/// Relative pose error of paired, time-ordered poses (poses_est[k] <-> poses_gt[k], taken at
/// stamps_s[k]). For each i the partner j is i + delta (frames) or the stamp closest to
/// stamps_s[i] + delta (seconds; pairs whose target lies more than 1 us beyond the last stamp
/// are skipped).
/// As evaluate_rpe.py: E = (E_j^-1 E_i)^-1 (G_j^-1 G_i); the translational error is |t(E)|,
/// the rotational error the angle of R(E). Invariant to a rigid change of either world frame.
/// Stamps may be empty for kFrames; for kSeconds they must be non-decreasing.
/// Errors: kInvalidArgument for a size mismatch, a non-positive or fractional-frame delta or
/// unsorted stamps; kOutOfRange when no pair fits in the trajectory.
Result<RpeResult> computeRpe(const std::vector<Eigen::Isometry3d>& poses_est,
                             const std::vector<Eigen::Isometry3d>& poses_gt,
                             const std::vector<double>& stamps_s, const RpeOptions& options = {});

/// Settings of a complete trajectory evaluation (the `plumb eval traj` defaults).
struct TrajectoryEvalConfig {
    /// Largest |t_gt - (t_est + offset_s)| for two poses to be associated, in seconds (strict,
    /// as TUM associate.py; 0.02 s is the TUM default).
    double max_difference_s = 0.02;
    /// Added to the estimate's timestamps before association, in seconds.
    double offset_s = 0.0;
    /// ATE options (alignment on by default).
    AteOptions ate;
    /// RPE options (1 frame by default).
    RpeOptions rpe;
};

struct TrajectoryEvaluation {
    size_t num_est = 0;  ///< poses in the estimate
    size_t num_gt = 0;   ///< poses in the ground truth
    /// Associated (index into gt, index into est) pairs, ordered by ground-truth time.
    std::vector<std::pair<size_t, size_t>> pairs;
    AteResult ate;
    /// nullopt when the associated trajectory is too short for the RPE delta.
    std::optional<RpeResult> rpe;
};

/// Associates `est` with `gt` by timestamp (gt first, as TUM evaluate_ate.py), then computes
/// ATE on the positions and RPE on the poses of the associated pairs (ordered by gt time).
/// Errors: empty inputs, no associated pair (message gives both time ranges), ATE errors.
Result<TrajectoryEvaluation> evaluateTrajectories(const io::Trajectory& est,
                                                  const io::Trajectory& gt,
                                                  const TrajectoryEvalConfig& config = {});

/// Convenience: evaluateTrajectories with default options and the given association settings.
Result<TrajectoryEvaluation> evaluateTrajectories(const io::Trajectory& est,
                                                  const io::Trajectory& gt, double max_difference_s,
                                                  double offset_s);

}  // namespace plumb::eval
