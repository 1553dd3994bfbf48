// SPDX-License-Identifier: Apache-2.0
#include "common/eval/layout_metrics.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <tuple>

#include "common/geometry/lie.hpp"

namespace plumb::eval {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

/// Angle between two unit vectors in [0, pi], robust near 0 and pi.
double angleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::atan2(a.cross(b).norm(), a.dot(b));
}

Status validate(const Layout& layout, const char* which) {
    if (!lie::isValidPose(layout.T_W_L, 1e-6)) {
        return invalidArgument(fmt::format("{} layout: T_W_L is not a rigid transform", which));
    }
    for (const LayoutPlane& p : layout.planes) {
        if (!p.normal_L.allFinite() || !std::isfinite(p.d_L) ||
            std::abs(p.normal_L.norm() - 1.0) > 1e-6) {
            return invalidArgument(fmt::format(
                "{} layout: plane {} has a non-unit or non-finite normal", which, p.id));
        }
    }
    return Status::ok();
}

/// A ground-truth plane with its centre point, both in the comparison frame.
struct GtPlane {
    const LayoutPlane* source = nullptr;
    HessianPlane plane;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
};

/// Centre of a ground-truth plane in its layout frame: the wall segment midpoint at half the
/// ceiling height; the room polygon's vertex mean on the floor or ceiling; the foot of the
/// perpendicular from the origin when no extent is known.
Eigen::Vector3d centreInLayout(const Layout& layout, const LayoutPlane& p) {
    const Eigen::Vector3d foot = -p.d_L * p.normal_L;
    if (p.kind == LayoutPlaneKind::kWall) {
        if ((p.end_L - p.start_L).norm() > 0.0) {
            const Eigen::Vector2d mid = 0.5 * (p.start_L + p.end_L);
            const double z = layout.ceiling_height_m > 0.0 ? 0.5 * layout.ceiling_height_m : 0.0;
            return Eigen::Vector3d(mid.x(), mid.y(), z);
        }
        return foot;
    }
    if (layout.room_polygon_L.empty()) return foot;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const Eigen::Vector2d& v : layout.room_polygon_L) mean += v;
    mean /= static_cast<double>(layout.room_polygon_L.size());
    // Project the polygon centre onto the plane along z (floor and ceiling are near horizontal).
    const Eigen::Vector3d n = p.normal_L;
    if (std::abs(n.z()) < 1e-6) return foot;
    const double z = -(n.x() * mean.x() + n.y() * mean.y() + p.d_L) / n.z();
    return Eigen::Vector3d(mean.x(), mean.y(), z);
}

PlaneError compare(const GtPlane& gt, int est_id, const HessianPlane& est_in) {
    PlaneError e;
    e.gt_id = gt.source->id;
    e.est_id = est_id;
    HessianPlane est = est_in;
    if (est.normal.dot(gt.plane.normal) < 0.0) {
        est.normal = -est.normal;
        est.d = -est.d;
        e.flipped = true;
    }
    e.estimate = est;
    e.angle_error_deg = angleBetween(est.normal, gt.plane.normal) * kRadToDeg;
    e.offset_error_m = est.d - gt.plane.d;
    e.centre_distance_m = est.signedDistance(gt.centre);
    return e;
}

}  // namespace

Result<LayoutMetrics> evaluateLayout(const Layout& estimate, const Layout& ground_truth,
                                     const LayoutMetricsConfig& config) {
    PLUMB_RETURN_IF_ERROR(validate(estimate, "estimated"));
    PLUMB_RETURN_IF_ERROR(validate(ground_truth, "ground-truth"));
    if (!(config.angle_weight_m_per_rad >= 0.0) || !(config.max_match_angle_deg > 0.0) ||
        !(config.max_match_distance_m > 0.0)) {
        return invalidArgument("layout metrics: weights and gates must be positive");
    }
    // Comparison frame C: T_C_Lgt and T_C_Lest.
    const Eigen::Isometry3d T_C_Lgt =
        config.frame == LayoutFrame::kWorld ? ground_truth.T_W_L : Eigen::Isometry3d::Identity();
    const Eigen::Isometry3d T_C_W = config.frame == LayoutFrame::kWorld
                                        ? Eigen::Isometry3d::Identity()
                                        : ground_truth.T_W_L.inverse();
    const Eigen::Isometry3d T_C_Lest = T_C_W * estimate.T_W_L;

    auto gtPlane = [&](const LayoutPlane& p) {
        GtPlane g;
        g.source = &p;
        g.plane = transformPlane(HessianPlane{p.normal_L, p.d_L}, T_C_Lgt);
        g.centre = T_C_Lgt * centreInLayout(ground_truth, p);
        return g;
    };
    auto estPlane = [&](const LayoutPlane& p) {
        return transformPlane(HessianPlane{p.normal_L, p.d_L}, T_C_Lest);
    };

    LayoutMetrics m;
    m.frame = config.frame;
    const std::vector<const LayoutPlane*> gt_walls = ground_truth.walls();
    const std::vector<const LayoutPlane*> est_walls = estimate.walls();
    m.num_gt_walls = gt_walls.size();
    m.num_est_walls = est_walls.size();

    std::vector<GtPlane> gt_planes;
    for (const LayoutPlane* p : gt_walls) gt_planes.push_back(gtPlane(*p));
    std::vector<HessianPlane> est_planes;
    for (const LayoutPlane* p : est_walls) est_planes.push_back(estPlane(*p));

    // All gated candidate pairs, cheapest first; ties broken by (gt index, est index).
    std::vector<std::tuple<double, size_t, size_t>> candidates;
    for (size_t g = 0; g < gt_planes.size(); ++g) {
        for (size_t e = 0; e < est_planes.size(); ++e) {
            const PlaneError err = compare(gt_planes[g], est_walls[e]->id, est_planes[e]);
            if (err.angle_error_deg > config.max_match_angle_deg ||
                std::abs(err.centre_distance_m) > config.max_match_distance_m) {
                continue;
            }
            const double cost = err.angle_error_deg / kRadToDeg * config.angle_weight_m_per_rad +
                                std::abs(err.centre_distance_m);
            candidates.emplace_back(cost, g, e);
        }
    }
    std::sort(candidates.begin(), candidates.end());
    std::vector<int> match_of_gt(gt_planes.size(), -1);
    std::vector<bool> est_used(est_planes.size(), false);
    for (const auto& [cost, g, e] : candidates) {
        if (match_of_gt[g] >= 0 || est_used[e]) continue;
        match_of_gt[g] = static_cast<int>(e);
        est_used[e] = true;
    }

    std::vector<size_t> matched_gt;  // indices into gt_planes, in GT order
    for (size_t g = 0; g < gt_planes.size(); ++g) {
        if (match_of_gt[g] < 0) {
            m.unmatched_gt_walls.push_back(gt_walls[g]->id);
            continue;
        }
        const auto e = static_cast<size_t>(match_of_gt[g]);
        m.walls.push_back(compare(gt_planes[g], est_walls[e]->id, est_planes[e]));
        matched_gt.push_back(g);
    }
    for (size_t e = 0; e < est_planes.size(); ++e) {
        if (!est_used[e]) m.unmatched_est_walls.push_back(est_walls[e]->id);
    }

    if (!m.walls.empty()) {
        double sum_angle = 0.0, sum_offset = 0.0;
        for (const PlaneError& w : m.walls) {
            sum_angle += w.angle_error_deg;
            sum_offset += std::abs(w.offset_error_m);
            m.max_wall_angle_error_deg = std::max(m.max_wall_angle_error_deg, w.angle_error_deg);
            m.max_abs_wall_offset_error_m =
                std::max(m.max_abs_wall_offset_error_m, std::abs(w.offset_error_m));
        }
        m.mean_wall_angle_error_deg = sum_angle / static_cast<double>(m.walls.size());
        m.mean_abs_wall_offset_error_m = sum_offset / static_cast<double>(m.walls.size());
    }
    for (size_t a = 0; a < m.walls.size(); ++a) {
        for (size_t b = a + 1; b < m.walls.size(); ++b) {
            WallPairAngle pair;
            pair.gt_id_a = m.walls[a].gt_id;
            pair.gt_id_b = m.walls[b].gt_id;
            pair.gt_angle_deg = angleBetween(gt_planes[matched_gt[a]].plane.normal,
                                             gt_planes[matched_gt[b]].plane.normal) *
                                kRadToDeg;
            pair.est_angle_deg =
                angleBetween(m.walls[a].estimate.normal, m.walls[b].estimate.normal) * kRadToDeg;
            pair.error_deg = std::abs(pair.est_angle_deg - pair.gt_angle_deg);
            m.max_wall_pair_angle_error_deg =
                std::max(m.max_wall_pair_angle_error_deg, pair.error_deg);
            m.wall_pairs.push_back(pair);
        }
    }

    for (LayoutPlaneKind kind : {LayoutPlaneKind::kFloor, LayoutPlaneKind::kCeiling}) {
        const LayoutPlane* g = ground_truth.firstOf(kind);
        const LayoutPlane* e = estimate.firstOf(kind);
        if (g == nullptr || e == nullptr) continue;
        const PlaneError err = compare(gtPlane(*g), e->id, estPlane(*e));
        (kind == LayoutPlaneKind::kFloor ? m.floor : m.ceiling) = err;
    }
    if (estimate.ceiling_height_m > 0.0 && ground_truth.ceiling_height_m > 0.0) {
        m.ceiling_height_error_m = estimate.ceiling_height_m - ground_truth.ceiling_height_m;
    }
    return m;
}

}  // namespace plumb::eval
