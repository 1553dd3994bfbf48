// SPDX-License-Identifier: Apache-2.0
#include "backend/global/global_registration.hpp"

#include <fmt/format.h>

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <nanoflann.hpp>
#include <numeric>
#include <optional>
#include <utility>

#include "backend/global/residuals.hpp"
#include "common/cloud/kd_tree.hpp"
#include "common/cloud/voxel_groups.hpp"
#include "common/config/config.hpp"
#include "common/core/parallel.hpp"
#include "common/geometry/polygon.hpp"

namespace plumb::global {

void describe(config::Schema& s, GlobalConfig& c) {
    s.field("voxel_size_m", c.voxel_size_m,
            "voxel size of the subsampled fragment clouds the energy is evaluated on", "m")
        .positive()
        .max(1.0);
    s.field("max_points_per_fragment", c.max_points_per_fragment,
            "at most this many subsampled points per fragment (evenly strided beyond)", "points")
        .min(1);
    s.field("frag_weight", c.frag_weight,
            "w1: weight of the mean fragment-to-fragment term E_frag relative to the mean layout "
            "term (lambda1 = w1 N_L / N_F)")
        .min(0.0);
    s.field("pair_weight", c.pair_weight,
            "w2: weight of the mean pairwise-prior term E_pair relative to the mean layout term "
            "(lambda2 = w2 N_L / N_P), for the priors of loops and of odometry edges registered "
            "by ICP")
        .min(0.0);
    s.field("tracked_pair_weight", c.tracked_pair_weight,
            "w2 of the pairwise priors whose information is the device tracker's (odometry edges "
            "within one tracking segment)")
        .min(0.0);
    s.field("use_layout", c.use_layout,
            "use the layout term E_layout (false: the Choi-style baseline E_frag + E_pair)");
    s.field("huber_delta_m", c.huber_delta_m,
            "Huber threshold of the point-to-plane residuals (E_layout, E_frag)", "m")
        .positive();
    s.field("frag_max_distance_m", c.frag_max_distance_m,
            "maximum distance of a fragment-fragment correspondence (eps_F)", "m")
        .positive();
    s.field("frag_max_normal_angle_deg", c.frag_max_normal_angle_deg,
            "maximum angle between the normals of a fragment-fragment correspondence", "deg")
        .range(0.0, 180.0);
    s.field("frag_pairs_from_overlap", c.frag_pairs_from_overlap,
            "besides the pair priors' pairs, use every fragment pair whose overlap is at least "
            "min_overlap");
    s.field("min_overlap", c.min_overlap,
            "minimum overlap (share of the smaller fragment's points with a correspondence) of a "
            "pair found by overlap")
        .range(0.0, 1.0);
    s.field("layout_max_distance_m", c.layout_max_distance_m,
            "maximum distance of a fragment point from the layout plane it is pulled onto (eps_L)",
            "m")
        .positive();
    s.field("layout_max_normal_angle_deg", c.layout_max_normal_angle_deg,
            "maximum angle between a point's normal and the layout plane's normal", "deg")
        .range(0.0, 180.0);
    s.field("wall_margin_m", c.wall_margin_m,
            "support region of a wall: how far beyond the wall segment's ends (and below the "
            "floor / above the ceiling) a point may lie (tau2)",
            "m")
        .min(0.0);
    s.field("floor_margin_m", c.floor_margin_m,
            "support region of floor and ceiling: how far outside the room polygon a point may "
            "lie",
            "m")
        .min(0.0);
    s.field("rounds", c.rounds,
            "correspondence rounds (re-established at the current poses before each inner loop)")
        .min(1);
    s.field("max_iterations", c.max_iterations,
            "maximum Levenberg-Marquardt iterations per round (inner loop)")
        .min(1);
    s.field("step_tolerance", c.step_tolerance,
            "an inner loop stops when the largest pose step falls below this (rad and m)")
        .positive();
    s.field("initial_damping", c.initial_damping,
            "initial Levenberg-Marquardt damping relative to the diagonal of the normal equations")
        .positive();
    s.field("num_threads", c.num_threads,
            "worker threads for correspondence search and accumulation (0 = TBB default); "
            "results do not depend on it")
        .min(0);
}

namespace {

constexpr double kDegToRad = M_PI / 180.0;

}  // namespace

// ---------------------------------------------------------------------------------------------
// GlobalCloud

// The tree keeps the points' buffer: a moved std::vector keeps it, so the tree stays valid when
// its GlobalCloud is moved.
struct GlobalCloud::Tree : PointKdTree<double> {
    using PointKdTree<double>::PointKdTree;
};

GlobalCloud::GlobalCloud() = default;
GlobalCloud::~GlobalCloud() = default;
GlobalCloud::GlobalCloud(GlobalCloud&&) noexcept = default;
GlobalCloud& GlobalCloud::operator=(GlobalCloud&&) noexcept = default;

bool GlobalCloud::nearest(const Eigen::Vector3d& query, uint32_t* index,
                          double* distance_sq) const {
    if (points_.empty() || !tree_) return false;
    tree_->index().knnSearch(query.data(), 1, index, distance_sq);
    return true;
}

bool GlobalCloud::nearestWithin(const Eigen::Vector3d& query, double max_distance_sq,
                                uint32_t* index, double* distance_sq, uint32_t hint) const {
    if (points_.empty() || !tree_) return false;
    nanoflann::KNNResultSet<double, uint32_t, size_t> result(1);
    result.init(index, distance_sq);
    // The search keeps only points closer than this.
    *distance_sq = tree_->searchBound(query, hint, max_distance_sq);
    tree_->index().findNeighbors(result, query.data(), nanoflann::SearchParams());
    return result.size() == 1 && *distance_sq < max_distance_sq;
}

Result<std::vector<GlobalCloud>> prepareClouds(const std::vector<Fragment>& fragments,
                                               const GlobalConfig& config) {
    if (!(config.voxel_size_m > 0.0)) return invalidArgument("global: voxel_size_m must be > 0");
    if (config.max_points_per_fragment < 1) {
        return invalidArgument("global: max_points_per_fragment must be >= 1");
    }
    for (size_t f = 0; f < fragments.size(); ++f) {
        const PointCloud& c = fragments[f].points_F;
        if (!c.empty() && !c.hasNormals()) {
            return invalidArgument(
                fmt::format("global: fragment {} has points without normals", f));
        }
        for (size_t k = 0; k < c.size(); ++k) {
            if (!c.points[k].allFinite() || !c.normals[k].allFinite()) {
                return invalidArgument(
                    fmt::format("global: fragment {} point {} is not finite", f, k));
            }
        }
    }
    std::vector<GlobalCloud> clouds(fragments.size());
    parallelFor(config.num_threads, fragments.size(), [&](size_t f) {
        const PointCloud& c = fragments[f].points_F;
        GlobalCloud& out = clouds[f];
        const VoxelGroups groups = groupByVoxel(c.points, config.voxel_size_m);
        std::vector<Eigen::Vector3d> pts, nrm;
        std::vector<uint32_t> src;
        for (size_t v = 0; v < groups.voxels(); ++v) {
            const uint32_t a = groups.start[v], b = groups.start[v + 1];
            Eigen::Vector3d sum_p = Eigen::Vector3d::Zero();
            Eigen::Vector3d sum_n = Eigen::Vector3d::Zero();
            for (uint32_t k = a; k < b; ++k) {
                sum_p += c.points[groups.order[k]].cast<double>();
                sum_n += c.normals[groups.order[k]].cast<double>();
            }
            const double count = static_cast<double>(b - a);
            const Eigen::Vector3d centroid = sum_p / count;
            const double nn = sum_n.norm();
            // A voxel whose normals cancel (thin structure seen from both sides) has no usable
            // orientation for point-to-plane terms.
            if (nn > 0.5 * count) {
                uint32_t best = groups.order[a];
                double best_d = std::numeric_limits<double>::infinity();
                for (uint32_t k = a; k < b; ++k) {
                    const double d =
                        (c.points[groups.order[k]].cast<double>() - centroid).squaredNorm();
                    if (d < best_d) {
                        best_d = d;
                        best = groups.order[k];
                    }
                }
                pts.push_back(centroid);
                nrm.push_back(sum_n / nn);
                src.push_back(best);
            }
        }
        const size_t max_points = static_cast<size_t>(config.max_points_per_fragment);
        if (pts.size() > max_points) {
            std::vector<Eigen::Vector3d> p2, n2;
            std::vector<uint32_t> s2;
            for (size_t k = 0; k < max_points; ++k) {
                const size_t idx = k * pts.size() / max_points;
                p2.push_back(pts[idx]);
                n2.push_back(nrm[idx]);
                s2.push_back(src[idx]);
            }
            pts.swap(p2);
            nrm.swap(n2);
            src.swap(s2);
        }
        out.points_ = std::move(pts);
        out.normals_ = std::move(nrm);
        out.source_index_ = std::move(src);
        if (!out.points_.empty()) out.tree_ = std::make_unique<GlobalCloud::Tree>(out.points_);
    });
    return clouds;
}

// ---------------------------------------------------------------------------------------------
// Layout support regions

namespace {

double pointSegmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a,
                            const Eigen::Vector2d& b) {
    const Eigen::Vector2d e = b - a;
    const double len_sq = e.squaredNorm();
    double s = len_sq > 0.0 ? (p - a).dot(e) / len_sq : 0.0;
    s = std::clamp(s, 0.0, 1.0);
    return (p - (a + s * e)).norm();
}

/// The layout prepared for correspondence search: planes in W, support regions in L.
struct PreparedLayout {
    struct Plane {
        HessianPlane world;
        LayoutPlaneKind kind = LayoutPlaneKind::kWall;
        Eigen::Vector2d a = Eigen::Vector2d::Zero();  // wall segment start (L)
        Eigen::Vector2d u = Eigen::Vector2d::Zero();  // unit direction along the wall (L)
        double length = 0.0;
    };
    Eigen::Isometry3d T_L_W = Eigen::Isometry3d::Identity();
    std::vector<Plane> planes;
    std::vector<Eigen::Vector2d> polygon;
    double height = 0.0;
    double cos_normal = 1.0;
    double max_distance = 0.0;
    double wall_margin = 0.0;
    double floor_margin = 0.0;

    bool inSupport(const Plane& plane, const Eigen::Vector3d& x_W) const {
        const Eigen::Vector3d x_L = T_L_W * x_W;
        if (plane.kind == LayoutPlaneKind::kWall) {
            if (plane.length > 0.0) {
                const double s = plane.u.dot(x_L.head<2>() - plane.a);
                if (s < -wall_margin || s > plane.length + wall_margin) return false;
            }
            if (height > 0.0 && (x_L.z() < -wall_margin || x_L.z() > height + wall_margin)) {
                return false;
            }
            return true;
        }
        if (polygon.size() < 3) return true;
        const Eigen::Vector2d xy = x_L.head<2>();
        if (insidePolygon(polygon, xy)) return true;
        for (size_t k = 0; k < polygon.size(); ++k) {
            if (pointSegmentDistance(xy, polygon[k], polygon[(k + 1) % polygon.size()]) <=
                floor_margin) {
                return true;
            }
        }
        return false;
    }

    /// The plane x (normal m, both in W) is pulled onto, -1 for none.
    int assign(const Eigen::Vector3d& x_W, const Eigen::Vector3d& m_W) const {
        int best = -1;
        double best_d = max_distance;
        for (size_t k = 0; k < planes.size(); ++k) {
            const Plane& pl = planes[k];
            const double d = std::abs(pl.world.signedDistance(x_W));
            if (d >= best_d) continue;
            if (pl.world.normal.dot(m_W) < cos_normal) continue;
            if (!inSupport(pl, x_W)) continue;
            best = static_cast<int>(k);
            best_d = d;
        }
        return best;
    }
};

Result<PreparedLayout> prepareLayout(const Layout& layout, const GlobalConfig& config) {
    PreparedLayout out;
    if (!lie::isValidPose(layout.T_W_L, 1e-6)) {
        return invalidArgument("global: the layout's T_W_L is not a valid pose");
    }
    out.T_L_W = layout.T_W_L.inverse();
    out.polygon = layout.room_polygon_L;
    for (const Eigen::Vector2d& v : out.polygon) {
        if (!v.allFinite()) return invalidArgument("global: the layout polygon is not finite");
    }
    out.height = layout.ceiling_height_m;
    if (!std::isfinite(out.height)) return invalidArgument("global: ceiling height not finite");
    out.cos_normal = std::cos(config.layout_max_normal_angle_deg * kDegToRad);
    out.max_distance = config.layout_max_distance_m;
    out.wall_margin = config.wall_margin_m;
    out.floor_margin = config.floor_margin_m;
    for (const LayoutPlane& lp : layout.planes) {
        if (!lp.normal_L.allFinite() || !std::isfinite(lp.d_L) ||
            std::abs(lp.normal_L.norm() - 1.0) > 1e-6) {
            return invalidArgument(
                fmt::format("global: layout plane {} has a non-unit or non-finite normal", lp.id));
        }
        PreparedLayout::Plane p;
        p.world = planeInWorld(layout, lp);
        p.kind = lp.kind;
        if (lp.kind == LayoutPlaneKind::kWall) {
            const Eigen::Vector2d e = lp.end_L - lp.start_L;
            if (!e.allFinite()) {
                return invalidArgument(fmt::format("global: wall {} segment not finite", lp.id));
            }
            p.a = lp.start_L;
            p.length = e.norm();
            p.u = p.length > 0.0 ? Eigen::Vector2d(e / p.length) : Eigen::Vector2d::Zero();
        }
        out.planes.push_back(p);
    }
    return out;
}

// ---------------------------------------------------------------------------------------------
// Correspondences

}  // namespace

// The pairs' correspondences are kept between calls (MatchHints), so their types are not local
// to this file's anonymous namespace.
struct FragMatch {
    uint32_t p = 0;  // point index in the source cloud (pair.from)
    uint32_t q = 0;  // point index in the target cloud (pair.to)
};

/// Correspondences of a fragment pair (both directions): from -> to and to -> from.
struct PairMatches {
    uint32_t a = 0;
    uint32_t b = 0;
    std::vector<FragMatch> a_to_b;
    std::vector<FragMatch> b_to_a;
    bool from_prior = false;
};

struct MatchHints::Pairs {
    std::vector<PairMatches> pairs;  ///< in (a, b) order
};
MatchHints::MatchHints() = default;
MatchHints::~MatchHints() = default;
MatchHints::MatchHints(MatchHints&&) noexcept = default;
MatchHints& MatchHints::operator=(MatchHints&&) noexcept = default;

namespace {

struct LayoutMatch {
    uint32_t p = 0;
    int plane = -1;
};

struct Correspondences {
    std::vector<std::vector<LayoutMatch>> layout;  // per fragment
    std::vector<PairMatches> pairs;                // kept pairs, in (a, b) order
};

/// Where a fragment's points lie at its current pose, coarsely: the world cells (edge at least
/// the correspondence distance) holding its points, sorted, each with its points; and every cell
/// within one cell of those. A point of another fragment closer than the correspondence distance
/// to one of these points lies in a `near` cell: points elsewhere need no search.
struct Occupancy {
    using Cell = std::array<int32_t, 3>;
    struct Occupied {
        Cell cell;
        uint32_t begin = 0;  ///< its points: order[begin, end)
        uint32_t end = 0;
    };
    std::vector<Occupied> cells;  ///< sorted by cell
    std::vector<uint32_t> order;  ///< point indices by cell, then index
    std::vector<Cell> near;       ///< occupied cells and their 26 neighbours, sorted
};

/// Cells of 25 cm, or the correspondence distance when that is larger.
double occupancyCell(const GlobalConfig& config) {
    return std::max(0.25, config.frag_max_distance_m);
}

Occupancy occupancyOf(const GlobalCloud& cloud, const Eigen::Isometry3d& T_W_F, double cell_m) {
    std::vector<std::pair<Occupancy::Cell, uint32_t>> keyed;
    keyed.reserve(cloud.size());
    const double inv = 1.0 / cell_m;
    for (size_t k = 0; k < cloud.size(); ++k) {
        const Eigen::Vector3d c = (T_W_F * cloud.points()[k]) * inv;
        keyed.push_back(
            {{static_cast<int32_t>(std::floor(c.x())), static_cast<int32_t>(std::floor(c.y())),
              static_cast<int32_t>(std::floor(c.z()))},
             static_cast<uint32_t>(k)});
    }
    std::sort(keyed.begin(), keyed.end());
    Occupancy o;
    o.order.reserve(keyed.size());
    for (size_t i = 0; i < keyed.size(); ++i) {
        if (i == 0 || keyed[i].first != keyed[i - 1].first)
            o.cells.push_back({keyed[i].first, static_cast<uint32_t>(i), 0});
        o.order.push_back(keyed[i].second);
        o.cells.back().end = static_cast<uint32_t>(i + 1);
    }
    for (const Occupancy::Occupied& occupied : o.cells) {
        const Occupancy::Cell& c = occupied.cell;
        for (int dx = -1; dx <= 1; ++dx)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dz = -1; dz <= 1; ++dz)
                    o.near.push_back({c[0] + dx, c[1] + dy, c[2] + dz});
    }
    std::sort(o.near.begin(), o.near.end());
    o.near.erase(std::unique(o.near.begin(), o.near.end()), o.near.end());
    return o;
}

/// Calls visit(cell) for every cell of `from` that is near `to`, in cell order.
template <typename Visit>
void forCellsNear(const Occupancy& from, const Occupancy& to, const Visit& visit) {
    auto it = to.near.begin();
    for (const Occupancy::Occupied& occupied : from.cells) {
        it = std::lower_bound(it, to.near.end(), occupied.cell);
        if (it == to.near.end()) return;
        if (*it == occupied.cell) visit(occupied);
    }
}

/// How many points of `from` lie in `to`'s near cells: an upper bound on the points of `from`
/// that can find a correspondence in `to`.
size_t pointsNear(const Occupancy& from, const Occupancy& to) {
    size_t count = 0;
    forCellsNear(from, to, [&](const Occupancy::Occupied& c) { count += c.end - c.begin; });
    return count;
}

/// Correspondences from -> to: each point of `from` with its nearest point of `to` within
/// frag_max_distance_m and frag_max_normal_angle_deg, in point order. Only points in cells near
/// `to` (the occupancies) are searched for: the others have no point of `to` that close. The
/// `previous` matches of this direction (in point order; may be null), from poses a step away,
/// start each point's search at its previous partner's distance: the same matches, sooner.
void matchDirection(const GlobalCloud& from, const GlobalCloud& to,
                    const Eigen::Isometry3d& T_W_from, const Eigen::Isometry3d& T_W_to,
                    const Occupancy& from_cells, const Occupancy& to_cells,
                    const GlobalConfig& config, const std::vector<FragMatch>* previous,
                    std::vector<FragMatch>* out) {
    out->clear();
    if (from.size() == 0 || to.size() == 0) return;
    std::vector<char> near(from.size(), 0);
    forCellsNear(from_cells, to_cells, [&](const Occupancy::Occupied& c) {
        for (uint32_t i = c.begin; i < c.end; ++i) near[from_cells.order[i]] = 1;
    });
    const Eigen::Isometry3d T_to_from = T_W_to.inverse() * T_W_from;
    const Eigen::Matrix3d R = T_to_from.linear();
    const double max_sq = config.frag_max_distance_m * config.frag_max_distance_m;
    const double cos_gate = std::cos(config.frag_max_normal_angle_deg * kDegToRad);
    size_t next_previous = 0;  // previous matches are in point order
    for (size_t k = 0; k < from.size(); ++k) {
        if (!near[k]) continue;
        uint32_t hint = std::numeric_limits<uint32_t>::max();
        if (previous != nullptr) {
            while (next_previous < previous->size() && (*previous)[next_previous].p < k)
                ++next_previous;
            if (next_previous < previous->size() && (*previous)[next_previous].p == k)
                hint = (*previous)[next_previous].q;
        }
        const Eigen::Vector3d query = T_to_from * from.points()[k];
        uint32_t idx = 0;
        double d_sq = 0.0;
        if (!to.nearestWithin(query, max_sq, &idx, &d_sq, hint)) continue;
        if ((R * from.normals()[k]).dot(to.normals()[idx]) < cos_gate) continue;
        out->push_back({static_cast<uint32_t>(k), idx});
    }
}

/// False only when pair (a, b) cannot pass the overlap test of `establish` at these poses: the
/// smaller fragment has fewer points near the other than min_overlap asks (and none at all when
/// min_overlap is 0). Exact: no pair that would be kept is dropped.
bool mayOverlap(const std::vector<Occupancy>& occupancy, const std::vector<GlobalCloud>& clouds,
                uint32_t a, uint32_t b, double min_overlap) {
    const bool a_smaller = clouds[a].size() <= clouds[b].size();
    const uint32_t small = a_smaller ? a : b;
    const size_t near = pointsNear(occupancy[small], occupancy[a_smaller ? b : a]);
    return near > 0 &&
           static_cast<double>(near) / static_cast<double>(clouds[small].size()) >= min_overlap;
}

/// C_i: each fragment's points with the layout plane they are pulled onto (none without a
/// layout), in point order.
std::vector<std::vector<LayoutMatch>> establishLayout(const std::vector<GlobalCloud>& clouds,
                                                      const std::vector<Eigen::Isometry3d>& T_W_F,
                                                      const PreparedLayout* layout,
                                                      const GlobalConfig& config) {
    const size_t n = clouds.size();
    std::vector<std::vector<LayoutMatch>> matches(n);
    if (layout == nullptr || layout->planes.empty()) return matches;
    parallelFor(config.num_threads, n, [&](size_t i) {
        const GlobalCloud& cl = clouds[i];
        const Eigen::Isometry3d& T = T_W_F[i];
        for (size_t k = 0; k < cl.size(); ++k) {
            const int plane = layout->assign(T * cl.points()[k], T.linear() * cl.normals()[k]);
            if (plane >= 0) matches[i].push_back({static_cast<uint32_t>(k), plane});
        }
    });
    return matches;
}

/// C_ij: the kept fragment pairs with their correspondences in both directions, in (a, b)
/// order. They do not depend on the layout.
std::vector<PairMatches> establishPairs(const std::vector<GlobalCloud>& clouds,
                                        const std::vector<Eigen::Isometry3d>& T_W_F,
                                        const std::vector<PairPrior>& priors,
                                        const GlobalConfig& config,
                                        const std::vector<PairMatches>* previous = nullptr) {
    const size_t n = clouds.size();
    std::vector<PairMatches> kept;
    // C_ij: candidate pairs = the priors' pairs plus pairs whose bounding spheres meet and whose
    // occupied cells leave room for the overlap test.
    std::vector<Occupancy> occupancy(n);
    parallelFor(config.num_threads, n, [&](size_t i) {
        occupancy[i] = occupancyOf(clouds[i], T_W_F[i], occupancyCell(config));
    });
    std::map<std::pair<uint32_t, uint32_t>, bool> candidates;  // value: from a prior
    for (const PairPrior& p : priors) {
        candidates[{std::min(p.i, p.j), std::max(p.i, p.j)}] = true;
    }
    if (config.frag_pairs_from_overlap) {
        std::vector<Eigen::Vector3d> centre(n, Eigen::Vector3d::Zero());
        std::vector<double> radius(n, 0.0);
        for (size_t i = 0; i < n; ++i) {
            const GlobalCloud& cl = clouds[i];
            if (cl.size() == 0) continue;
            Eigen::Vector3d sum = Eigen::Vector3d::Zero();
            for (const auto& p : cl.points()) sum += p;
            const Eigen::Vector3d mean = sum / static_cast<double>(cl.size());
            double r = 0.0;
            for (const auto& p : cl.points()) r = std::max(r, (p - mean).norm());
            centre[i] = T_W_F[i] * mean;
            radius[i] = r;
        }
        for (uint32_t a = 0; a < n; ++a) {
            for (uint32_t b = a + 1; b < n; ++b) {
                if (clouds[a].size() == 0 || clouds[b].size() == 0) continue;
                if ((centre[a] - centre[b]).norm() >
                    radius[a] + radius[b] + config.frag_max_distance_m) {
                    continue;
                }
                if (candidates.count({a, b}) == 0 &&
                    !mayOverlap(occupancy, clouds, a, b, config.min_overlap))
                    continue;  // it would be searched for nothing and dropped below
                candidates.emplace(std::make_pair(a, b), false);
            }
        }
    }
    std::vector<PairMatches> all;
    all.reserve(candidates.size());
    for (const auto& [key, from_prior] : candidates) {
        PairMatches pm;
        pm.a = key.first;
        pm.b = key.second;
        pm.from_prior = from_prior;
        all.push_back(std::move(pm));
    }
    parallelFor(config.num_threads, all.size(), [&](size_t k) {
        PairMatches& pm = all[k];
        // The pair's matches of the previous call, if it was kept (they are in (a, b) order).
        const PairMatches* before = nullptr;
        if (previous != nullptr) {
            const auto it =
                std::lower_bound(previous->begin(), previous->end(), pm,
                                 [](const PairMatches& x, const PairMatches& y) {
                                     return std::make_pair(x.a, x.b) < std::make_pair(y.a, y.b);
                                 });
            if (it != previous->end() && it->a == pm.a && it->b == pm.b) before = &*it;
        }
        matchDirection(clouds[pm.a], clouds[pm.b], T_W_F[pm.a], T_W_F[pm.b], occupancy[pm.a],
                       occupancy[pm.b], config, before != nullptr ? &before->a_to_b : nullptr,
                       &pm.a_to_b);
        matchDirection(clouds[pm.b], clouds[pm.a], T_W_F[pm.b], T_W_F[pm.a], occupancy[pm.b],
                       occupancy[pm.a], config, before != nullptr ? &before->b_to_a : nullptr,
                       &pm.b_to_a);
    });
    for (PairMatches& pm : all) {
        if (pm.a_to_b.empty() && pm.b_to_a.empty()) continue;
        if (!pm.from_prior) {
            const size_t na = clouds[pm.a].size();
            const size_t nb = clouds[pm.b].size();
            const double overlap =
                na <= nb ? static_cast<double>(pm.a_to_b.size()) / static_cast<double>(na)
                         : static_cast<double>(pm.b_to_a.size()) / static_cast<double>(nb);
            if (overlap < config.min_overlap) continue;
        }
        kept.push_back(std::move(pm));
    }
    return kept;
}

/// C at T_W_F; `previous` (may be null): the pairs' correspondences at nearby poses, which
/// only speed the search up.
Correspondences establish(const std::vector<GlobalCloud>& clouds,
                          const std::vector<Eigen::Isometry3d>& T_W_F,
                          const std::vector<PairPrior>& priors, const PreparedLayout* layout,
                          const GlobalConfig& config,
                          const std::vector<PairMatches>* previous = nullptr) {
    Correspondences c;
    c.layout = establishLayout(clouds, T_W_F, layout, config);
    c.pairs = establishPairs(clouds, T_W_F, priors, config, previous);
    return c;
}

// ---------------------------------------------------------------------------------------------
// Energy and normal equations

/// Contributions of one group of residuals to the normal equations: blocks of at most two
/// fragments (a, b).
struct GroupSystem {
    uint32_t a = 0;
    uint32_t b = 0;
    Matrix6d H_aa = Matrix6d::Zero();
    Matrix6d H_ab = Matrix6d::Zero();
    Matrix6d H_bb = Matrix6d::Zero();
    Vector6d b_a = Vector6d::Zero();
    Vector6d b_b = Vector6d::Zero();
    double cost = 0.0;  // Σ ρ (unscaled)
};

inline double huberWeight(double r, double delta, double* rho) {
    const double ar = std::abs(r);
    if (ar <= delta) {
        *rho = r * r;
        return 1.0;
    }
    *rho = 2.0 * delta * ar - delta * delta;
    return delta / ar;
}

/// Normalised information Λ̂ = Λ / n, n = PairPrior::count or trace(Λ_translation) / 3.
Matrix6d normalisedInformation(const PairPrior& prior) {
    const double n =
        prior.count > 0.0 ? prior.count : prior.information.bottomRightCorner<3, 3>().trace() / 3.0;
    return n > 0.0 ? Matrix6d(prior.information / n) : prior.information;
}

struct Problem {
    const std::vector<GlobalCloud>* clouds = nullptr;
    const std::vector<PairPrior>* priors = nullptr;
    std::vector<Matrix6d> info_hat;  // per prior: its w2 times Λ / n
    const PreparedLayout* layout = nullptr;
    const GlobalConfig* config = nullptr;
};

/// Evaluates E (and, when `system` is set, the Gauss-Newton system of the scaled energy) at
/// `T_W_F` for fixed correspondences.
EnergyTerms evaluate(const Problem& pb, const Correspondences& c,
                     const std::vector<Eigen::Isometry3d>& T_W_F,
                     std::vector<GroupSystem>* system) {
    const GlobalConfig& cfg = *pb.config;
    const size_t n_layout_groups = c.layout.size();
    const size_t n_pair_groups = c.pairs.size();
    const size_t n_prior_groups = pb.priors->size();
    std::vector<GroupSystem> groups(n_layout_groups + n_pair_groups + n_prior_groups);
    const bool want = system != nullptr;
    const double delta = cfg.huber_delta_m;

    // Layout groups: one per fragment, Eq. (8).
    parallelFor(cfg.num_threads, n_layout_groups, [&](size_t i) {
        GroupSystem& g = groups[i];
        g.a = g.b = static_cast<uint32_t>(i);
        const GlobalCloud& cl = (*pb.clouds)[i];
        RowJacobian J;
        for (const LayoutMatch& m : c.layout[i]) {
            const double r = layoutResidual(T_W_F[i], cl.points()[m.p],
                                            pb.layout->planes[static_cast<size_t>(m.plane)].world,
                                            want ? &J : nullptr);
            double rho = 0.0;
            const double w = huberWeight(r, delta, &rho);
            g.cost += rho;
            if (want) {
                g.H_aa.noalias() += w * J.transpose() * J;
                g.b_a.noalias() += w * r * J.transpose();
            }
        }
    });
    // Fragment pair groups, Eq. (9), both directions, from every point and normal of the
    // fragments they join in the world frame (a point has correspondences in several pairs).
    std::vector<char> joined(pb.clouds->size(), 0);
    for (const PairMatches& pm : c.pairs) joined[pm.a] = joined[pm.b] = 1;
    std::vector<std::vector<Eigen::Vector3d>> x_W(pb.clouds->size()), m_W(pb.clouds->size());
    parallelFor(cfg.num_threads, pb.clouds->size(), [&](size_t f) {
        if (!joined[f]) return;
        const GlobalCloud& cl = (*pb.clouds)[f];
        x_W[f].resize(cl.size());
        m_W[f].resize(cl.size());
        for (size_t k = 0; k < cl.size(); ++k) {
            x_W[f][k] = T_W_F[f] * cl.points()[k];
            m_W[f][k] = T_W_F[f].linear() * cl.normals()[k];
        }
    });
    parallelFor(cfg.num_threads, n_pair_groups, [&](size_t k) {
        const PairMatches& pm = c.pairs[k];
        GroupSystem& g = groups[n_layout_groups + k];
        g.a = pm.a;
        g.b = pm.b;
        // A residual's Jacobians are J and -J (fragResidual), so every term of H_ab, H_bb and
        // b_b is the matching term of H_aa or b_a negated or repeated, exactly (a product's
        // rounding does not depend on the signs): those three are the sums of H_aa and b_a,
        // negated or repeated, and only H_aa and b_a are accumulated.
        auto add = [&](uint32_t i, uint32_t j, const std::vector<FragMatch>& matches,
                       bool from_is_a) {
            for (const FragMatch& m : matches) {
                RowJacobian Ji, Jj;
                const double r = fragResidualWorld(x_W[i][m.p], x_W[j][m.q], m_W[j][m.q],
                                                   want ? &Ji : nullptr, want ? &Jj : nullptr);
                double rho = 0.0;
                const double w = huberWeight(r, delta, &rho);
                g.cost += rho;
                if (want) {
                    const RowJacobian& Ja = from_is_a ? Ji : Jj;
                    g.H_aa.noalias() += w * Ja.transpose() * Ja;
                    g.b_a.noalias() += w * r * Ja.transpose();
                }
            }
        };
        add(pm.a, pm.b, pm.a_to_b, true);
        add(pm.b, pm.a, pm.b_to_a, false);
        if (want) {
            g.H_ab = -g.H_aa;
            g.H_bb = g.H_aa;
            g.b_b = -g.b_a;
        }
    });
    // Pair priors, Eq. (10).
    parallelFor(cfg.num_threads, n_prior_groups, [&](size_t k) {
        const PairPrior& p = (*pb.priors)[k];
        GroupSystem& g = groups[n_layout_groups + n_pair_groups + k];
        g.a = p.i;
        g.b = p.j;
        Matrix6d Ji, Jj;
        const Vector6d e = pairResidual(T_W_F[p.i], T_W_F[p.j], p.T_i_j, want ? &Ji : nullptr,
                                        want ? &Jj : nullptr);
        const Matrix6d& L = pb.info_hat[k];
        g.cost = e.dot(L * e);
        if (want) {
            g.H_aa = Ji.transpose() * L * Ji;
            g.H_ab = Ji.transpose() * L * Jj;
            g.H_bb = Jj.transpose() * L * Jj;
            g.b_a = Ji.transpose() * L * e;
            g.b_b = Jj.transpose() * L * e;
        }
    });

    EnergyTerms e;
    for (const auto& l : c.layout) e.num_layout += l.size();
    for (const auto& pm : c.pairs) e.num_frag += pm.a_to_b.size() + pm.b_to_a.size();
    e.num_pair = n_prior_groups;
    const double s_layout = e.num_layout > 0 ? 1.0 / static_cast<double>(e.num_layout) : 0.0;
    const double s_frag = e.num_frag > 0 ? cfg.frag_weight / static_cast<double>(e.num_frag) : 0.0;
    // Each prior's w2 is in its Λ̂ (makeProblem).
    const double s_pair = e.num_pair > 0 ? 1.0 / static_cast<double>(e.num_pair) : 0.0;
    for (size_t k = 0; k < groups.size(); ++k) {
        const double s = k < n_layout_groups                   ? s_layout
                         : k < n_layout_groups + n_pair_groups ? s_frag
                                                               : s_pair;
        double& term = k < n_layout_groups                   ? e.layout
                       : k < n_layout_groups + n_pair_groups ? e.frag
                                                             : e.pair;
        term += s * groups[k].cost;
        if (want) {
            GroupSystem& g = groups[k];
            g.H_aa *= s;
            g.H_ab *= s;
            g.H_bb *= s;
            g.b_a *= s;
            g.b_b *= s;
        }
    }
    e.total = e.layout + e.frag + e.pair;
    if (want) *system = std::move(groups);
    return e;
}

/// Solves (H + mu diag(H)) xi = -b over fragments 1..n-1. False when the factorisation fails.
bool solveStep(const std::vector<GroupSystem>& groups, size_t n, double mu,
               std::vector<Vector6d>* xi) {
    const Eigen::Index m = static_cast<Eigen::Index>(6 * (n - 1));
    std::vector<Matrix6d> diag(n, Matrix6d::Zero());
    std::vector<Vector6d> rhs(n, Vector6d::Zero());
    std::map<std::pair<uint32_t, uint32_t>, Matrix6d> off;
    for (const GroupSystem& g : groups) {
        diag[g.a] += g.H_aa;
        rhs[g.a] += g.b_a;
        if (g.a != g.b) {
            diag[g.b] += g.H_bb;
            rhs[g.b] += g.b_b;
            if (g.a == 0 || g.b == 0) continue;
            if (g.a < g.b) {
                auto it = off.try_emplace({g.a, g.b}, Matrix6d::Zero()).first;
                it->second += g.H_ab;
            } else {
                auto it = off.try_emplace({g.b, g.a}, Matrix6d::Zero()).first;
                it->second += g.H_ab.transpose();
            }
        }
    }
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(36 * (n + 2 * off.size()));
    Eigen::VectorXd b(m);
    for (size_t i = 1; i < n; ++i) {
        const Eigen::Index o = static_cast<Eigen::Index>(6 * (i - 1));
        Matrix6d D = diag[i];
        for (int k = 0; k < 6; ++k) {
            // Damping on the diagonal; an unconstrained fragment gets an identity block (its
            // right-hand side is zero, so its step is zero).
            const double dk = D(k, k);
            D(k, k) = dk > 0.0 ? dk * (1.0 + mu) : 1.0;
        }
        for (int r = 0; r < 6; ++r) {
            for (int col = 0; col < 6; ++col) triplets.emplace_back(o + r, o + col, D(r, col));
        }
        b.segment<6>(o) = rhs[i];
    }
    for (const auto& [key, block] : off) {
        const Eigen::Index oi = static_cast<Eigen::Index>(6 * (key.first - 1));
        const Eigen::Index oj = static_cast<Eigen::Index>(6 * (key.second - 1));
        for (int r = 0; r < 6; ++r) {
            for (int col = 0; col < 6; ++col) {
                triplets.emplace_back(oi + r, oj + col, block(r, col));
                triplets.emplace_back(oj + col, oi + r, block(r, col));
            }
        }
    }
    Eigen::SparseMatrix<double> A(m, m);
    A.setFromTriplets(triplets.begin(), triplets.end());
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(A);
    if (ldlt.info() != Eigen::Success) return false;
    const Eigen::VectorXd x = ldlt.solve(-b);
    if (ldlt.info() != Eigen::Success || !x.allFinite()) return false;
    xi->assign(n, Vector6d::Zero());
    for (size_t i = 1; i < n; ++i) {
        (*xi)[i] = x.segment<6>(static_cast<Eigen::Index>(6 * (i - 1)));
    }
    return true;
}

Status validateInputs(size_t n, const std::vector<Eigen::Isometry3d>& T_W_F,
                      const std::vector<PairPrior>& priors, const GlobalConfig& config) {
    if (T_W_F.size() != n) {
        return invalidArgument(fmt::format("global: {} poses for {} fragments", T_W_F.size(), n));
    }
    for (size_t i = 0; i < n; ++i) {
        if (!lie::isValidPose(T_W_F[i], 1e-6)) {
            return invalidArgument(fmt::format("global: pose of fragment {} is not valid", i));
        }
    }
    for (size_t k = 0; k < priors.size(); ++k) {
        const PairPrior& p = priors[k];
        if (p.i >= n || p.j >= n || p.i == p.j) {
            return invalidArgument(fmt::format(
                "global: pair prior {} ({}, {}) is not a pair of distinct fragments < {}", k, p.i,
                p.j, n));
        }
        if (!lie::isValidPose(p.T_i_j, 1e-6)) {
            return invalidArgument(fmt::format("global: pair prior {} transform not valid", k));
        }
        if (!std::isfinite(p.count) || p.count < 0.0) {
            return invalidArgument(
                fmt::format("global: pair prior {} count {} not valid", k, p.count));
        }
        if (!p.information.allFinite() ||
            (p.information - p.information.transpose()).cwiseAbs().maxCoeff() >
                1e-9 * std::max(1.0, p.information.cwiseAbs().maxCoeff())) {
            return invalidArgument(
                fmt::format("global: pair prior {} information is not finite and symmetric", k));
        }
    }
    const Status s = config::validate(config);
    if (!s.isOk()) return invalidArgument("global: " + s.message());
    return Status::ok();
}

/// The problem of refinePoses()/evaluateEnergy(); `prepared` holds the prepared layout it points
/// to (when the layout is used).
Result<Problem> makeProblem(const std::vector<GlobalCloud>& clouds,
                            const std::vector<PairPrior>& priors, const Layout& layout,
                            const GlobalConfig& config, std::optional<PreparedLayout>* prepared) {
    if (config.use_layout && !layout.planes.empty()) {
        Result<PreparedLayout> pl = prepareLayout(layout, config);
        if (!pl.isOk()) return pl.status();
        *prepared = std::move(pl).value();
    }
    Problem pb;
    pb.clouds = &clouds;
    pb.priors = &priors;
    pb.layout = prepared->has_value() ? &**prepared : nullptr;
    pb.config = &config;
    for (const PairPrior& p : priors) {
        const double w2 = p.tracked ? config.tracked_pair_weight : config.pair_weight;
        pb.info_hat.push_back(w2 * normalisedInformation(p));
    }
    return pb;
}

}  // namespace

std::vector<std::vector<int>> layoutAssignments(const std::vector<GlobalCloud>& clouds,
                                                const std::vector<Eigen::Isometry3d>& T_W_F,
                                                const Layout& layout, const GlobalConfig& config) {
    std::vector<std::vector<int>> out(clouds.size());
    Result<PreparedLayout> pl = prepareLayout(layout, config);
    for (size_t i = 0; i < clouds.size(); ++i) {
        out[i].assign(clouds[i].size(), -1);
        if (!pl.isOk() || i >= T_W_F.size()) continue;
        for (size_t k = 0; k < clouds[i].size(); ++k) {
            out[i][k] = pl->assign(T_W_F[i] * clouds[i].points()[k],
                                   T_W_F[i].linear() * clouds[i].normals()[k]);
        }
    }
    return out;
}

namespace {

/// refinePoses() of problem `pb` from T_W_F (more than one fragment); `first`, when given, are
/// the correspondences the first round would establish at T_W_F.
GlobalResult refineRounds(const Problem& pb, std::vector<Eigen::Isometry3d> T_W_F,
                          std::optional<Correspondences> first, MatchHints* hints) {
    const std::vector<GlobalCloud>& clouds = *pb.clouds;
    const GlobalConfig& config = *pb.config;
    const size_t n = clouds.size();
    GlobalResult result;
    // The last search's pairs: hints for the next one.
    std::vector<PairMatches> previous;
    if (hints != nullptr && hints->pairs) previous = std::move(hints->pairs->pairs);
    for (int round = 0; round < config.rounds; ++round) {
        Correspondences corr;
        if (round == 0 && first) {
            corr = std::move(*first);
        } else {
            corr = establish(clouds, T_W_F, *pb.priors, pb.layout, config, &previous);
        }
        std::vector<GroupSystem> system;
        EnergyTerms energy = evaluate(pb, corr, T_W_F, &system);
        if (round == 0) result.initial = energy;
        result.num_frag_pairs = corr.pairs.size();
        result.rounds = round + 1;
        double mu = config.initial_damping;
        bool converged = false;
        for (int it = 0; it < config.max_iterations; ++it) {
            GlobalIteration rec;
            rec.round = round;
            rec.iteration = it;
            rec.damping = mu;
            std::vector<Vector6d> xi;
            if (!solveStep(system, n, mu, &xi)) {
                rec.energy = energy;
                result.iterations.push_back(rec);
                mu *= 10.0;
                if (mu > 1e8) break;
                continue;
            }
            std::vector<Eigen::Isometry3d> candidate = T_W_F;
            for (size_t i = 1; i < n; ++i) {
                rec.max_step_rad = std::max(rec.max_step_rad, xi[i].head<3>().norm());
                rec.max_step_m = std::max(rec.max_step_m, xi[i].tail<3>().norm());
                candidate[i] = lie::orthonormalized(lie::expSE3(xi[i]) * T_W_F[i]);
            }
            std::vector<GroupSystem> candidate_system;
            const EnergyTerms candidate_energy = evaluate(pb, corr, candidate, &candidate_system);
            // LM acceptance: E never increases within the inner loop.
            if (candidate_energy.total <= energy.total) {
                rec.accepted = true;
                T_W_F = std::move(candidate);
                system = std::move(candidate_system);
                energy = candidate_energy;
                mu = std::max(mu / 3.0, 1e-12);
            } else {
                mu *= 10.0;
            }
            rec.energy = energy;
            result.iterations.push_back(rec);
            if (rec.accepted &&
                std::max(rec.max_step_rad, rec.max_step_m) < config.step_tolerance) {
                converged = true;
                break;
            }
            if (mu > 1e8) break;
        }
        result.final = energy;
        result.converged = converged;
        const double nl = static_cast<double>(energy.num_layout);
        result.lambda1 = energy.num_frag > 0
                             ? config.frag_weight * nl / static_cast<double>(energy.num_frag)
                             : 0.0;
        result.lambda2 = energy.num_pair > 0
                             ? config.pair_weight * nl / static_cast<double>(energy.num_pair)
                             : 0.0;
        previous = std::move(corr.pairs);
    }
    if (hints != nullptr) {
        if (!hints->pairs) hints->pairs = std::make_unique<MatchHints::Pairs>();
        hints->pairs->pairs = std::move(previous);
    }
    result.T_W_F = std::move(T_W_F);
    return result;
}

/// E_R at T_W_F with two layouts, the fragment pairs' correspondences established once;
/// `second_corr` (may be null) receives the correspondences with the second layout.
Result<std::array<EnergyTerms, 2>> evaluateTwo(const std::vector<GlobalCloud>& clouds,
                                               const std::vector<Eigen::Isometry3d>& T_W_F,
                                               const std::vector<PairPrior>& priors,
                                               const Layout& first, const Layout& second,
                                               const GlobalConfig& config,
                                               Correspondences* second_corr,
                                               const std::vector<PairMatches>* hints = nullptr) {
    PLUMB_RETURN_IF_ERROR(validateInputs(clouds.size(), T_W_F, priors, config));
    std::array<EnergyTerms, 2> energies;
    Correspondences corr;
    corr.pairs = establishPairs(clouds, T_W_F, priors, config, hints);
    const std::array<const Layout*, 2> layouts{&first, &second};
    for (size_t k = 0; k < layouts.size(); ++k) {
        std::optional<PreparedLayout> prepared;
        Result<Problem> problem = makeProblem(clouds, priors, *layouts[k], config, &prepared);
        if (!problem.isOk()) return problem.status();
        corr.layout = establishLayout(clouds, T_W_F, problem->layout, config);
        energies[k] = evaluate(problem.value(), corr, T_W_F, nullptr);
    }
    if (second_corr != nullptr) *second_corr = std::move(corr);
    return energies;
}

/// refinePoses() from T_W_F; `first`, when given, are the correspondences its first round would
/// establish at T_W_F.
Result<GlobalResult> refineFrom(const std::vector<GlobalCloud>& clouds,
                                std::vector<Eigen::Isometry3d> T_W_F,
                                const std::vector<PairPrior>& priors, const Layout& layout,
                                const GlobalConfig& config, std::optional<Correspondences> first,
                                MatchHints* hints) {
    PLUMB_RETURN_IF_ERROR(validateInputs(clouds.size(), T_W_F, priors, config));
    if (clouds.size() <= 1) {
        GlobalResult result;
        result.T_W_F = std::move(T_W_F);
        result.converged = true;
        return result;
    }
    std::optional<PreparedLayout> prepared;
    Result<Problem> problem = makeProblem(clouds, priors, layout, config, &prepared);
    if (!problem.isOk()) return problem.status();
    return refineRounds(problem.value(), std::move(T_W_F), std::move(first), hints);
}

}  // namespace

Result<GlobalResult> refinePoses(const std::vector<GlobalCloud>& clouds,
                                 std::vector<Eigen::Isometry3d> T_W_F,
                                 const std::vector<PairPrior>& priors, const Layout& layout,
                                 const GlobalConfig& config, MatchHints* hints) {
    return refineFrom(clouds, std::move(T_W_F), priors, layout, config, std::nullopt, hints);
}

Result<LayoutStepOutcome> refinePosesAfterLayoutStep(const std::vector<GlobalCloud>& clouds,
                                                     const std::vector<Eigen::Isometry3d>& T_W_F,
                                                     const std::vector<PairPrior>& priors,
                                                     const Layout& previous, const Layout& layout,
                                                     const GlobalConfig& config,
                                                     MatchHints* hints) {
    LayoutStepOutcome out;
    Correspondences corr;
    const std::vector<PairMatches>* before =
        hints != nullptr && hints->pairs ? &hints->pairs->pairs : nullptr;
    Result<std::array<EnergyTerms, 2>> e =
        evaluateTwo(clouds, T_W_F, priors, previous, layout, config, &corr, before);
    if (!e.isOk()) return e.status();
    out.energies = e.value();
    if (out.energies[1].total > out.energies[0].total) return out;
    Result<GlobalResult> step =
        refineFrom(clouds, T_W_F, priors, layout, config, std::move(corr), hints);
    if (!step.isOk()) return step.status();
    out.step = std::move(step).value();
    return out;
}

Result<EnergyTerms> evaluateEnergy(const std::vector<GlobalCloud>& clouds,
                                   const std::vector<Eigen::Isometry3d>& T_W_F,
                                   const std::vector<PairPrior>& priors, const Layout& layout,
                                   const GlobalConfig& config) {
    PLUMB_RETURN_IF_ERROR(validateInputs(clouds.size(), T_W_F, priors, config));
    std::optional<PreparedLayout> prepared;
    Result<Problem> problem = makeProblem(clouds, priors, layout, config, &prepared);
    if (!problem.isOk()) return problem.status();
    const Problem& pb = problem.value();
    const Correspondences corr = establish(clouds, T_W_F, priors, pb.layout, config);
    return evaluate(pb, corr, T_W_F, nullptr);
}

Result<std::array<EnergyTerms, 2>> evaluateEnergies(const std::vector<GlobalCloud>& clouds,
                                                    const std::vector<Eigen::Isometry3d>& T_W_F,
                                                    const std::vector<PairPrior>& priors,
                                                    const Layout& first, const Layout& second,
                                                    const GlobalConfig& config) {
    return evaluateTwo(clouds, T_W_F, priors, first, second, config, nullptr);
}

Result<GlobalResult> refinePoses(const std::vector<Fragment>& fragments,
                                 std::vector<Eigen::Isometry3d> T_W_F,
                                 const std::vector<PairPrior>& priors, const Layout& layout,
                                 const GlobalConfig& config) {
    Result<std::vector<GlobalCloud>> clouds = prepareClouds(fragments, config);
    if (!clouds.isOk()) return clouds.status();
    return refinePoses(clouds.value(), std::move(T_W_F), priors, layout, config);
}

}  // namespace plumb::global
