// SPDX-License-Identifier: Apache-2.0
#include "backend/calibration/right_angles.hpp"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

namespace plumb::calibration {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

/// A pair of one frame's planes taken to be perpendicular or parallel (Eq. 3).
struct PlanePair {
    Eigen::Vector3d pi1, pi2;  ///< measured plane vectors n / h
    double w1, w2;             ///< the far offset's share at each plane's mean depth
    bool parallel = false;
};

using Params = Eigen::Matrix<double, 6, 1>;  ///< near offset, then far offset

/// The far offset's share of delta at depth z (DisparityOffset::at).
double farShare(double z) {
    return std::clamp(
        (z - DisparityOffset::kNearM) / (DisparityOffset::kFarM - DisparityOffset::kNearM), 0.0,
        1.0);
}

Eigen::Vector3d planeVector(const SegmentPlane& p) { return p.normal / p.distance; }

/// Eq. 3's residuals of one pair at delta, radians to first order: for a perpendicular pair the
/// cosine of its angle (then two zeros), for a parallel one the cross product of the unit
/// normals.
Eigen::Vector3d residual(const PlanePair& p, const Params& x) {
    const Eigen::Vector3d a =
        (p.pi1 - (1.0 - p.w1) * x.head<3>() - p.w1 * x.tail<3>()).normalized();
    const Eigen::Vector3d b =
        (p.pi2 - (1.0 - p.w2) * x.head<3>() - p.w2 * x.tail<3>()).normalized();
    if (p.parallel) return a.cross(b);
    return Eigen::Vector3d(a.dot(b), 0.0, 0.0);
}

std::vector<PlanePair> collectPairs(const std::vector<std::vector<SegmentPlane>>& frames,
                                    const RightAngleConfig& c, size_t* frames_used) {
    const double sin_off = std::sin(c.max_off_deg * kDeg);
    std::vector<PlanePair> pairs;
    *frames_used = 0;
    for (const std::vector<SegmentPlane>& planes : frames) {
        const size_t before = pairs.size();
        for (size_t i = 0; i < planes.size(); ++i) {
            if (planes[i].blocks < static_cast<size_t>(c.min_blocks)) continue;
            for (size_t j = i + 1; j < planes.size(); ++j) {
                if (planes[j].blocks < static_cast<size_t>(c.min_blocks)) continue;
                const double cosine = planes[i].normal.dot(planes[j].normal);
                PlanePair pair{planeVector(planes[i]), planeVector(planes[j]),
                               c.depth_dependent ? farShare(planes[i].mean_depth) : 0.0,
                               c.depth_dependent ? farShare(planes[j].mean_depth) : 0.0, false};
                if (std::abs(cosine) <= sin_off) {
                    pairs.push_back(pair);
                } else if (std::sqrt(std::max(0.0, 1.0 - cosine * cosine)) <= sin_off &&
                           std::abs(std::abs(planes[i].distance) - std::abs(planes[j].distance)) >=
                               c.min_parallel_gap_m) {
                    pair.parallel = true;
                    pairs.push_back(pair);
                }
            }
        }
        if (pairs.size() > before) ++*frames_used;
    }
    return pairs;
}

/// Huber-weighted RMS of the pairs' residuals at delta, degrees.
double rmsDegrees(const std::vector<PlanePair>& pairs, const Params& x, double huber_rad) {
    double cost = 0.0, count = 0.0;
    for (const PlanePair& p : pairs) {
        const double e = residual(p, x).norm();
        const double w = e <= huber_rad ? 1.0 : huber_rad / e;
        cost += w * e * e;
        count += 1.0;
    }
    return count > 0.0 ? std::sqrt(cost / count) / kDeg : 0.0;
}

}  // namespace

void describe(config::Schema& s, RightAngleConfig& c) {
    s.field("enabled", c.enabled,
            "after each planar stage, remove the disparity offset that the angles between each "
            "frame's planes show (walls perpendicular to the floor and to each other)");
    s.field("first_pass", c.first_pass,
            "also after --self-calibrate's first planar stage, of the raw depth (off: only after "
            "the last one)");
    s.field("max_off_deg", c.max_off_deg,
            "two planes of one frame within this of perpendicular (or parallel) are taken to be "
            "exactly so",
            "degrees")
        .range(0.1, 20.0);
    s.field("min_parallel_gap_m", c.min_parallel_gap_m,
            "parallel pairs are used when their distances from the camera differ by at least this",
            "m")
        .min(0.0);
    s.field("min_blocks", c.min_blocks, "planes of fewer blocks are not used").min(3);
    s.field("depth_dependent", c.depth_dependent,
            "estimate the offset at the 1 m and the 3 m bin apart (linear in depth between them) "
            "instead of one for all depths");
    s.field("estimate_uniform", c.estimate_uniform,
            "estimate the offset's uniform part (a depth scale growing with depth) too; off: only "
            "its tilts across the image");
    s.field("huber_deg", c.huber_deg, "Huber threshold on a pair's angle residual", "degrees")
        .positive();
    s.field("iterations", c.iterations, "Gauss-Newton iterations").min(1);
    s.field("min_pairs", c.min_pairs, "fewer perpendicular pairs than this: no estimate").min(1);
    s.field("min_observation", c.min_observation,
            "smallest over largest eigenvalue of the normal equations below this: no estimate")
        .range(0.0, 1.0);
}

Status validate(const RightAngleConfig& c) {
    if (!(c.max_off_deg > 0.0 && c.max_off_deg < 45.0)) {
        return invalidArgument("right angles: max_off_deg must be in (0, 45)");
    }
    if (!(c.min_parallel_gap_m >= 0.0 && c.huber_deg > 0.0)) {
        return invalidArgument("right angles: min_parallel_gap_m >= 0 and huber_deg > 0");
    }
    if (c.min_blocks < 3 || c.iterations < 1 || c.min_pairs < 1) {
        return invalidArgument("right angles: min_blocks >= 3, iterations >= 1, min_pairs >= 1");
    }
    if (!(c.min_observation >= 0.0 && c.min_observation <= 1.0)) {
        return invalidArgument("right angles: min_observation must be in [0, 1]");
    }
    return Status::ok();
}

Result<RightAngleEstimate> estimateRightAngles(const std::vector<std::vector<SegmentPlane>>& frames,
                                               const RightAngleConfig& config) {
    PLUMB_RETURN_IF_ERROR(validate(config));
    RightAngleEstimate out;
    const std::vector<PlanePair> pairs = collectPairs(frames, config, &out.frames);
    for (const PlanePair& p : pairs) ++(p.parallel ? out.parallel : out.perpendicular);
    // Perpendicular pairs carry the estimate; parallel ones (at different distances) only add
    // to it: a scan of parallel planes alone (one wall and the furniture in front of it) may
    // hold no true one among them.
    if (out.perpendicular < static_cast<size_t>(config.min_pairs)) {
        return failedPrecondition(fmt::format(
            "right angles: {} pairs of perpendicular planes in {} frames (at least {}); the "
            "views hold too few walls meeting the floor or each other",
            out.perpendicular, frames.size(), config.min_pairs));
    }
    const double huber = config.huber_deg * kDeg;
    out.rms_before_deg = rmsDegrees(pairs, Params::Zero(), huber);
    // Without depth_dependent every pair's far share is 0: the far offset is unobserved and
    // held at the near one.
    const int unknowns = config.depth_dependent ? 6 : 3;
    Params x = Params::Zero();
    Eigen::MatrixXd h;
    for (int it = 0; it < config.iterations; ++it) {
        h = Eigen::MatrixXd::Zero(unknowns, unknowns);
        Eigen::VectorXd g = Eigen::VectorXd::Zero(unknowns);
        for (const PlanePair& p : pairs) {
            const Eigen::Vector3d r = residual(p, x);
            const double e = r.norm();
            const double w = e <= huber ? 1.0 : huber / e;
            // Central differences: few parameters, smooth residuals.
            Eigen::MatrixXd jac(3, unknowns);
            constexpr double kStep = 1e-6;
            for (int k = 0; k < unknowns; ++k) {
                Params step = Params::Zero();
                step[k] = kStep;
                jac.col(k) = (residual(p, x + step) - residual(p, x - step)) / (2.0 * kStep);
            }
            h.noalias() += w * jac.transpose() * jac;
            g.noalias() += w * jac.transpose() * r;
        }
        if (!config.estimate_uniform) {
            // Hold the uniform components at 0: their rows decoupled, their diagonal at the
            // largest of the others (so that it bounds neither end of the spectrum below).
            double largest = 0.0;
            for (int k = 0; k < unknowns; ++k) {
                if (k % 3 != 2) largest = std::max(largest, h(k, k));
            }
            for (int k = 2; k < unknowns; k += 3) {
                h.row(k).setZero();
                h.col(k).setZero();
                h(k, k) = largest;
                g[k] = 0.0;
            }
        }
        const Eigen::VectorXd change = -h.ldlt().solve(g);
        x.head(unknowns) += change;
        if (!config.depth_dependent) x.tail<3>() = x.head<3>();
        if (change.norm() < 1e-9) break;
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(h);
    const double largest = es.eigenvalues()[unknowns - 1];
    out.observation = largest > 0.0 ? es.eigenvalues()[0] / largest : 0.0;
    if (out.observation < config.min_observation) {
        return failedPrecondition(fmt::format(
            "right angles: the {} pairs leave a direction of the disparity offset unobserved "
            "(eigenvalue ratio {:.2g}, at least {:.2g})",
            pairs.size(), out.observation, config.min_observation));
    }
    out.delta.near = x.head<3>();
    out.delta.far = x.tail<3>();
    out.rms_after_deg = rmsDegrees(pairs, x, huber);
    return out;
}

Eigen::Vector3d DisparityOffset::at(double z) const {
    const double w = farShare(z);
    return (1.0 - w) * near + w * far;
}

DistortionTable removeDisparityOffset(const DistortionTable& table, const DisparityOffset& delta,
                                      const PinholeCamera& camera) {
    const int n = DistortionTable::kCellsPerSide;
    const double sx = camera.width / 640.0, sy = camera.height / 480.0;
    std::vector<std::array<float, 5>> cells(static_cast<size_t>(n) * n);
    for (int cy = 0; cy < n; ++cy) {
        for (int cx = 0; cx < n; ++cx) {
            // The cell's centre on the 640x480 grid (cells of 8 x 6 pixels), in the camera.
            const double x = ((cx + 0.5) * 8.0 * sx - camera.cx) / camera.fx;
            const double y = ((cy + 0.5) * 6.0 * sy - camera.cy) / camera.fy;
            const Eigen::Vector3d ray(x, y, 1.0);
            std::array<float, 5> f = table.cell(cx, cy);
            for (int b = 0; b < DistortionTable::kBins; ++b) {
                if (f[b] <= 0.0F) continue;
                const double offset = delta.at(DistortionTable::binCentreM(b)).dot(ray);
                // z = z_c / (1 - z_c offset) for the depth z_c the table gave, i.e.
                // z = z_c (1 + z offset) in the true depth z at which the table is read.
                f[b] = static_cast<float>(f[b] * (1.0 + DistortionTable::binCentreM(b) * offset));
            }
            cells[static_cast<size_t>(cy) * n + cx] = f;
        }
    }
    return DistortionTable::fromCells(std::move(cells));
}

}  // namespace plumb::calibration
