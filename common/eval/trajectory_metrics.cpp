// SPDX-License-Identifier: Apache-2.0
#include "common/eval/trajectory_metrics.hpp"

#include <fmt/format.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "common/geometry/lie.hpp"

namespace plumb::eval {
namespace {

/// Slack when comparing a time-delta target with the last stamp (stamps are often ~1e9 s,
/// where one ulp is ~2e-7 s).
constexpr double kStampSlackS = 1e-6;

struct Stats {
    double rmse = 0.0;
    double mean = 0.0;
    double median = 0.0;
    double max = 0.0;
    double min = 0.0;
};

/// RMSE, mean, median (numpy convention: mean of the middle two for an even count), max, min.
Stats statistics(const std::vector<double>& values) {
    PLUMB_CHECK(!values.empty()) << "statistics of no values";
    Stats s;
    double sum = 0.0, sum_sq = 0.0;
    for (double v : values) {
        sum += v;
        sum_sq += v * v;
    }
    const double n = static_cast<double>(values.size());
    s.rmse = std::sqrt(sum_sq / n);
    s.mean = sum / n;
    std::vector<double> sorted = values;
    std::sort(sorted.begin(), sorted.end());
    const size_t mid = sorted.size() / 2;
    s.median = sorted.size() % 2 == 1 ? sorted[mid] : 0.5 * (sorted[mid - 1] + sorted[mid]);
    s.min = sorted.front();
    s.max = sorted.back();
    return s;
}

Status checkFinite(const std::vector<Eigen::Vector3d>& points, const char* which) {
    for (size_t k = 0; k < points.size(); ++k) {
        if (!points[k].allFinite()) {
            return invalidArgument(fmt::format("position {} of the {} is not finite", k, which));
        }
    }
    return Status::ok();
}

}  // namespace

Eigen::Isometry3d alignRigid(const std::vector<Eigen::Vector3d>& positions_est,
                             const std::vector<Eigen::Vector3d>& positions_gt) {
    PLUMB_CHECK(positions_est.size() == positions_gt.size())
        << positions_est.size() << " estimated vs " << positions_gt.size() << " gt positions";
    PLUMB_CHECK(!positions_est.empty()) << "alignment of no points";
    const double n = static_cast<double>(positions_est.size());
    Eigen::Vector3d mean_est = Eigen::Vector3d::Zero(), mean_gt = Eigen::Vector3d::Zero();
    for (size_t k = 0; k < positions_est.size(); ++k) {
        mean_est += positions_est[k];
        mean_gt += positions_gt[k];
    }
    mean_est /= n;
    mean_gt /= n;
    // W = sum m_c d_c^T with m = estimate, d = ground truth, both centred (§6.2).
    Eigen::Matrix3d W = Eigen::Matrix3d::Zero();
    for (size_t k = 0; k < positions_est.size(); ++k) {
        W += (positions_est[k] - mean_est) * (positions_gt[k] - mean_gt).transpose();
    }
    // SVD W^T = U S V^T; R = U diag(1, 1, det(U) det(V)) V^T maximises tr(R^T W^T) over
    // rotations (the diag term turns the best reflection into the best rotation).
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(W.transpose(),
                                                Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Matrix3d& U = svd.matrixU();
    const Eigen::Matrix3d& V = svd.matrixV();
    Eigen::Vector3d d(1.0, 1.0, (U.determinant() * V.determinant()) < 0.0 ? -1.0 : 1.0);
    Eigen::Isometry3d T_gt_est = Eigen::Isometry3d::Identity();
    T_gt_est.linear() = U * d.asDiagonal() * V.transpose();
    T_gt_est.translation() = mean_gt - T_gt_est.linear() * mean_est;  // t = mean(d) - R mean(m)
    return T_gt_est;
}

Result<AteResult> computeAte(const std::vector<Eigen::Vector3d>& positions_est,
                             const std::vector<Eigen::Vector3d>& positions_gt,
                             const AteOptions& options) {
    if (positions_est.size() != positions_gt.size()) {
        return invalidArgument(fmt::format("ATE needs paired positions: {} estimated vs {} gt",
                                           positions_est.size(), positions_gt.size()));
    }
    if (positions_est.empty()) return invalidArgument("ATE of an empty trajectory");
    if (options.align && positions_est.size() < 3) {
        return invalidArgument(fmt::format(
            "ATE with alignment needs at least 3 position pairs, got {}", positions_est.size()));
    }
    PLUMB_RETURN_IF_ERROR(checkFinite(positions_est, "estimate"));
    PLUMB_RETURN_IF_ERROR(checkFinite(positions_gt, "ground truth"));

    AteResult result;
    result.num_pairs = positions_est.size();
    if (options.align) result.T_gt_est = alignRigid(positions_est, positions_gt);
    result.errors_m.resize(positions_est.size());
    for (size_t k = 0; k < positions_est.size(); ++k) {
        result.errors_m[k] = (result.T_gt_est * positions_est[k] - positions_gt[k]).norm();
    }
    const Stats s = statistics(result.errors_m);
    result.rmse_m = s.rmse;
    result.mean_m = s.mean;
    result.median_m = s.median;
    result.max_m = s.max;
    result.min_m = s.min;
    return result;
}

Result<RpeResult> computeRpe(const std::vector<Eigen::Isometry3d>& poses_est,
                             const std::vector<Eigen::Isometry3d>& poses_gt,
                             const std::vector<double>& stamps_s, const RpeOptions& options) {
    const size_t n = poses_est.size();
    if (poses_gt.size() != n) {
        return invalidArgument(
            fmt::format("RPE needs paired poses: {} estimated vs {} gt", n, poses_gt.size()));
    }
    const bool by_time = options.delta_unit == DeltaUnit::kSeconds;
    if ((by_time || !stamps_s.empty()) && stamps_s.size() != n) {
        return invalidArgument(fmt::format("RPE has {} poses but {} stamps", n, stamps_s.size()));
    }
    if (!(options.delta > 0.0) || !std::isfinite(options.delta)) {
        return invalidArgument(fmt::format("RPE delta must be positive, got {}", options.delta));
    }
    const long long step = std::llround(options.delta);
    if (!by_time && std::abs(options.delta - static_cast<double>(step)) > 1e-9) {
        return invalidArgument(
            fmt::format("RPE delta in frames must be an integer, got {}", options.delta));
    }
    if (by_time && !std::is_sorted(stamps_s.begin(), stamps_s.end())) {
        return invalidArgument("RPE with a time delta needs non-decreasing stamps");
    }
    for (size_t k = 0; k < n; ++k) {
        if (!lie::isValidPose(poses_est[k], 1e-6) || !lie::isValidPose(poses_gt[k], 1e-6)) {
            return invalidArgument(
                fmt::format("RPE pose pair {} is not a finite rigid transform", k));
        }
    }

    RpeResult result;
    for (size_t i = 0; i < n; ++i) {
        size_t j = 0;
        if (by_time) {
            const double target = stamps_s[i] + options.delta;
            // Past the end (1 us slack for rounding of large stamps): every later i too.
            if (target > stamps_s.back() + kStampSlackS) break;
            const auto it = std::lower_bound(stamps_s.begin(), stamps_s.end(), target);
            j = static_cast<size_t>(it - stamps_s.begin());
            // The closest stamp to the target (evaluate_rpe.py find_closest_index).
            if (j > 0 && target - stamps_s[j - 1] <= stamps_s[j] - target) --j;
            if (j <= i) continue;
        } else {
            j = i + static_cast<size_t>(step);
            if (j >= n) break;
        }
        // evaluate_rpe.py: error = ominus(ominus(E_j, E_i), ominus(G_j, G_i)), ominus(a, b) =
        // a^-1 b, i.e. E = (E_j^-1 E_i)^-1 (G_j^-1 G_i).
        const Eigen::Isometry3d motion_est = poses_est[j].inverse() * poses_est[i];
        const Eigen::Isometry3d motion_gt = poses_gt[j].inverse() * poses_gt[i];
        const Eigen::Isometry3d error = motion_est.inverse() * motion_gt;
        result.trans_errors_m.push_back(error.translation().norm());
        result.rot_errors_rad.push_back(lie::rotationAngle(error));
    }
    if (result.trans_errors_m.empty()) {
        return outOfRange(
            fmt::format("RPE: no pose pair spans a delta of {} {} in a trajectory of {} poses",
                        options.delta, by_time ? "s" : "frame(s)", n));
    }
    result.num_pairs = result.trans_errors_m.size();
    const Stats t = statistics(result.trans_errors_m);
    const Stats r = statistics(result.rot_errors_rad);
    result.trans_rmse_m = t.rmse;
    result.trans_mean_m = t.mean;
    result.trans_median_m = t.median;
    result.trans_max_m = t.max;
    result.rot_rmse_rad = r.rmse;
    result.rot_mean_rad = r.mean;
    result.rot_median_rad = r.median;
    result.rot_max_rad = r.max;
    return result;
}

Result<TrajectoryEvaluation> evaluateTrajectories(const io::Trajectory& est,
                                                  const io::Trajectory& gt,
                                                  const TrajectoryEvalConfig& config) {
    if (est.empty()) return invalidArgument("the estimated trajectory is empty");
    if (gt.empty()) return invalidArgument("the ground-truth trajectory is empty");
    std::vector<double> stamps_est(est.size()), stamps_gt(gt.size());
    for (size_t k = 0; k < est.size(); ++k) stamps_est[k] = est[k].timestamp_s;
    for (size_t k = 0; k < gt.size(); ++k) stamps_gt[k] = gt[k].timestamp_s;

    TrajectoryEvaluation evaluation;
    evaluation.num_est = est.size();
    evaluation.num_gt = gt.size();
    // Ground truth first and the offset on the estimate, as evaluate_ate.py.
    evaluation.pairs =
        io::associate(stamps_gt, stamps_est, config.max_difference_s, config.offset_s);
    if (evaluation.pairs.empty()) {
        const auto [min_e, max_e] = std::minmax_element(stamps_est.begin(), stamps_est.end());
        const auto [min_g, max_g] = std::minmax_element(stamps_gt.begin(), stamps_gt.end());
        return invalidArgument(fmt::format(
            "no estimated pose is within {} s of a ground-truth pose (estimate stamps [{}, {}] "
            "with offset {} s, ground truth [{}, {}]); check the offset, the maximum difference "
            "and that both files use the same time unit",
            config.max_difference_s, *min_e, *max_e, config.offset_s, *min_g, *max_g));
    }
    std::stable_sort(
        evaluation.pairs.begin(), evaluation.pairs.end(),
        [&](const auto& a, const auto& b) { return stamps_gt[a.first] < stamps_gt[b.first]; });

    std::vector<Eigen::Vector3d> positions_est, positions_gt;
    std::vector<Eigen::Isometry3d> poses_est, poses_gt;
    std::vector<double> stamps;
    for (const auto& [g, e] : evaluation.pairs) {
        positions_est.push_back(est[e].T_W_C.translation());
        positions_gt.push_back(gt[g].T_W_C.translation());
        poses_est.push_back(est[e].T_W_C);
        poses_gt.push_back(gt[g].T_W_C);
        stamps.push_back(stamps_gt[g]);
    }
    Result<AteResult> ate = computeAte(positions_est, positions_gt, config.ate);
    if (!ate.isOk()) return ate.status();
    evaluation.ate = std::move(ate).value();

    Result<RpeResult> rpe = computeRpe(poses_est, poses_gt, stamps, config.rpe);
    if (rpe.isOk()) {
        evaluation.rpe = std::move(rpe).value();
    } else if (rpe.status().code() != StatusCode::kOutOfRange) {
        return rpe.status();
    }
    return evaluation;
}

Result<TrajectoryEvaluation> evaluateTrajectories(const io::Trajectory& est,
                                                  const io::Trajectory& gt, double max_difference_s,
                                                  double offset_s) {
    TrajectoryEvalConfig config;
    config.max_difference_s = max_difference_s;
    config.offset_s = offset_s;
    return evaluateTrajectories(est, gt, config);
}

}  // namespace plumb::eval
