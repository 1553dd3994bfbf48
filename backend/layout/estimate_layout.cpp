// SPDX-License-Identifier: Apache-2.0
#include "backend/layout/estimate_layout.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "backend/layout/plane_fit.hpp"
#include "backend/layout/tlinkage.hpp"
#include "common/config/config.hpp"
#include "common/config/schema.hpp"
#include "common/core/timing.hpp"
#include "common/geometry/polygon.hpp"

namespace plumb::layout {

void describe(config::Schema& s, LayoutConfig& c) {
    s.field("tau_m", c.tau_m, "second T-linkage inlier scale", "m").positive().max(1.0);
    s.field("cutoff_factor", c.cutoff_factor, "preferences vanish beyond cutoff_factor * tau")
        .positive();
    s.field("max_group_angle_deg", c.max_group_angle_deg,
            "groups whose planes differ by more never share a dominant plane", "deg")
        .range(0.0, 90.0);
    s.field("max_group_points", c.max_group_points, "points per group in residuals and fits")
        .min(3);
    s.field("min_dominant_area_m2", c.min_dominant_area_m2,
            "dominant planes with less occupied area are ignored", "m^2")
        .min(0.0);
    s.field("grid_cell_m", c.grid_cell_m, "occupancy grid cell size", "m").positive().max(1.0);
    s.field("min_cell_points", c.min_cell_points, "points for an occupied base-grid cell").min(1);
    s.field("closing_kernel_cells", c.closing_kernel_cells,
            "morphological closing kernel diameter (0 = none)", "cells")
        .range(0, 51);
    s.field("base_min_one_sided", c.base_min_one_sided,
            "base plane: fraction of points on its room side")
        .range(0.0, 1.0);
    s.field("base_side_margin_m", c.base_side_margin_m,
            "base plane: points closer than this do not count for the side test", "m")
        .min(0.0);
    s.field("camera_up_C", c.camera_up_C,
            "up direction of an upright camera in the camera frame (0 = no gravity hint)");
    s.field("base_max_tilt_deg", c.base_max_tilt_deg,
            "with the hint: base-plane candidates within this angle of horizontal", "deg")
        .range(0.0, 90.0);
    s.field("tau1", c.tau1, "Eq. 6: walls need |n . n_base| below this").range(0.0, 1.0);
    s.field("tau2_m", c.tau2_m, "Eq. 7: walls need a mean boundary distance below this", "m")
        .positive();
    s.field("min_wall_area_m2", c.min_wall_area_m2, "walls with less occupied area are dropped",
            "m^2")
        .min(0.0);
    s.field("wall_top_margin_m", c.wall_top_margin_m, "walls must reach within this of the ceiling",
            "m")
        .positive();
    s.field("wall_top_seen_fraction", c.wall_top_seen_fraction,
            "a plane short of the ceiling is rejected only when lines of sight pass over its top "
            "along at least this fraction of its extent (0: always rejected)")
        .range(0.0, 1.0);
    s.field("wall_top_seen_margin_m", c.wall_top_seen_margin_m,
            "lines of sight count as over a plane's top when they pass this far above it, to "
            "points this far beyond it",
            "m")
        .positive();
    s.field("wall_top_unseen_min_length_m", c.wall_top_unseen_min_length_m,
            "a plane short of the ceiling and narrower than this is rejected whatever the lines "
            "of sight show",
            "m")
        .min(0.0);
    s.field("min_wall_height_m", c.min_wall_height_m,
            "without a ceiling, walls must span this height", "m")
        .positive();
    s.field("wall_merge_angle_deg", c.wall_merge_angle_deg, "wall merge: maximum angle", "deg")
        .range(0.0, 90.0);
    s.field("wall_merge_offset_m", c.wall_merge_offset_m, "wall merge: maximum offset", "m")
        .min(0.0);
    s.field("opposite_max_angle_deg", c.opposite_max_angle_deg,
            "opposite plane: maximum angle to the base", "deg")
        .range(0.0, 90.0);
    s.field("min_room_height_m", c.min_room_height_m,
            "opposite plane: minimum distance from the base", "m")
        .positive();
    s.field("snap_angle_deg", c.snap_angle_deg,
            "weak Manhattan: snap walls within this angle of a multiple of 90 deg", "deg")
        .range(0.0, 45.0);
    s.field("refit_band_m", c.refit_band_m, "offset re-estimation band", "m").positive();
    s.field("min_contour_run_cells", c.min_contour_run_cells,
            "room polygon: ignore shorter contour runs", "cells")
        .min(1);
    s.field("path_occupancy_radius_m", c.path_occupancy_radius_m,
            "base-grid cells this close to a camera position are occupied (0 = none)", "m")
        .range(0.0, 2.0);
    s.field("free_space_rays_per_fragment", c.free_space_rays_per_fragment,
            "lines of sight drawn into the base grid per fragment (0 = none)")
        .min(0);
    s.field("max_camera_behind_fraction", c.max_camera_behind_fraction,
            "walls with more of the camera positions in their extent behind them are rejected")
        .range(0.0, 1.0);
    s.field("camera_behind_margin_m", c.camera_behind_margin_m,
            "camera positions closer than this to a wall count on neither side", "m")
        .min(0.0);
    s.field("wall_piece_gap_m", c.wall_piece_gap_m,
            "rule a, the top test and the room polygon look along the pieces of a wall its points "
            "cover, split at gaps wider than this",
            "m")
        .positive();
    s.field("wall_split_min_edge_m", c.wall_split_min_edge_m,
            "a plane the room polygon follows along several edges this long is one wall per edge "
            "(0 = one wall per plane)",
            "m")
        .min(0.0);
    s.field("stacked_wall_angle_deg", c.stacked_wall_angle_deg,
            "stacked walls: maximum angle between the two", "deg")
        .range(0.0, 45.0);
    s.field("stacked_wall_max_gap_m", c.stacked_wall_max_gap_m,
            "the inner of two same-facing parallel walls this close is rejected (0 = never)", "m")
        .min(0.0);
}

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

struct Group {
    int fragment = 0;
    int label = 0;
    Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
    double d = 0.0;
    std::vector<Eigen::Vector3d> all;     // every labelled point, world
    std::vector<Eigen::Vector3d> capped;  // a stride subsample of at most max_group_points
};

/// A plane with the points that support it (world frame).
struct SupportedPlane {
    int id = 0;
    Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
    double d = 0.0;
    double area = 0.0;
    std::vector<int> groups;
    std::vector<const Eigen::Vector3d*> all;
    std::vector<const Eigen::Vector3d*> capped;
    double rms = 0.0;
};

/// Two unit vectors spanning the plane perpendicular to n.
void planeBasis(const Eigen::Vector3d& n, Eigen::Vector3d* e1, Eigen::Vector3d* e2) {
    Eigen::Index axis;
    n.cwiseAbs().minCoeff(&axis);
    Eigen::Vector3d a = Eigen::Vector3d::Zero();
    a(axis) = 1.0;
    *e1 = (a - a.dot(n) * n).normalized();
    *e2 = n.cross(*e1);
}

/// Occupied area of points projected into the plane's own 2-D grid (reference §4.7).
double occupiedArea(const SupportedPlane& p, double cell) {
    Eigen::Vector3d e1, e2;
    planeBasis(p.n, &e1, &e2);
    std::vector<int64_t> keys;
    keys.reserve(p.all.size());
    for (const Eigen::Vector3d* x : p.all) {
        const auto u = static_cast<int64_t>(std::floor(e1.dot(*x) / cell));
        const auto v = static_cast<int64_t>(std::floor(e2.dot(*x) / cell));
        keys.push_back((u << 32) ^ (v & 0xFFFFFFFF));
    }
    std::sort(keys.begin(), keys.end());
    const auto cells = std::unique(keys.begin(), keys.end()) - keys.begin();
    return static_cast<double>(cells) * cell * cell;
}

/// Least-squares refit with one trimming pass (points within `band` of the first fit).
void refitPlane(SupportedPlane* p, double band) {
    PlaneMoments m;
    for (const Eigen::Vector3d* x : p->capped) m.add(*x);
    PlaneFitResult f = m.fit();
    if (!f.valid) return;
    PlaneMoments trimmed;
    for (const Eigen::Vector3d* x : p->capped) {
        if (std::abs(f.normal.dot(*x) + f.d) <= band) trimmed.add(*x);
    }
    const PlaneFitResult g = trimmed.fit();
    if (g.valid) f = g;
    const Eigen::Vector3d n = f.normal.dot(p->n) < 0 ? -f.normal : f.normal;
    p->n = n;
    p->d = -n.dot(f.centroid);
    p->rms = f.rms_m;
}

/// Offset for a fixed normal over the points within `band` of the current plane.
double refitOffset(const SupportedPlane& p, const Eigen::Vector3d& n, double band) {
    PlaneMoments m;
    for (const Eigen::Vector3d* x : p.capped) {
        if (std::abs(p.n.dot(*x) + p.d) <= band) m.add(*x);
    }
    if (m.count() == 0) return p.d;
    return m.offsetFor(n);
}

bool isRigid(const Eigen::Isometry3d& T) {
    if (!T.matrix().allFinite()) return false;
    const Eigen::Matrix3d R = T.linear();
    return (R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-6 &&
           std::abs(R.determinant() - 1.0) < 1e-6;
}

struct Line2 {
    Eigen::Vector2d n;  // unit
    double d;           // n.x + d = 0
};

bool intersect(const Line2& a, const Line2& b, Eigen::Vector2d* x) {
    const double det = a.n.x() * b.n.y() - a.n.y() * b.n.x();
    if (std::abs(det) < std::sin(10.0 * kDeg)) return false;
    *x = Eigen::Vector2d((-a.d * b.n.y() + b.d * a.n.y()) / det,
                         (-a.n.x() * b.d + b.n.x() * a.d) / det);
    return true;
}

/// Camera positions in W: every tracked frame's (T_W_F * T_F_C), a fragment's origin when it
/// lists no frames.
std::vector<Eigen::Vector3d> cameraPositions(const std::vector<Fragment>& fragments,
                                             const std::vector<Eigen::Isometry3d>& T_W_F) {
    std::vector<Eigen::Vector3d> out;
    for (size_t i = 0; i < fragments.size(); ++i) {
        if (fragments[i].frames.empty()) {
            out.push_back(T_W_F[i].translation());
            continue;
        }
        for (const FragmentFrame& f : fragments[i].frames) {
            if (f.tracking_ok && f.T_F_C.matrix().allFinite()) {
                out.push_back(T_W_F[i] * f.T_F_C.translation());
            }
        }
    }
    return out;
}

/// Where a fragment was seen from: the camera position of its middle tracked frame in W (its
/// origin when it lists no tracked frame).
Eigen::Vector3d fragmentViewpoint(const Fragment& fragment, const Eigen::Isometry3d& T_W_F) {
    std::vector<const FragmentFrame*> tracked;
    for (const FragmentFrame& f : fragment.frames) {
        if (f.tracking_ok && f.T_F_C.matrix().allFinite()) tracked.push_back(&f);
    }
    if (tracked.empty()) return T_W_F.translation();
    return T_W_F * tracked[tracked.size() / 2]->T_F_C.translation();
}

// ---- The steps of estimateLayout, in the order of the header's list ----

/// Step 1's output: the labelled point groups and every sample point, in the world frame.
struct WorldPoints {
    std::vector<Group> groups;
    std::vector<Eigen::Vector3d> all;  ///< every sample point of every fragment
    /// Fragment i's points are all[begin[i] .. begin[i + 1]).
    std::vector<size_t> begin;
};

/// Step 1 (reference §4.6): every labelled point group (fragment i, plane l) of at least 3
/// points and its plane go to the world frame by T_W_F[i].
WorldPoints groupsInWorld(const std::vector<FragmentPlanes>& planes,
                          const std::vector<Eigen::Isometry3d>& T_W_F, const LayoutConfig& config) {
    WorldPoints w;
    for (size_t i = 0; i < planes.size(); ++i) {
        w.begin.push_back(w.all.size());
        const FragmentPlanes& fp = planes[i];
        const Eigen::Isometry3d& T = T_W_F[i];
        std::vector<std::vector<Eigen::Vector3d>> by_label(fp.planes.size());
        for (size_t k = 0; k < fp.sample_F.size(); ++k) {
            const Eigen::Vector3d p = T * fp.sample_F.points[k].cast<double>();
            w.all.push_back(p);
            const int l = fp.labels[k];
            if (l >= 0 && l < static_cast<int>(fp.planes.size())) by_label[l].push_back(p);
        }
        for (size_t l = 0; l < fp.planes.size(); ++l) {
            if (by_label[l].size() < 3) continue;
            Group g;
            g.fragment = static_cast<int>(i);
            g.label = static_cast<int>(l);
            g.n = T.linear() * fp.planes[l].normal_F;
            g.d = fp.planes[l].d_F - g.n.dot(T.translation());
            g.all = std::move(by_label[l]);
            const size_t stride =
                (g.all.size() + config.max_group_points - 1) / config.max_group_points;
            for (size_t k = 0; k < g.all.size(); k += stride) g.capped.push_back(g.all[k]);
            w.groups.push_back(std::move(g));
        }
    }
    w.begin.push_back(w.all.size());
    return w;
}

/// Step 2 (reference §4.6): the second T-linkage, items = the groups, hypotheses = the groups'
/// planes, residual = mean |n.p + d| of a group's points (infinite beyond max_group_angle_deg).
/// Each cluster becomes a dominant plane refitted to its groups' points, kept when its occupied
/// area reaches min_dominant_area_m2; sorted by area, largest first, id = position.
std::vector<SupportedPlane> dominantPlanes(const std::vector<Group>& groups,
                                           const std::vector<Fragment>& fragments,
                                           const LayoutConfig& config, LayoutDiagnostics* diag) {
    const int num_groups = static_cast<int>(groups.size());
    const double cos_group = std::cos(config.max_group_angle_deg * kDeg);
    std::vector<PreferenceVector> prefs(num_groups);
    for (int g = 0; g < num_groups; ++g) {
        prefs[g] = preferencesFromResiduals(
            num_groups,
            [&](int h) {
                if (std::abs(groups[h].n.dot(groups[g].n)) < cos_group) return -1.0;
                double s = 0.0;
                for (const Eigen::Vector3d& x : groups[g].capped) {
                    s += std::abs(groups[h].n.dot(x) + groups[h].d);
                }
                return s / static_cast<double>(groups[g].capped.size());
            },
            config.tau_m, config.cutoff_factor);
    }
    const TLinkageResult tl = tLinkage(prefs);
    diag->num_clusters = tl.num_clusters;
    std::vector<SupportedPlane> dominant;
    for (const std::vector<int>& cl : tl.members) {
        SupportedPlane sp;
        Eigen::Vector3d nsum = Eigen::Vector3d::Zero();
        for (int g : cl) {
            sp.groups.push_back(g);
            nsum += static_cast<double>(groups[g].all.size()) * groups[g].n;
            for (const Eigen::Vector3d& x : groups[g].all) sp.all.push_back(&x);
            for (const Eigen::Vector3d& x : groups[g].capped) sp.capped.push_back(&x);
        }
        sp.n = nsum.normalized();
        sp.d = groups[cl.front()].d;
        refitPlane(&sp, 3.0 * config.tau_m);
        sp.area = occupiedArea(sp, config.grid_cell_m);
        if (sp.area < config.min_dominant_area_m2) continue;
        dominant.push_back(std::move(sp));
    }
    std::stable_sort(
        dominant.begin(), dominant.end(),
        [](const SupportedPlane& a, const SupportedPlane& b) { return a.area > b.area; });
    for (size_t k = 0; k < dominant.size(); ++k) {
        dominant[k].id = static_cast<int>(k);
        DominantPlane dp;
        dp.id = dominant[k].id;
        dp.normal_W = dominant[k].n;
        dp.d_W = dominant[k].d;
        dp.area_m2 = dominant[k].area;
        dp.num_groups = static_cast<int>(dominant[k].groups.size());
        dp.num_points = static_cast<int>(dominant[k].all.size());
        dp.rms_m = dominant[k].rms;
        for (int g : dominant[k].groups) dp.fragments.push_back(fragments[groups[g].fragment].id);
        std::sort(dp.fragments.begin(), dp.fragments.end());
        dp.fragments.erase(std::unique(dp.fragments.begin(), dp.fragments.end()),
                           dp.fragments.end());
        diag->dominant_planes.push_back(dp);
    }
    return dominant;
}

/// Counts the points farther than `margin` from plane p on its positive and negative sides.
void sideCounts(const SupportedPlane& p, const std::vector<Eigen::Vector3d>& points, double margin,
                size_t* pos, size_t* neg) {
    *pos = *neg = 0;
    for (const Eigen::Vector3d& x : points) {
        const double s = p.n.dot(x) + p.d;
        if (s > margin) ++*pos;
        if (s < -margin) ++*neg;
    }
}

/// The base plane: which dominant plane it is and whether it is the floor (else the ceiling).
struct BaseChoice {
    int index = -1;
    bool is_floor = true;
};

/// Step 3 (reference §4.7): the base plane is the largest dominant plane with (almost) all
/// points on one side that is, with a gravity hint (camera_up_C averaged over the fragments'
/// rotations), roughly horizontal; failing both tests, the largest horizontal one; failing that,
/// the largest. It is oriented into the room (most points on its positive side). `dominant` must
/// not be empty.
BaseChoice chooseBasePlane(std::vector<SupportedPlane>& dominant,
                           const std::vector<Eigen::Vector3d>& all_points,
                           const std::vector<Eigen::Isometry3d>& T_W_F, const LayoutConfig& config,
                           LayoutDiagnostics* diag) {
    Eigen::Vector3d up_hint = Eigen::Vector3d::Zero();
    if (config.camera_up_C.norm() > 1e-9) {
        for (const Eigen::Isometry3d& T : T_W_F) up_hint += T.linear() * config.camera_up_C;
        if (up_hint.norm() > 1e-9) up_hint.normalize();
    }
    diag->up_hint_W = up_hint;
    const bool have_hint = up_hint.squaredNorm() > 0.5;
    const double cos_tilt = std::cos(config.base_max_tilt_deg * kDeg);
    int base = -1;
    for (int pass = 0; pass < 3 && base < 0; ++pass) {
        for (size_t k = 0; k < dominant.size(); ++k) {
            const bool horizontal = !have_hint || std::abs(dominant[k].n.dot(up_hint)) >= cos_tilt;
            size_t pos = 0, neg = 0;
            sideCounts(dominant[k], all_points, config.base_side_margin_m, &pos, &neg);
            const double one_sided =
                pos + neg == 0 ? 1.0 : static_cast<double>(std::max(pos, neg)) / (pos + neg);
            const bool sided = one_sided >= config.base_min_one_sided;
            // Pass 0: both tests; pass 1: horizontal only; pass 2: the largest plane.
            if ((pass == 0 && horizontal && sided) || (pass == 1 && horizontal) || pass == 2) {
                base = static_cast<int>(k);  // sorted by area: the first hit is the largest
                break;
            }
        }
    }
    SupportedPlane& bp = dominant[base];
    size_t pos = 0, neg = 0;
    sideCounts(bp, all_points, config.base_side_margin_m, &pos, &neg);
    if (neg > pos) {  // orient into the room
        bp.n = -bp.n;
        bp.d = -bp.d;
    }
    BaseChoice choice;
    choice.index = base;
    choice.is_floor = !have_hint || bp.n.dot(up_hint) >= 0.0;
    diag->base_plane_id = bp.id;
    diag->base_kind = choice.is_floor ? "floor" : "ceiling";
    return choice;
}

/// The occupancy grid on the base plane (step 4): cell (u, v) holds the points x with
/// e1.x in [umin + u cell, umin + (u + 1) cell) and likewise e2.x from vmin.
struct BaseGrid {
    Eigen::Vector3d e1 = Eigen::Vector3d::UnitX(), e2 = Eigen::Vector3d::UnitY();
    double umin = 0.0, vmin = 0.0, cell = 0.0;
    int width = 0, height = 0;
    cv::Mat room;                    ///< CV_8U, 255 in the room region (the outer contour, filled)
    cv::Mat distance;                ///< CV_32F, distance of each cell to the boundary dO, cells
    std::vector<cv::Point> contour;  ///< dO: the outer contour of the room region

    /// The cell x falls in, clamped to the grid.
    cv::Point cellOf(const Eigen::Vector3d& x) const {
        return cv::Point(std::clamp(static_cast<int>((e1.dot(x) - umin) / cell), 0, width - 1),
                         std::clamp(static_cast<int>((e2.dot(x) - vmin) / cell), 0, height - 1));
    }
    /// True when x falls in a cell of the room region (false outside the grid).
    bool inRoom(const Eigen::Vector3d& x) const {
        const double u = (e1.dot(x) - umin) / cell, v = (e2.dot(x) - vmin) / cell;
        if (u < 0 || v < 0 || u >= width || v >= height) return false;
        return room.at<uint8_t>(static_cast<int>(v), static_cast<int>(u)) != 0;
    }
};

/// Step 4 (reference §4.8): the occupancy grid of all points projected on the base plane (normal
/// n_b), with the space the camera moved in (cells near camera positions, lines of sight from
/// each fragment's middle camera to its points), closed; the largest outer contour is the
/// boundary dO, the region it encloses (holes filled) the room region.
Result<BaseGrid> occupancyGrid(const Eigen::Vector3d& n_b, const WorldPoints& points,
                               const std::vector<Eigen::Vector3d>& cameras_W,
                               const std::vector<Fragment>& fragments,
                               const std::vector<Eigen::Isometry3d>& T_W_F,
                               const LayoutConfig& config, LayoutDiagnostics* diag) {
    BaseGrid grid;
    const double cell = config.grid_cell_m;
    grid.cell = cell;
    planeBasis(n_b, &grid.e1, &grid.e2);
    double umin = 1e300, umax = -1e300, vmin = 1e300, vmax = -1e300;
    for (const std::vector<Eigen::Vector3d>* set :
         std::initializer_list<const std::vector<Eigen::Vector3d>*>{&points.all, &cameras_W}) {
        for (const Eigen::Vector3d& x : *set) {
            umin = std::min(umin, grid.e1.dot(x));
            umax = std::max(umax, grid.e1.dot(x));
            vmin = std::min(vmin, grid.e2.dot(x));
            vmax = std::max(vmax, grid.e2.dot(x));
        }
    }
    const int pad = 2 + config.closing_kernel_cells;
    umin -= pad * cell;
    vmin -= pad * cell;
    const int gw = static_cast<int>(std::ceil((umax - umin) / cell)) + pad + 1;
    const int gh = static_cast<int>(std::ceil((vmax - vmin) / cell)) + pad + 1;
    if (static_cast<double>(gw) * gh > 25e6) {
        return invalidArgument(fmt::format(
            "estimateLayout: the points span {:.1f} x {:.1f} m, too large for a {} m grid",
            umax - umin, vmax - vmin, cell));
    }
    grid.umin = umin;
    grid.vmin = vmin;
    grid.width = gw;
    grid.height = gh;
    diag->grid_width = gw;
    diag->grid_height = gh;
    cv::Mat counts = cv::Mat::zeros(gh, gw, CV_32S);
    for (const Eigen::Vector3d& x : points.all) ++counts.at<int>(grid.cellOf(x));
    cv::Mat occ = counts >= config.min_cell_points;  // CV_8U, 255 = occupied
    if (config.path_occupancy_radius_m > 0.0) {
        const int r = static_cast<int>(std::lround(config.path_occupancy_radius_m / cell));
        for (const Eigen::Vector3d& c : cameras_W) {
            cv::circle(occ, grid.cellOf(c), r, cv::Scalar(255), cv::FILLED);
        }
    }
    // Lines of sight are free space inside the room: from each fragment's middle camera to a
    // subsample of its points (this joins the path to the floor it saw from afar).
    if (config.free_space_rays_per_fragment > 0) {
        for (size_t i = 0; i < fragments.size(); ++i) {
            const size_t b = points.begin[i], e = points.begin[i + 1];
            if (e == b) continue;
            const cv::Point from = grid.cellOf(fragmentViewpoint(fragments[i], T_W_F[i]));
            const size_t n = static_cast<size_t>(config.free_space_rays_per_fragment);
            const size_t stride = std::max<size_t>(1, (e - b + n - 1) / n);
            for (size_t k = b; k < e; k += stride) {
                cv::line(occ, from, grid.cellOf(points.all[k]), cv::Scalar(255), 1);
            }
        }
    }
    if (config.closing_kernel_cells > 0) {
        const cv::Mat kernel = cv::getStructuringElement(
            cv::MORPH_ELLIPSE, cv::Size(config.closing_kernel_cells, config.closing_kernel_cells));
        cv::morphologyEx(occ, occ, cv::MORPH_CLOSE, kernel);
    }
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(occ.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
    if (contours.empty()) {
        return failedPrecondition("estimateLayout: empty occupancy grid on the base plane");
    }
    size_t largest = 0;
    for (size_t c = 1; c < contours.size(); ++c) {
        if (cv::contourArea(contours[c]) > cv::contourArea(contours[largest])) largest = c;
    }
    // The room region = the largest outer contour, filled (interior holes, i.e. furniture
    // shadows, become occupied); its 1-cell outline is dO.
    grid.room = cv::Mat::zeros(gh, gw, CV_8U);
    cv::drawContours(grid.room, contours, static_cast<int>(largest), cv::Scalar(255), cv::FILLED);
    cv::Mat boundary = cv::Mat::zeros(gh, gw, CV_8U);
    cv::drawContours(boundary, contours, static_cast<int>(largest), cv::Scalar(255), 1);
    diag->occupied_cells = cv::countNonZero(grid.room);
    diag->boundary_cells = cv::countNonZero(boundary);
    cv::Mat not_boundary = boundary == 0;
    cv::distanceTransform(not_boundary, grid.distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
    grid.contour = contours[largest];
    return grid;
}

/// Height of x above the (oriented) base plane.
double heightAbove(const SupportedPlane& base, const Eigen::Vector3d& x) {
    return base.n.dot(x) + base.d;
}

/// The heights above the base of plane p's points (capped), 1st and 99th percentiles.
struct HeightSpan {
    double lo = 0.0, hi = 0.0;
};
std::optional<HeightSpan> heightSpan(const SupportedPlane& p, const SupportedPlane& base) {
    std::vector<double> h;
    for (const Eigen::Vector3d* x : p.capped) h.push_back(heightAbove(base, *x));
    if (h.empty()) return std::nullopt;
    std::sort(h.begin(), h.end());
    return HeightSpan{h[h.size() / 100], h[h.size() - 1 - h.size() / 100]};
}

/// An interval [lo, hi] along a wall's direction.
struct Span {
    double lo = 0.0, hi = 0.0;
};

/// The stretches of [lo, hi] that the sorted positions `ts` cover, split wherever consecutive
/// positions leave a gap wider than gap_m.
std::vector<Span> splitAtGaps(const std::vector<double>& ts, double lo, double hi, double gap_m) {
    std::vector<Span> pieces;
    for (const double t : ts) {
        if (t < lo || t > hi) continue;
        if (pieces.empty() || t - pieces.back().hi > gap_m) {
            pieces.push_back({t, t});
        } else {
            pieces.back().hi = t;
        }
    }
    return pieces;
}

/// True when t lies within `margin` of one of the pieces.
bool onPiece(const std::vector<Span>& pieces, double t, double margin = 0.0) {
    return std::any_of(pieces.begin(), pieces.end(), [t, margin](const Span& s) {
        return t >= s.lo - margin && t <= s.hi + margin;
    });
}

/// A vertical plane p seen from above: its horizontal normal u, the direction along it
/// (n_b x u), its extent along that direction (0.5 % / 99.5 % of all its points, which must
/// not be empty) and the pieces of the extent its points cover, split at gaps wider than
/// piece_gap_m.
struct HorizontalExtent {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    Eigen::Vector3d dir = Eigen::Vector3d::Zero();
    double tmin = 0.0, tmax = 0.0;
    std::vector<Span> pieces;
};
HorizontalExtent horizontalExtent(const SupportedPlane& p, const Eigen::Vector3d& n_b,
                                  double piece_gap_m) {
    HorizontalExtent e;
    e.u = (p.n - p.n.dot(n_b) * n_b).normalized();
    e.dir = n_b.cross(e.u);
    std::vector<double> ts;
    ts.reserve(p.all.size());
    for (const Eigen::Vector3d* x : p.all) ts.push_back(e.dir.dot(*x));
    std::sort(ts.begin(), ts.end());
    e.tmin = ts[ts.size() / 200];
    e.tmax = ts[ts.size() - 1 - ts.size() / 200];
    e.pieces = splitAtGaps(ts, e.tmin, e.tmax, piece_gap_m);
    return e;
}

/// Step 5, the opposite plane: the largest dominant plane other than the base within
/// opposite_max_angle_deg of it whose points' mean lies at least min_room_height_m above it; -1
/// when there is none.
int oppositePlane(const std::vector<SupportedPlane>& dominant, int base,
                  const LayoutConfig& config) {
    const SupportedPlane& bp = dominant[base];
    const double cos_opp = std::cos(config.opposite_max_angle_deg * kDeg);
    for (size_t k = 0; k < dominant.size(); ++k) {  // sorted by area: the first is the largest
        const SupportedPlane& p = dominant[k];
        if (static_cast<int>(k) == base || std::abs(p.n.dot(bp.n)) < cos_opp) continue;
        PlaneMoments m;
        for (const Eigen::Vector3d* x : p.capped) m.add(*x);
        if (heightAbove(bp, m.mean()) >= config.min_room_height_m) return static_cast<int>(k);
    }
    return -1;
}

/// How far plane p's points stay from the ceiling (from the floor when the base is the
/// ceiling), 99th percentile; without an opposite plane, min_wall_height_m minus their span.
/// Layout walls span floor to ceiling; furniture never reaches it.
double reachGap(const SupportedPlane& p, const SupportedPlane& base, bool base_is_floor,
                bool have_opposite, double room_height, const LayoutConfig& config) {
    const std::optional<HeightSpan> h = heightSpan(p, base);
    if (!h) return 0.0;
    if (have_opposite) return base_is_floor ? room_height - h->hi : h->lo;
    return config.min_wall_height_m - (h->hi - h->lo);
}

/// Where the lines of sight start: each fragment's viewpoint (fragmentViewpoint) and its points.
struct SightLines {
    const WorldPoints& points;
    std::vector<Eigen::Vector3d> viewpoints;  ///< per fragment
};

/// What the lines of sight show of a plane's top (topSeenFraction).
struct TopSeen {
    double fraction = 0.0;  ///< of the plane's extent, seen over
    double length_m = 0.0;  ///< the plane's horizontal extent (0.5-99.5 % of its points)
};

/// The fraction of plane p's horizontal extent (its points' 0.5-99.5 % range along it, less the
/// margin at each end, in bins of the margin) over which a line of sight passes over its top: from
/// a fragment's viewpoint to one of its points more than wall_top_seen_margin_m beyond the plane,
/// crossing the plane more than that above the plane's top (its points' 99th-percentile height;
/// below their 1st percentile, towards the base, when the base is the ceiling).
TopSeen topSeenFraction(const SupportedPlane& p, const SupportedPlane& base, bool base_is_floor,
                        const SightLines& sight, const LayoutConfig& config) {
    const double m = config.wall_top_seen_margin_m;
    const std::optional<HeightSpan> h = heightSpan(p, base);
    if (!h || p.all.empty()) return {};
    // Heights beyond the top count positive: up from the floor, or towards a ceiling base.
    const double sign = base_is_floor ? 1.0 : -1.0;
    const double top = base_is_floor ? h->hi : h->lo;
    const HorizontalExtent ext = horizontalExtent(p, base.n, config.wall_piece_gap_m);
    const Eigen::Vector3d& dir = ext.dir;
    TopSeen out;
    out.length_m = ext.tmax - ext.tmin;
    const double t0 = ext.tmin + m, t1 = ext.tmax - m;
    if (!(t1 > t0)) return out;
    const size_t bins = static_cast<size_t>(std::ceil((t1 - t0) / m));
    // Only the stretches its points cover count: a wall coplanar with a furniture face across
    // the room is not seen over where the lines of sight pass the furniture.
    std::vector<char> covered(bins, 0), seen(bins, 0);
    for (size_t b = 0; b < bins; ++b) {
        covered[b] = onPiece(ext.pieces, t0 + (static_cast<double>(b) + 0.5) * m);
    }
    for (size_t i = 0; i + 1 < sight.points.begin.size(); ++i) {
        const Eigen::Vector3d& v = sight.viewpoints[i];
        const double sv = p.n.dot(v) + p.d;
        for (size_t k = sight.points.begin[i]; k < sight.points.begin[i + 1]; ++k) {
            const Eigen::Vector3d& x = sight.points.all[k];
            const double sx = p.n.dot(x) + p.d;
            if (std::abs(sx) <= m || (sx > 0.0) == (sv > 0.0)) continue;  // not beyond it
            const Eigen::Vector3d q = v + (sv / (sv - sx)) * (x - v);
            const double t = dir.dot(q);
            if (t < t0 || t >= t1) continue;
            if (sign * (heightAbove(base, q) - top) <= m) continue;
            seen[std::min(bins - 1, static_cast<size_t>((t - t0) / m))] = 1;
        }
    }
    size_t n_covered = 0, n_seen = 0;
    for (size_t b = 0; b < bins; ++b) {
        n_covered += covered[b] ? 1 : 0;
        n_seen += covered[b] && seen[b] ? 1 : 0;
    }
    if (n_covered > 0) out.fraction = static_cast<double>(n_seen) / static_cast<double>(n_covered);
    return out;
}

/// Merges wall candidate p into an already kept wall within wall_merge_angle_deg and
/// wall_merge_offset_m of it and refits that wall; returns its index into `dominant`, or -1 when
/// no kept wall is near-coplanar.
int mergeIntoKeptWall(std::vector<SupportedPlane>& dominant, const std::vector<int>& wall_ids,
                      const SupportedPlane& p, const LayoutConfig& config) {
    for (int w : wall_ids) {
        SupportedPlane& q = dominant[w];
        if (std::abs(q.n.dot(p.n)) < std::cos(config.wall_merge_angle_deg * kDeg)) continue;
        PlaneMoments m;
        for (const Eigen::Vector3d* x : p.capped) m.add(*x);
        if (std::abs(q.n.dot(m.mean()) + q.d) > config.wall_merge_offset_m) continue;
        q.all.insert(q.all.end(), p.all.begin(), p.all.end());
        q.capped.insert(q.capped.end(), p.capped.begin(), p.capped.end());
        q.groups.insert(q.groups.end(), p.groups.begin(), p.groups.end());
        refitPlane(&q, 3.0 * config.tau_m);
        return w;
    }
    return -1;
}

/// The walls of step 5 and the plane opposite the base.
struct WallSelection {
    std::vector<int> wall_ids;  ///< into `dominant`, in area order
    int opposite = -1;          ///< into `dominant`, -1 when none
};

/// Step 5 (Eq. 6-7): a dominant plane is a wall when |n . n_base| < tau1 (Eq. 6), the mean
/// distance g(dO, pi) of its points to the boundary dO is below tau2 (Eq. 7), its area reaches
/// min_wall_area_m2 and it reaches the ceiling (reachGap) or the space above its top was not seen
/// (topSeenFraction); near-coplanar walls are merged. One WallDecision per dominant plane goes
/// into diag->walls, in the order of `dominant`.
WallSelection selectWalls(std::vector<SupportedPlane>& dominant, const BaseChoice& base,
                          const BaseGrid& grid, const SightLines& sight, const LayoutConfig& config,
                          LayoutDiagnostics* diag) {
    WallSelection sel;
    const SupportedPlane& bp = dominant[base.index];
    const Eigen::Vector3d n_b = bp.n;
    sel.opposite = oppositePlane(dominant, base.index, config);
    double room_height = 0.0;
    if (sel.opposite >= 0) {
        PlaneMoments m;
        for (const Eigen::Vector3d* x : dominant[sel.opposite].capped) m.add(*x);
        room_height = heightAbove(bp, m.mean());
    }
    for (size_t k = 0; k < dominant.size(); ++k) {
        const SupportedPlane& p = dominant[k];
        const double reach_gap =
            reachGap(p, bp, base.is_floor, sel.opposite >= 0, room_height, config);
        WallDecision wd;
        wd.plane_id = p.id;
        wd.abs_dot_base = std::abs(p.n.dot(n_b));  // Eq. 6
        wd.top_gap_m = reach_gap;
        if (static_cast<int>(k) == base.index) {
            wd.reason = "base plane";
            diag->walls.push_back(wd);
            continue;
        }
        // Whether lines of sight pass over its top (a plane short of the ceiling); a plane too
        // narrow to tell by them, such as a cabinet's side, counts as seen over.
        const auto top_seen_over = [&] {
            const TopSeen seen = topSeenFraction(p, bp, base.is_floor, sight, config);
            wd.top_seen_fraction = seen.fraction;
            return seen.length_m < config.wall_top_unseen_min_length_m ||
                   seen.fraction >= config.wall_top_seen_fraction;
        };
        double g = 0.0;  // Eq. 7: g(dO, pi), the mean distance of the points to dO
        for (const Eigen::Vector3d* x : p.capped) g += grid.distance.at<float>(grid.cellOf(*x));
        wd.boundary_distance_m = p.capped.empty() ? 1e9 : g / p.capped.size() * grid.cell;
        if (wd.abs_dot_base >= config.tau1) {
            wd.reason = static_cast<int>(k) == sel.opposite ? "opposite plane" : "not vertical";
        } else if (wd.boundary_distance_m >= config.tau2_m) {
            wd.reason = "far from boundary";
        } else if (p.area < config.min_wall_area_m2) {
            wd.reason = "too small";
        } else if (reach_gap > config.wall_top_margin_m && sel.opposite < 0) {
            wd.reason = "too low";
        } else if (reach_gap > config.wall_top_margin_m && top_seen_over()) {
            wd.reason = "does not reach the ceiling";
        } else if (const int merged = mergeIntoKeptWall(dominant, sel.wall_ids, p, config);
                   merged >= 0) {
            wd.reason = fmt::format("merged into {}", dominant[merged].id);
        } else {
            wd.kept = true;
            wd.reason = "wall";
            sel.wall_ids.push_back(static_cast<int>(k));
        }
        diag->walls.push_back(wd);
    }
    diag->opposite_plane_id = sel.opposite >= 0 ? dominant[sel.opposite].id : -1;
    return sel;
}

/// A wall seen from above: a point on it, its direction, its extent along the direction
/// (0.5 % / 99.5 % of its points) and its horizontal normal into the room.
struct WallSide {
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    Eigen::Vector3d dir = Eigen::Vector3d::Zero();
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    double tmin = 0.0, tmax = 0.0;
    std::vector<Span> pieces;  ///< the parts of [tmin, tmax] its points cover (rule a)
};

/// Wall p seen from above. Its room side is the side where the room region lies, probed along
/// its extent just beyond tau2 (the band within which it counts as on the boundary); when no
/// side tells, the side most camera positions are on.
WallSide wallSide(const SupportedPlane& p, const Eigen::Vector3d& n_b, const BaseGrid& grid,
                  const std::vector<Eigen::Vector3d>& cameras_W, const LayoutConfig& config) {
    WallSide ws;
    PlaneMoments mm;
    for (const Eigen::Vector3d* x : p.capped) mm.add(*x);
    ws.m = mm.mean();
    const HorizontalExtent ext = horizontalExtent(p, n_b, config.wall_piece_gap_m);
    const Eigen::Vector3d& u = ext.u;
    ws.dir = ext.dir;
    ws.tmin = ext.tmin;
    ws.tmax = ext.tmax;
    ws.pieces = ext.pieces;
    const double probe = config.tau2_m + 2.0 * grid.cell;
    int plus = 0, minus = 0;
    for (double t = ws.tmin; t <= ws.tmax; t += grid.cell) {
        const Eigen::Vector3d q = ws.m + (t - ws.dir.dot(ws.m)) * ws.dir;
        const bool a = grid.inRoom(q + probe * u), b = grid.inRoom(q - probe * u);
        if (a && !b) ++plus;
        if (b && !a) ++minus;
    }
    if (plus == minus) {  // no side tells: the side most camera positions are on
        for (const Eigen::Vector3d& c : cameras_W) (u.dot(c - ws.m) >= 0 ? plus : minus)++;
    }
    ws.u = minus > plus ? Eigen::Vector3d(-u) : u;
    return ws;
}

/// True when the horizontal path from camera position c straight to wall ws (its foot on the
/// wall's plane, less the band `near` before the wall) stays in the room region: the camera faces
/// the wall across the room. A camera that faces it across space outside the room (the other arm
/// of a U behind a side wall of its notch) does not stand behind it.
bool facesAcrossRoom(const Eigen::Vector3d& c, const WallSide& ws, const BaseGrid& grid,
                     double near) {
    const double dist = std::abs(ws.u.dot(c - ws.m));
    const Eigen::Vector3d towards = ws.u.dot(c - ws.m) > 0.0 ? Eigen::Vector3d(-ws.u) : ws.u;
    for (double s = 0.0; s <= dist - near; s += grid.cell) {
        if (!grid.inRoom(c + s * towards)) return false;
    }
    return true;
}

/// Rule a (header): the walls without more than max_camera_behind_fraction of the camera
/// positions within their extent behind them; the others are marked "camera behind it". Only
/// the pieces of a wall its points cover count as its extent, and only camera positions that face
/// the wall across the room region.
std::vector<int> wallsWithoutCameraBehind(const std::vector<int>& wall_ids,
                                          const std::vector<WallSide>& sides,
                                          const std::vector<Eigen::Vector3d>& cameras_W,
                                          const BaseGrid& grid, const LayoutConfig& config,
                                          LayoutDiagnostics* diag) {
    const double near = config.tau2_m + 2.0 * grid.cell;  // the band wallSide probes beyond
    std::vector<int> kept;
    for (int k : wall_ids) {
        const WallSide& ws = sides[k];
        int within = 0, behind = 0;
        for (const Eigen::Vector3d& c : cameras_W) {
            const double t = ws.dir.dot(c);
            if (!onPiece(ws.pieces, t) || !facesAcrossRoom(c, ws, grid, near)) continue;
            ++within;
            if (ws.u.dot(c - ws.m) < -config.camera_behind_margin_m) ++behind;
        }
        WallDecision& wd = diag->walls[k];
        if (within > 0) wd.camera_behind_fraction = static_cast<double>(behind) / within;
        if (within > 0 && wd.camera_behind_fraction > config.max_camera_behind_fraction) {
            wd.kept = false;
            wd.reason = "camera behind it";
        } else {
            kept.push_back(k);
        }
    }
    return kept;
}

/// Two stacked walls: the inner one (a front) before the outer one, gap_m apart.
struct Front {
    int inner = -1, outer = -1;
    double gap_m = 0.0;
};

/// Rule b (header): for each wall, the farthest same-facing parallel wall behind it more than
/// wall_merge_offset_m and at most stacked_wall_max_gap_m away makes it a front.
std::vector<Front> stackedFronts(const std::vector<int>& kept, const std::vector<WallSide>& sides,
                                 const LayoutConfig& config) {
    std::vector<Front> fronts;
    const double cos_stack = std::cos(config.stacked_wall_angle_deg * kDeg);
    if (!(config.stacked_wall_max_gap_m > 0.0)) return fronts;
    for (int i : kept) {
        Front best;
        for (int o : kept) {
            if (o == i || sides[i].u.dot(sides[o].u) < cos_stack) continue;
            const double gap = sides[o].u.dot(sides[i].m - sides[o].m);
            if (gap > config.wall_merge_offset_m && gap <= config.stacked_wall_max_gap_m &&
                gap > best.gap_m) {
                best = Front{i, o, gap};
            }
        }
        if (best.inner >= 0) fronts.push_back(best);
    }
    return fronts;
}

/// Rule c (header): true when (95 % of) p's points lie in the slab between front f's outer
/// wall and the front (10 cm margin), within the front's extent: p is the side of that block.
bool isBlockSide(const SupportedPlane& p, const Front& f, const std::vector<WallSide>& sides) {
    const double margin = 0.1;
    const WallSide& o = sides[f.outer];
    const WallSide& in = sides[f.inner];
    size_t between = 0;
    for (const Eigen::Vector3d* x : p.capped) {
        const double s = o.u.dot(*x - o.m), t = in.dir.dot(*x);
        if (s >= -margin && s <= f.gap_m + margin && t >= in.tmin - 2 * margin &&
            t <= in.tmax + 2 * margin) {
            ++between;
        }
    }
    return !p.capped.empty() && between >= 0.95 * static_cast<double>(p.capped.size());
}

/// Step 5, then: walls must bound the space the camera moved in (rules a-c in the header).
/// Returns the walls kept, marking the others in diag->walls (diag->walls[k] is the decision on
/// dominant[k]).
std::vector<int> boundingWalls(const std::vector<SupportedPlane>& dominant,
                               const std::vector<int>& wall_ids, const Eigen::Vector3d& n_b,
                               const BaseGrid& grid, const std::vector<Eigen::Vector3d>& cameras_W,
                               const LayoutConfig& config, LayoutDiagnostics* diag) {
    std::vector<WallSide> sides(dominant.size());
    for (int k : wall_ids) sides[k] = wallSide(dominant[k], n_b, grid, cameras_W, config);
    const std::vector<int> kept =
        wallsWithoutCameraBehind(wall_ids, sides, cameras_W, grid, config, diag);  // a
    const std::vector<Front> fronts = stackedFronts(kept, sides, config);          // b
    const double cos_stack = std::cos(config.stacked_wall_angle_deg * kDeg);
    std::vector<int> bounding;
    for (int k : kept) {
        WallDecision& wd = diag->walls[k];
        bool inner = false;
        for (const Front& f : fronts) {
            if (f.inner == k) {
                wd.kept = false;
                wd.reason = fmt::format("in front of wall {}", dominant[f.outer].id);
                inner = true;
            }
        }
        if (inner) continue;
        for (const Front& f : fronts) {  // c
            if (std::abs(sides[k].u.dot(sides[f.outer].u)) >= cos_stack) continue;
            if (isBlockSide(dominant[k], f, sides)) {
                wd.kept = false;
                wd.reason =
                    fmt::format("side of a block in front of wall {}", dominant[f.outer].id);
                break;
            }
        }
        if (wd.kept) bounding.push_back(k);
    }
    return bounding;
}

/// The walls after step 6, parallel to the wall list.
struct SnappedWalls {
    std::vector<Eigen::Vector3d> n;  ///< vertical unit normals, W
    std::vector<double> d;           ///< offsets refitted for those normals
    std::vector<bool> snapped;
    int ref = -1;  ///< the reference (largest) wall, -1 without walls
};

/// Step 6 (reference §4.10), weak-Manhattan snapping: walls made exactly vertical; those within
/// snap_angle_deg of a multiple of 90 degrees from the largest wall made exactly orthogonal or
/// parallel to it, the others keep their angle; offsets re-estimated with the normals fixed.
SnappedWalls snapWeakManhattan(const std::vector<SupportedPlane>& dominant,
                               const std::vector<int>& wall_ids, const Eigen::Vector3d& n_b,
                               const BaseGrid& grid, const LayoutConfig& config,
                               LayoutDiagnostics* diag) {
    SnappedWalls sw;
    sw.n.resize(wall_ids.size());
    sw.d.resize(wall_ids.size());
    sw.snapped.assign(wall_ids.size(), false);
    sw.ref = wall_ids.empty() ? -1 : 0;  // walls are in area order: the first is largest
    const int ref = sw.ref;
    const Eigen::Vector3d& e1 = grid.e1;
    const Eigen::Vector3d& e2 = grid.e2;
    for (size_t w = 0; w < wall_ids.size(); ++w) {
        const SupportedPlane& p = dominant[wall_ids[w]];
        sw.n[w] = (p.n - p.n.dot(n_b) * n_b).normalized();
    }
    if (ref >= 0) {
        const double phi_ref = std::atan2(sw.n[ref].dot(e2), sw.n[ref].dot(e1));
        int num_snapped = 0;
        for (size_t w = 0; w < wall_ids.size(); ++w) {
            SnapDecision sd;
            sd.plane_id = dominant[wall_ids[w]].id;
            sd.normal_before_W = sw.n[w];
            sd.reference = static_cast<int>(w) == ref;
            const double phi = std::atan2(sw.n[w].dot(e2), sw.n[w].dot(e1));
            double rel = std::fmod((phi - phi_ref) / kDeg, 180.0);
            if (rel < 0) rel += 180.0;
            sd.angle_to_reference_deg = rel;
            const double nearest = std::round(rel / 90.0) * 90.0;
            sd.residual_deg = std::abs(rel - nearest);
            if (!sd.reference && sd.residual_deg <= config.snap_angle_deg) {
                const double target = phi + (nearest - rel) * kDeg;
                sw.n[w] = std::cos(target) * e1 + std::sin(target) * e2;
                sd.snapped = true;
                sw.snapped[w] = true;
                ++num_snapped;
            }
            diag->snapping.push_back(sd);
        }
        if (num_snapped > 0) {
            sw.snapped[ref] = true;
            diag->snapping[ref].snapped = true;
        }
    }
    for (size_t w = 0; w < wall_ids.size(); ++w) {
        sw.d[w] = refitOffset(dominant[wall_ids[w]], sw.n[w], config.refit_band_m);
    }
    return sw;
}

/// Step 7's frame: z up along the floor normal, floor at z = 0, x along `x_hint` made
/// horizontal.
struct LayoutFrame {
    Eigen::Isometry3d T_W_L = Eigen::Isometry3d::Identity();
    bool have_ceiling = false;
    double height = 0.0;  ///< ceiling height above the floor (with have_ceiling)
};

/// Step 7, the layout frame L from the base plane (n_b, d_base refitted) and the opposite plane
/// (offset d_opp for the normal -n_b, when there is one). A ceiling base without an opposite
/// floor puts the floor at the lowest points (1st percentile; diag->floor_inferred).
LayoutFrame layoutFrame(const Eigen::Vector3d& n_b, bool base_is_floor, double d_base,
                        bool have_opposite, double d_opp,
                        const std::vector<Eigen::Vector3d>& all_points,
                        const Eigen::Vector3d& x_hint, LayoutDiagnostics* diag) {
    LayoutFrame frame;
    Eigen::Vector3d up;
    double d_floor;  // floor plane: up.x + d_floor = 0
    if (base_is_floor) {
        up = n_b;
        d_floor = d_base;
        if (have_opposite) {
            frame.have_ceiling = true;
            // Ceiling oriented by -n_b: -up.x + d_opp = 0, i.e. at height d_opp + d_floor.
            frame.height = d_opp + d_floor;
        }
    } else {
        up = -n_b;
        frame.have_ceiling = true;
        // Ceiling: n_b.x + d_base = 0 -> up.x = d_base.
        if (have_opposite) {
            d_floor = d_opp;  // opposite oriented with -n_b = up: up.x + d_opp = 0
        } else {
            std::vector<double> heights;
            heights.reserve(all_points.size());
            for (const Eigen::Vector3d& x : all_points) heights.push_back(up.dot(x));
            const size_t q = heights.size() / 100;
            std::nth_element(heights.begin(), heights.begin() + q, heights.end());
            d_floor = -heights[q];
            diag->floor_inferred = true;
        }
        frame.height = d_base + d_floor;
    }
    Eigen::Vector3d x_axis = x_hint;
    x_axis = (x_axis - x_axis.dot(up) * up).normalized();
    const Eigen::Vector3d y_axis = up.cross(x_axis);
    frame.T_W_L.linear().col(0) = x_axis;
    frame.T_W_L.linear().col(1) = y_axis;
    frame.T_W_L.linear().col(2) = up;
    frame.T_W_L.translation() = -d_floor * up;
    return frame;
}

/// A wall as a 2-D line in L with the extent of its points.
struct Wall2 {
    Line2 line;
    double tmin = 0.0, tmax = 0.0;  // extent along the direction (-n.y, n.x)
    std::vector<Span> pieces;       // the parts of [tmin, tmax] its points cover
    int index = 0;                  // into the wall list
};

/// The snapped walls as lines in L, each with the extent (0.5 % / 99.5 %) of its points and the
/// pieces of it they cover (split at gaps wider than piece_gap_m).
std::vector<Wall2> wallLines(const std::vector<SupportedPlane>& dominant,
                             const std::vector<int>& wall_ids, const SnappedWalls& walls,
                             const Eigen::Isometry3d& T_W_L, double piece_gap_m) {
    const Eigen::Isometry3d T_L_W = T_W_L.inverse();
    std::vector<Wall2> walls2(wall_ids.size());
    for (size_t w = 0; w < wall_ids.size(); ++w) {
        const Eigen::Vector3d nL = T_L_W.linear() * walls.n[w];
        Wall2& w2 = walls2[w];
        w2.line.n = Eigen::Vector2d(nL.x(), nL.y()).normalized();
        w2.line.d = walls.d[w] + walls.n[w].dot(T_W_L.translation());
        w2.index = static_cast<int>(w);
        const Eigen::Vector2d dir(-w2.line.n.y(), w2.line.n.x());
        std::vector<double> ts;
        for (const Eigen::Vector3d* x : dominant[wall_ids[w]].all) {
            const Eigen::Vector3d xl = T_L_W * *x;
            ts.push_back(dir.dot(xl.head<2>()));
        }
        std::sort(ts.begin(), ts.end());
        w2.tmin = ts[ts.size() / 200];
        w2.tmax = ts[ts.size() - 1 - ts.size() / 200];
        w2.pieces = splitAtGaps(ts, w2.tmin, w2.tmax, piece_gap_m);
    }
    return walls2;
}

/// The base grid seen from the layout frame.
struct GridInLayout {
    const BaseGrid& grid;
    const SupportedPlane& base;
    Eigen::Isometry3d T_W_L;
    Eigen::Isometry3d T_L_W;

    /// The centre of cell c on the base plane, in L (2-D).
    Eigen::Vector2d cellCentre(const cv::Point& c) const {
        const Eigen::Vector3d x = (grid.umin + (c.x + 0.5) * grid.cell) * grid.e1 +
                                  (grid.vmin + (c.y + 0.5) * grid.cell) * grid.e2 - base.d * base.n;
        return Eigen::Vector2d((T_L_W * x).head<2>());
    }
    /// True when the point q of the floor (L, 2-D) falls in the room region.
    bool inRoom(const Eigen::Vector2d& q) const {
        return grid.inRoom(T_W_L * Eigen::Vector3d(q.x(), q.y(), 0.0));
    }
};

/// Where the contour rounds a corner its cells can alternate between the two walls (A B A B):
/// of a run B between two runs of the same wall A, the shortest of the three is dropped (B: the
/// two A runs merge; one A: a stray stretch of A's line, e.g. where a partial scan's contour
/// passes near it again), until no such triple is left. `runs` are (wall, length), cyclic.
void dropAlternatingRuns(std::vector<std::pair<int, int>>* runs) {
    std::vector<std::pair<int, int>>& kept = *runs;
    auto mergeEqualNeighbours = [&](size_t at) {  // kept[at] and kept[at + 1] (wrapping)
        const size_t m = kept.size();
        const size_t nx = (at + 1) % m;
        if (m < 2 || kept[at].first != kept[nx].first) return;
        kept[at].second += kept[nx].second;
        kept.erase(kept.begin() + static_cast<std::ptrdiff_t>(nx));
    };
    for (bool changed = true; changed && kept.size() > 3;) {
        changed = false;
        const size_t m = kept.size();
        size_t drop = m;
        for (size_t k = 0; k < m; ++k) {
            const size_t prev = (k + m - 1) % m, next = (k + 1) % m;
            if (kept[prev].first != kept[next].first) continue;
            for (size_t c : {k, prev, next}) {
                if (drop == m || kept[c].second < kept[drop].second) drop = c;
            }
        }
        if (drop == m) break;
        kept.erase(kept.begin() + static_cast<std::ptrdiff_t>(drop));
        mergeEqualNeighbours((drop + kept.size() - 1) % kept.size());
        changed = true;
    }
}

/// Step 7, the walls in the order the boundary contour meets them: each contour cell is
/// labelled with the nearest wall line it lies on (within tau2 and 0.3 m of a piece of the wall its
/// points cover), runs shorter than min_contour_run_cells are ignored, alternating runs at corners
/// resolved.
std::vector<int> contourWallSequence(const GridInLayout& view, const std::vector<Wall2>& walls2,
                                     const LayoutConfig& config) {
    const std::vector<cv::Point>& contour = view.grid.contour;
    std::vector<int> lab(contour.size(), -1);
    for (size_t c = 0; c < contour.size(); ++c) {
        const Eigen::Vector2d q = view.cellCentre(contour[c]);
        double best = config.tau2_m;
        for (const Wall2& w2 : walls2) {
            const double dd = std::abs(w2.line.n.dot(q) + w2.line.d);
            const double t = Eigen::Vector2d(-w2.line.n.y(), w2.line.n.x()).dot(q);
            if (dd < best && onPiece(w2.pieces, t, 0.3)) {
                best = dd;
                lab[c] = w2.index;
            }
        }
    }
    std::vector<std::pair<int, int>> runs;  // (label, length)
    for (int l : lab) {
        if (!runs.empty() && runs.back().first == l) {
            ++runs.back().second;
        } else {
            runs.emplace_back(l, 1);
        }
    }
    if (runs.size() > 1 && runs.front().first == runs.back().first) {
        runs.front().second += runs.back().second;
        runs.pop_back();
    }
    std::vector<std::pair<int, int>> kept;  // labelled runs long enough, neighbours merged
    for (const auto& [l, len] : runs) {
        if (l < 0 || len < config.min_contour_run_cells) continue;
        if (!kept.empty() && kept.back().first == l) {
            kept.back().second += len;
        } else {
            kept.emplace_back(l, len);
        }
    }
    dropAlternatingRuns(&kept);
    std::vector<int> seq;
    for (const auto& run : kept) {
        if (!seq.empty() && seq.back() == run.first) continue;
        seq.push_back(run.first);
    }
    while (seq.size() > 1 && seq.front() == seq.back()) seq.pop_back();
    return seq;
}

/// The room polygon in L, counter-clockwise, and the wall of each edge.
struct RoomPolygon {
    std::vector<Eigen::Vector2d> vertices;
    std::vector<int> edge_wall;  ///< wall index of edge k (vertex k -> k + 1), -1 for none
    bool from_walls = false;     ///< false: the fallback from the contour
};

/// Step 7, the room polygon: consecutive walls of the contour sequence intersected (parallel
/// neighbours joined by a step); when that gives no valid room, the contour simplified.
RoomPolygon roomPolygon(const std::vector<int>& seq, const std::vector<Wall2>& walls2,
                        const GridInLayout& view) {
    RoomPolygon room;
    std::vector<Eigen::Vector2d>& polygon = room.vertices;
    std::vector<int>& edge_wall = room.edge_wall;
    if (seq.size() >= 3) {
        const size_t m = seq.size();
        for (size_t k = 0; k < m; ++k) {
            const Wall2& a = walls2[seq[k]];
            const Wall2& b = walls2[seq[(k + 1) % m]];
            Eigen::Vector2d x;
            if (intersect(a.line, b.line, &x)) {
                polygon.push_back(x);
                edge_wall.push_back(seq[(k + 1) % m]);
            } else {
                // Parallel neighbours (a step between them): a ends where b begins.
                const Eigen::Vector2d da(-a.line.n.y(), a.line.n.x());
                const Eigen::Vector2d db(-b.line.n.y(), b.line.n.x());
                const Eigen::Vector2d pa0 = -a.line.d * a.line.n;
                const Eigen::Vector2d pb0 = -b.line.d * b.line.n;
                const double tb_on_a = da.dot(pb0 + 0.5 * (b.tmin + b.tmax) * db);
                const double ta =
                    std::abs(tb_on_a - a.tmin) < std::abs(tb_on_a - a.tmax) ? a.tmin : a.tmax;
                const Eigen::Vector2d va = pa0 + ta * da;
                const Eigen::Vector2d vb = va - (b.line.n.dot(va) + b.line.d) * b.line.n;
                polygon.push_back(va);
                edge_wall.push_back(-1);
                polygon.push_back(vb);
                edge_wall.push_back(seq[(k + 1) % m]);
            }
        }
        // polygon[k] starts edge_wall[k]; rotate bookkeeping so edge k = wall of vertex k -> k+1.
        if (signedArea(polygon) < 0) {
            std::reverse(polygon.begin(), polygon.end());
            std::reverse(edge_wall.begin(), edge_wall.end());
            // After reversal vertex k -> k+1 runs along the wall that ended at old vertex k.
            std::vector<int> fixed(edge_wall.size());
            for (size_t k = 0; k < edge_wall.size(); ++k) {
                fixed[k] = edge_wall[(k + 1) % edge_wall.size()];
            }
            edge_wall.swap(fixed);
        }
        room.from_walls = makeRoomLayout(polygon, 1.0).isOk();
    }
    if (!room.from_walls) {
        std::vector<cv::Point> approx;
        cv::approxPolyDP(view.grid.contour, approx, 2.0, true);
        polygon.clear();
        edge_wall.clear();
        for (const cv::Point& c : approx) polygon.push_back(view.cellCentre(c));
        if (signedArea(polygon) < 0) std::reverse(polygon.begin(), polygon.end());
        edge_wall.assign(polygon.size(), -1);
    }
    return room;
}

/// Step 7, wall w2 as a layout plane: its segment is the longest polygon edge on it, else the
/// extent of its points; its normal points into the room (the left of a counter-clockwise
/// polygon edge, else the side of the segment's midpoint where the room region lies).
LayoutPlane wallPlane(const Wall2& w2, int w, const RoomPolygon& room, const GridInLayout& view) {
    const std::vector<Eigen::Vector2d>& polygon = room.vertices;
    LayoutPlane lp;
    lp.kind = LayoutPlaneKind::kWall;
    double best_len = -1.0;
    for (size_t k = 0; k < room.edge_wall.size(); ++k) {
        if (room.edge_wall[k] != w) continue;
        const Eigen::Vector2d& a = polygon[k];
        const Eigen::Vector2d& b = polygon[(k + 1) % polygon.size()];
        if ((b - a).norm() > best_len) {
            best_len = (b - a).norm();
            lp.start_L = a;
            lp.end_L = b;
        }
    }
    Eigen::Vector2d n2 = w2.line.n;
    double d2 = w2.line.d;
    const Eigen::Vector2d dir(-n2.y(), n2.x());
    if (best_len < 0) {
        const Eigen::Vector2d p0 = -d2 * n2;
        lp.start_L = p0 + w2.tmin * dir;
        lp.end_L = p0 + w2.tmax * dir;
    }
    bool flip = false;
    if (best_len >= 0) {
        const Eigen::Vector2d e = lp.end_L - lp.start_L;
        flip = n2.dot(Eigen::Vector2d(-e.y(), e.x())) < 0;
    } else {
        const Eigen::Vector2d mid = 0.5 * (lp.start_L + lp.end_L);
        flip = !view.inRoom(mid + 0.2 * n2) && view.inRoom(mid - 0.2 * n2);
    }
    if (flip) {
        n2 = -n2;
        d2 = -d2;
    }
    lp.normal_L = Eigen::Vector3d(n2.x(), n2.y(), 0.0);
    lp.d_L = d2;
    return lp;
}

/// Step 7, the planes of the layout in L: the floor (id 0), the ceiling (id 1) when there is
/// one, then the walls from id 2, those on the polygon first in polygon order. A wall the
/// polygon follows along several edges of at least split_min_edge_m is one layout wall per such
/// edge (its longest first).
std::vector<LayoutPlane> layoutPlanes(const LayoutFrame& frame, const std::vector<Wall2>& walls2,
                                      const SnappedWalls& walls, const RoomPolygon& room,
                                      const GridInLayout& view, double split_min_edge_m) {
    std::vector<LayoutPlane> planes;
    LayoutPlane floor;
    floor.id = 0;
    floor.kind = LayoutPlaneKind::kFloor;
    floor.normal_L = Eigen::Vector3d::UnitZ();
    floor.d_L = 0.0;
    planes.push_back(floor);
    if (frame.have_ceiling) {
        LayoutPlane ceiling;
        ceiling.id = 1;
        ceiling.kind = LayoutPlaneKind::kCeiling;
        ceiling.normal_L = -Eigen::Vector3d::UnitZ();
        ceiling.d_L = frame.height;
        planes.push_back(ceiling);
    }
    std::vector<int> order;
    for (int w : room.edge_wall) {
        if (w >= 0 && std::find(order.begin(), order.end(), w) == order.end()) order.push_back(w);
    }
    for (size_t w = 0; w < walls2.size(); ++w) {
        if (std::find(order.begin(), order.end(), static_cast<int>(w)) == order.end()) {
            order.push_back(static_cast<int>(w));
        }
    }
    int next_id = 2;
    const std::vector<Eigen::Vector2d>& polygon = room.vertices;
    for (int w : order) {
        LayoutPlane lp = wallPlane(walls2[w], w, room, view);
        lp.id = next_id++;
        lp.manhattan_snapped = walls.snapped[w];
        planes.push_back(lp);
        // Further polygon edges on the same plane (coplanar walls apart, as the ends of a U's
        // arms) are walls of their own, on the same plane, when they are long enough.
        if (!(split_min_edge_m > 0.0)) continue;
        for (size_t k = 0; k < room.edge_wall.size(); ++k) {
            if (room.edge_wall[k] != w) continue;
            const Eigen::Vector2d& a = polygon[k];
            const Eigen::Vector2d& b = polygon[(k + 1) % polygon.size()];
            if ((b - a).norm() < split_min_edge_m || (a == lp.start_L && b == lp.end_L)) continue;
            LayoutPlane more = lp;
            more.id = next_id++;
            more.start_L = a;
            more.end_L = b;
            planes.push_back(more);
        }
    }
    return planes;
}

/// The fraction of the camera positions inside the room polygon (1 without camera positions, 0
/// without a polygon).
double pathInsideFraction(const std::vector<Eigen::Vector3d>& cameras_W,
                          const std::vector<Eigen::Vector2d>& polygon,
                          const Eigen::Isometry3d& T_L_W) {
    if (cameras_W.empty()) return 1.0;
    if (polygon.size() < 3) return 0.0;
    size_t inside = 0;
    for (const Eigen::Vector3d& c : cameras_W) {
        if (insidePolygon(polygon, (T_L_W * c).head<2>())) ++inside;
    }
    return static_cast<double>(inside) / cameras_W.size();
}

/// Checks the inputs of estimateLayout.
Status checkInputs(const std::vector<Fragment>& fragments,
                   const std::vector<FragmentPlanes>& planes,
                   const std::vector<Eigen::Isometry3d>& T_W_F, const LayoutConfig& config) {
    PLUMB_RETURN_IF_ERROR(config::validate(config));
    if (fragments.size() != planes.size() || fragments.size() != T_W_F.size()) {
        return invalidArgument(
            fmt::format("estimateLayout: {} fragments, {} plane sets and {} poses (must be equal)",
                        fragments.size(), planes.size(), T_W_F.size()));
    }
    if (fragments.empty()) return invalidArgument("estimateLayout: no fragments");
    for (size_t i = 0; i < T_W_F.size(); ++i) {
        if (!isRigid(T_W_F[i])) {
            return invalidArgument(
                fmt::format("estimateLayout: pose of fragment {} is not a finite rigid transform",
                            fragments[i].id));
        }
        if (planes[i].labels.size() != planes[i].sample_F.size()) {
            return invalidArgument(
                fmt::format("estimateLayout: plane set {} has {} labels for {} sample points", i,
                            planes[i].labels.size(), planes[i].sample_F.size()));
        }
    }
    return Status::ok();
}

}  // namespace

Result<LayoutEstimate> estimateLayout(const std::vector<Fragment>& fragments,
                                      const std::vector<FragmentPlanes>& planes,
                                      const std::vector<Eigen::Isometry3d>& T_W_F,
                                      const LayoutConfig& config) {
    const auto t_start = SteadyClock::now();
    PLUMB_RETURN_IF_ERROR(checkInputs(fragments, planes, T_W_F, config));
    LayoutEstimate est;
    LayoutDiagnostics& diag = est.diagnostics;
    diag.num_fragments = static_cast<int>(fragments.size());

    auto t0 = SteadyClock::now();
    const WorldPoints points = groupsInWorld(planes, T_W_F, config);  // 1
    diag.num_groups = static_cast<int>(points.groups.size());
    diag.num_hypotheses = diag.num_groups;
    if (points.groups.empty()) {
        return failedPrecondition("estimateLayout: no plane in any fragment");
    }
    std::vector<SupportedPlane> dominant =
        dominantPlanes(points.groups, fragments, config, &diag);  // 2
    diag.ms_clustering = msSince(t0);
    if (dominant.empty()) {
        return failedPrecondition("estimateLayout: no dominant plane with enough area");
    }
    const BaseChoice base = chooseBasePlane(dominant, points.all, T_W_F, config, &diag);  // 3
    const SupportedPlane& bp = dominant[base.index];
    const Eigen::Vector3d n_b = bp.n;

    t0 = SteadyClock::now();  // 4
    const std::vector<Eigen::Vector3d> cameras_W = cameraPositions(fragments, T_W_F);
    diag.num_camera_positions = static_cast<int>(cameras_W.size());
    Result<BaseGrid> grid_or =
        occupancyGrid(n_b, points, cameras_W, fragments, T_W_F, config, &diag);
    if (!grid_or.isOk()) return grid_or.status();
    const BaseGrid& grid = *grid_or;
    diag.ms_grid = msSince(t0);

    SightLines sight{points, {}};
    for (size_t i = 0; i < fragments.size(); ++i) {
        sight.viewpoints.push_back(fragmentViewpoint(fragments[i], T_W_F[i]));
    }
    WallSelection sel = selectWalls(dominant, base, grid, sight, config, &diag);  // 5
    const std::vector<int> wall_ids =
        boundingWalls(dominant, sel.wall_ids, n_b, grid, cameras_W, config, &diag);

    const SnappedWalls walls =
        snapWeakManhattan(dominant, wall_ids, n_b, grid, config, &diag);  // 6
    const double d_base = refitOffset(bp, n_b, config.refit_band_m);
    double d_opp = 0.0;
    if (sel.opposite >= 0) d_opp = refitOffset(dominant[sel.opposite], -n_b, config.refit_band_m);

    const LayoutFrame frame =  // 7
        layoutFrame(n_b, base.is_floor, d_base, sel.opposite >= 0, d_opp, points.all,
                    walls.ref >= 0 ? walls.n[walls.ref] : grid.e1, &diag);
    Layout& layout = est.layout;
    layout.T_W_L = frame.T_W_L;
    layout.ceiling_height_m = frame.have_ceiling ? frame.height : 0.0;
    const GridInLayout view{grid, bp, frame.T_W_L, frame.T_W_L.inverse()};
    const std::vector<Wall2> walls2 =
        wallLines(dominant, wall_ids, walls, frame.T_W_L, config.wall_piece_gap_m);
    const RoomPolygon room = roomPolygon(contourWallSequence(view, walls2, config), walls2, view);
    diag.polygon_method = room.from_walls ? "walls" : "contour";
    layout.room_polygon_L = room.vertices;
    diag.path_inside_fraction = pathInsideFraction(cameras_W, room.vertices, view.T_L_W);
    layout.planes = layoutPlanes(frame, walls2, walls, room, view, config.wall_split_min_edge_m);
    diag.ms_total = msSince(t_start);
    return est;
}

namespace {
nlohmann::json vec(const Eigen::Vector3d& v) {
    return nlohmann::json::array({v.x(), v.y(), v.z()});
}
}  // namespace

nlohmann::json toJson(const LayoutDiagnostics& d) {
    nlohmann::json j;
    j["num_fragments"] = d.num_fragments;
    j["num_groups"] = d.num_groups;
    j["num_hypotheses"] = d.num_hypotheses;
    j["num_clusters"] = d.num_clusters;
    j["dominant_planes"] = nlohmann::json::array();
    for (const DominantPlane& p : d.dominant_planes) {
        j["dominant_planes"].push_back({{"id", p.id},
                                        {"normal_W", vec(p.normal_W)},
                                        {"d_W", p.d_W},
                                        {"area_m2", p.area_m2},
                                        {"num_groups", p.num_groups},
                                        {"num_points", p.num_points},
                                        {"rms_m", p.rms_m},
                                        {"fragments", p.fragments}});
    }
    j["base_plane_id"] = d.base_plane_id;
    j["base_kind"] = d.base_kind;
    j["opposite_plane_id"] = d.opposite_plane_id;
    j["floor_inferred"] = d.floor_inferred;
    j["up_hint_W"] = vec(d.up_hint_W);
    j["grid"] = {{"width", d.grid_width},
                 {"height", d.grid_height},
                 {"occupied_cells", d.occupied_cells},
                 {"boundary_cells", d.boundary_cells}};
    j["walls"] = nlohmann::json::array();
    for (const WallDecision& w : d.walls) {
        j["walls"].push_back({{"plane_id", w.plane_id},
                              {"kept", w.kept},
                              {"abs_dot_base", w.abs_dot_base},
                              {"boundary_distance_m", w.boundary_distance_m},
                              {"top_gap_m", w.top_gap_m},
                              {"top_seen_fraction", w.top_seen_fraction},
                              {"camera_behind_fraction", w.camera_behind_fraction},
                              {"reason", w.reason}});
    }
    j["snapping"] = nlohmann::json::array();
    for (const SnapDecision& s : d.snapping) {
        j["snapping"].push_back({{"plane_id", s.plane_id},
                                 {"angle_to_reference_deg", s.angle_to_reference_deg},
                                 {"residual_deg", s.residual_deg},
                                 {"snapped", s.snapped},
                                 {"reference", s.reference},
                                 {"normal_before_W", vec(s.normal_before_W)}});
    }
    j["polygon_method"] = d.polygon_method;
    j["num_camera_positions"] = d.num_camera_positions;
    j["path_inside_fraction"] = d.path_inside_fraction;
    j["ms_clustering"] = d.ms_clustering;
    j["ms_grid"] = d.ms_grid;
    j["ms_total"] = d.ms_total;
    return j;
}

}  // namespace plumb::layout
