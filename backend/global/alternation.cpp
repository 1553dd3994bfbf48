// SPDX-License-Identifier: Apache-2.0
#include "backend/global/alternation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>

#include "common/config/config.hpp"
#include "common/core/logging.hpp"

namespace plumb::global {

void describe(config::Schema& s, AlternationConfig& c) {
    s.field("max_outer_iterations", c.max_outer_iterations,
            "maximum outer iterations of Algorithm 1 (layout re-estimations)")
        .min(1);
    s.field("pose_tolerance_rad", c.pose_tolerance_rad,
            "outer loop converged when no fragment rotated more than this in an iteration", "rad")
        .positive();
    s.field("pose_tolerance_m", c.pose_tolerance_m,
            "outer loop converged when no fragment moved more than this in an iteration", "m")
        .positive();
    s.field("energy_tolerance", c.energy_tolerance,
            "outer loop converged when the layout is unchanged, the annealing done, and E_R fell "
            "by less than this fraction over the iteration (0 = poses and layout only)")
        .min(0.0);
    s.field("layout_angle_tolerance_deg", c.layout_angle_tolerance_deg,
            "layout unchanged when every plane normal moved less than this", "deg")
        .positive();
    s.field("layout_offset_tolerance_m", c.layout_offset_tolerance_m,
            "layout unchanged when every plane offset moved less than this", "m")
        .positive();
    s.field("shrink_factor", c.shrink_factor,
            "per outer iteration the correspondence distances and support margins are "
            "multiplied by this, down to the final values")
        .range(0.0, 1.0);
    s.field("final_frag_max_distance_m", c.final_frag_max_distance_m,
            "smallest fragment-fragment correspondence distance reached by the annealing", "m")
        .positive();
    s.field("final_layout_max_distance_m", c.final_layout_max_distance_m,
            "smallest point-to-layout distance reached by the annealing", "m")
        .positive();
    s.field("final_margin_m", c.final_margin_m,
            "smallest wall / floor support margin reached by the annealing", "m")
        .min(0.0);
    s.field("monotone_layout_steps", c.monotone_layout_steps,
            "keep a re-estimated layout only when it does not raise E_R at the current poses; "
            "otherwise stop with the previous layout");
    s.section("registration", c.global, "layout-constrained global registration (one outer step)");
}

bool compareLayouts(const Layout& a, const Layout& b, double* max_angle_deg, double* max_offset_m) {
    *max_angle_deg = 0.0;
    *max_offset_m = 0.0;
    bool same = true;
    for (LayoutPlaneKind kind :
         {LayoutPlaneKind::kFloor, LayoutPlaneKind::kCeiling, LayoutPlaneKind::kWall}) {
        std::vector<HessianPlane> pa, pb;
        for (const LayoutPlane& p : a.planes) {
            if (p.kind == kind) pa.push_back(planeInWorld(a, p));
        }
        for (const LayoutPlane& p : b.planes) {
            if (p.kind == kind) pb.push_back(planeInWorld(b, p));
        }
        if (pa.size() != pb.size()) same = false;
        for (const HessianPlane& p : pa) {
            double best_angle = 180.0;
            double best_offset = 0.0;
            for (const HessianPlane& q : pb) {
                // atan2 stays accurate for nearly parallel normals (acos does not).
                const double angle =
                    std::atan2(p.normal.cross(q.normal).norm(), p.normal.dot(q.normal)) * 180.0 /
                    M_PI;
                if (angle < best_angle) {
                    best_angle = angle;
                    best_offset = std::abs(p.d - q.d);
                }
            }
            if (pb.empty()) continue;
            *max_angle_deg = std::max(*max_angle_deg, best_angle);
            *max_offset_m = std::max(*max_offset_m, best_offset);
        }
    }
    return same;
}

namespace {

/// The annealed distances and margins of two outer iterations are the same.
bool sameDistances(const GlobalConfig& a, const GlobalConfig& b) {
    return a.frag_max_distance_m == b.frag_max_distance_m &&
           a.layout_max_distance_m == b.layout_max_distance_m &&
           a.wall_margin_m == b.wall_margin_m && a.floor_margin_m == b.floor_margin_m;
}

}  // namespace

Result<AlternationResult> alternate(const std::vector<GlobalCloud>& clouds,
                                    const std::vector<Eigen::Isometry3d>& initial_T_W_F,
                                    const std::vector<PairPrior>& priors,
                                    const LayoutEstimator& estimate_layout,
                                    const AlternationConfig& config,
                                    const ProgressCallback& progress) {
    {
        const Status s = config::validate(config);
        if (!s.isOk()) return invalidArgument("alternation: " + s.message());
    }
    if (!estimate_layout) return invalidArgument("alternation: no layout estimator given");
    AlternationResult result;
    result.T_W_F = initial_T_W_F;
    result.stop_reason = "max_outer_iterations";
    Layout previous;
    GlobalConfig previous_gc;
    // Each registration's last correspondences start the next one's searches (same results).
    MatchHints hints;
    for (int outer = 0; outer < config.max_outer_iterations; ++outer) {
        OuterIteration rec;
        rec.iteration = outer;
        // Layout step (Algorithm 1: layout from the current poses).
        Result<Layout> layout = estimate_layout(result.T_W_F);
        if (!layout.isOk()) {
            return Status(layout.status().code(),
                          fmt::format("alternation: layout estimation in outer iteration {}: {}",
                                      outer, layout.status().message()));
        }
        rec.layout = std::move(layout).value();
        if (outer > 0) {
            rec.layout_same_structure =
                compareLayouts(previous, rec.layout, &rec.layout_change_deg, &rec.layout_change_m);
        }
        // Registration step with annealed distances.
        GlobalConfig gc = config.global;
        const double shrink = std::pow(config.shrink_factor, outer);
        gc.frag_max_distance_m =
            std::max(config.final_frag_max_distance_m, config.global.frag_max_distance_m * shrink);
        gc.layout_max_distance_m = std::max(config.final_layout_max_distance_m,
                                            config.global.layout_max_distance_m * shrink);
        gc.wall_margin_m = std::max(std::min(config.final_margin_m, config.global.wall_margin_m),
                                    config.global.wall_margin_m * shrink);
        gc.floor_margin_m = std::max(std::min(config.final_margin_m, config.global.floor_margin_m),
                                     config.global.floor_margin_m * shrink);
        auto failed = [outer](const Status& st) {
            return Status(st.code(), fmt::format("alternation: registration in outer iteration "
                                                 "{}: {}",
                                                 outer, st.message()));
        };
        std::optional<GlobalResult> step;
        if (outer > 0 && config.monotone_layout_steps) {
            // Block-coordinate descent: the layout step must not raise E_R at these poses.
            Result<LayoutStepOutcome> o = refinePosesAfterLayoutStep(
                clouds, result.T_W_F, priors, previous, rec.layout, gc, &hints);
            if (!o.isOk()) return failed(o.status());
            rec.energy_previous_layout = o->energies[0].total;
            rec.energy_new_layout = o->energies[1].total;
            if (!o->step) {
                result.stop_reason = "layout step raised the energy";
                break;
            }
            step = std::move(o->step);
        } else {
            Result<GlobalResult> r =
                refinePoses(clouds, result.T_W_F, priors, rec.layout, gc, &hints);
            if (!r.isOk()) return failed(r.status());
            step = std::move(r).value();
        }
        rec.before = step->initial;
        rec.after = step->final;
        rec.inner = step->iterations;
        rec.inner_iterations = static_cast<int>(step->iterations.size());
        for (size_t i = 0; i < result.T_W_F.size(); ++i) {
            const Eigen::Isometry3d d = result.T_W_F[i].inverse() * step->T_W_F[i];
            rec.max_pose_change_rad = std::max(rec.max_pose_change_rad, lie::rotationAngle(d));
            rec.max_pose_change_m =
                std::max(rec.max_pose_change_m,
                         (result.T_W_F[i].translation() - step->T_W_F[i].translation()).norm());
        }
        result.T_W_F = step->T_W_F;
        const bool layout_settled = outer > 0 && rec.layout_same_structure &&
                                    rec.layout_change_deg < config.layout_angle_tolerance_deg &&
                                    rec.layout_change_m < config.layout_offset_tolerance_m;
        const bool poses_settled = rec.max_pose_change_rad < config.pose_tolerance_rad &&
                                   rec.max_pose_change_m < config.pose_tolerance_m;
        const bool energy_settled =
            config.energy_tolerance > 0.0 && outer > 0 && sameDistances(gc, previous_gc) &&
            result.iterations.back().after.total - rec.after.total <
                config.energy_tolerance * result.iterations.back().after.total;
        log::debug(
            "alternation: outer iteration {}: E {:.4e} -> {:.4e} in {} inner iterations; poses "
            "moved up to {:.3f} mm and {:.4f} deg, the layout {:.3f} mm and {:.3f} deg",
            outer, rec.before.total, rec.after.total, rec.inner_iterations,
            rec.max_pose_change_m * 1e3, rec.max_pose_change_rad * 180.0 / M_PI,
            rec.layout_change_m * 1e3, rec.layout_change_deg);
        previous = rec.layout;
        previous_gc = gc;
        result.layout = rec.layout;
        result.iterations.push_back(std::move(rec));
        report(progress);
        if (layout_settled && poses_settled) {
            result.converged = true;
            result.stop_reason = "converged";
            break;
        }
        if (layout_settled && energy_settled) {
            result.converged = true;
            result.stop_reason = "energy settled";
            break;
        }
    }
    return result;
}

Result<AlternationResult> alternate(const std::vector<Fragment>& fragments,
                                    const std::vector<Eigen::Isometry3d>& initial_T_W_F,
                                    const std::vector<PairPrior>& priors,
                                    const LayoutEstimator& estimate_layout,
                                    const AlternationConfig& config,
                                    const ProgressCallback& progress) {
    Result<std::vector<GlobalCloud>> clouds = prepareClouds(fragments, config.global);
    if (!clouds.isOk()) return clouds.status();
    return alternate(clouds.value(), initial_T_W_F, priors, estimate_layout, config, progress);
}

}  // namespace plumb::global
