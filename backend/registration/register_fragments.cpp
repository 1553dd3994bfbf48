// SPDX-License-Identifier: Apache-2.0
#include "backend/registration/register_fragments.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <future>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <tuple>
#include <utility>

#include "backend/registration/cloud_ops.hpp"
#include "common/geometry/lie.hpp"

namespace plumb::registration {

using posegraph::PoseGraphEdge;

void describe(config::Schema& s, LiveConfig& c) {
    s.field("min_predicted_overlap", c.min_predicted_overlap,
            "live: fraction of the new fragment near an earlier one to make it a candidate")
        .range(0.0, 1.0);
    s.field("candidate_distance_m", c.candidate_distance_m,
            "live: proximity radius of the predicted overlap (tolerates drift)", "m")
        .positive();
    s.field("max_candidates", c.max_candidates, "live: at most this many loop candidates").min(0);
}

void describe(config::Schema& s, RegistrationConfig& c) {
    s.section("prepare", c.prepare, "downsampling, normals and FPFH");
    s.section("icp", c.icp,
              "multi-scale ICP: coloured where both fragments carry colour, point-to-plane "
              "otherwise");
    s.section("ransac", c.ransac, "FPFH matching and RANSAC for loop closures");
    s.section("guided", c.guided, "odometry-guided loop search within a tracking segment");
    s.section("pose_graph", c.pose_graph, "line-process pose graph");
    s.section("live", c.live, "live mode candidate selection");
    s.field("min_overlap", c.min_overlap,
            "loop closures need this fraction of the smaller fragment within tau")
        .range(0.0, 1.0);
    s.field("max_loop_rotation_deviation_deg", c.max_loop_rotation_deviation_deg,
            "loop closures within a tracking segment that turn further than this from the "
            "odometry are rejected (a bare room matches itself after a quarter or half turn); "
            "0 = no check",
            "deg")
        .range(0.0, 180.0);
    s.field("loop_icp_iterations", c.loop_icp_iterations,
            "coarse ICP iterations when verifying a RANSAC loop candidate")
        .min(1);
    s.field("ransac_only_when_unguided", c.ransac_only_when_unguided,
            "within a tracking segment, FPFH + RANSAC runs only when no odometry-guided start "
            "passes the overlap test in agreement with the odometry");
    s.field("candidate_drift_sigmas", c.candidate_drift_sigmas,
            "offline, pairs of one tracking segment are registered only when min_overlap of the "
            "smaller fragment lies within tau + this many deviations of the drift prior of the "
            "other at the odometry poses (pairs that could not pass the overlap test unless the "
            "odometry drifted further); 0 = every pair")
        .min(0.0);
    s.field("max_candidates_per_fragment", c.max_candidates_per_fragment,
            "offline, at most this many loop candidates of its own segment per fragment, those "
            "of the highest overlap predicted at the odometry (0 = no limit)")
        .min(0);
    s.field("plane_information", c.plane_information,
            "edges weigh by the point-to-plane information over their overlap, scaled to the "
            "trace of Choi's point-to-point information (false: Choi's, which trusts a slide "
            "along what the overlap does not pin)");
    s.field("tracker_odometry", c.tracker_odometry,
            "odometry edges keep the tracked transform, weighed by the tracker's information, "
            "where fragments carry it (false: fragment-to-fragment ICP and Choi's information)");
    s.field("refinement_pass", c.refinement_pass,
            "re-align surviving edges by ICP from the optimised poses and optimise again");
    s.field("refinement_settled_m", c.refinement_settled_m,
            "the refinement pass leaves an edge as registered when the optimised poses agree "
            "with its transform within this and refinement_settled_deg (0 = re-align every edge)",
            "m")
        .min(0.0);
    s.field("refinement_settled_deg", c.refinement_settled_deg,
            "rotation part of refinement_settled_m (0 = re-align every edge)", "deg")
        .min(0.0);
    s.field("seed", c.seed, "seed of the RANSAC generators");
    s.field("num_threads", c.num_threads, "worker threads, 0 = all; results do not depend on it")
        .min(0);
}

namespace {

/// Wall-clock seconds since the last lap (or construction).
class Stopwatch {
  public:
    double lap() {
        const auto now = std::chrono::steady_clock::now();
        const double s = std::chrono::duration<double>(now - last_).count();
        last_ = now;
        return s;
    }

  private:
    std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

uint64_t splitmix64(uint64_t x) {
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}

uint64_t pairSeed(uint64_t seed, uint32_t i, uint32_t j) {
    return splitmix64(splitmix64(seed) ^ (static_cast<uint64_t>(i) << 32 | j));
}

std::string fmt2(const char* f, double a, double b) {
    char buf[200];
    std::snprintf(buf, sizeof(buf), f, a, b);
    return buf;
}

/// The per-pair configuration: inner loops single-threaded (pairs run in parallel).
RegistrationConfig innerConfig(const RegistrationConfig& c) {
    RegistrationConfig inner = c;
    inner.icp.num_threads = 1;
    inner.prepare.num_threads = 1;
    inner.ransac.num_threads = 1;
    return inner;
}

double tauOf(const RegistrationConfig& c) { return c.pose_graph.max_correspondence_distance_m; }

/// L scaled so that its translation block has the trace of Choi's Λ over `num_correspondences`
/// correspondences (3 per correspondence, at least 3: see pose_graph.hpp); the identity when L
/// has no translation information.
Matrix6d scaledToChoiTrace(Matrix6d L, double num_correspondences) {
    L = 0.5 * (L + L.transpose());
    const double trace = L.bottomRightCorner<3, 3>().trace();
    if (!(trace > 0.0)) return Matrix6d::Identity();
    return L * (3.0 * std::max(1.0, num_correspondences) / trace);
}

/// The edge's transform, information and figures from an evaluated alignment: the point-to-plane
/// information (c.plane_information, where the overlap has at least 6 correspondences with
/// normals) or Choi's Λ.
void setFromPair(PoseGraphEdge& e, const PairResult& eval, const RegistrationConfig& c) {
    e.T_source_target = eval.T_source_target;
    e.num_correspondences = eval.num_correspondences;
    e.overlap = eval.overlap;
    e.inlier_rmse_m = eval.inlier_rmse_m;
    if (c.plane_information && eval.num_correspondences >= 6 &&
        eval.plane_information.bottomRightCorner<3, 3>().trace() > 0.0) {
        e.information = scaledToChoiTrace(eval.plane_information, eval.num_correspondences);
        e.information_source = PoseGraphEdge::Information::kPlane;
    } else {
        e.information = eval.information;
        e.information_source = PoseGraphEdge::Information::kChoi;
    }
}

/// The tracker's information H (left perturbation in the source frame) as the edge's
/// target-frame information Ad(T)^T H Ad(T).
Matrix6d trackerInformation(const Matrix6d& H, const Eigen::Isometry3d& T_source_target) {
    const Matrix6d Ad = lie::adjointSE3(T_source_target);
    const Matrix6d L = Ad.transpose() * H * Ad;
    return 0.5 * (L + L.transpose());
}

/// Whether the odometry edge into `target` takes the tracker's information.
bool useTracker(const Fragment& source, const Fragment& target, const RegistrationConfig& c) {
    return c.tracker_odometry && source.segment == target.segment && target.id == source.id + 1 &&
           target.odometry_information.bottomRightCorner<3, 3>().trace() > 0.0;
}

}  // namespace

PoseGraphEdge odometryEdge(const FragmentIndex& s, const FragmentIndex& t, const Fragment& source,
                           const Fragment& target, const RegistrationConfig& c, bool* icp_failed) {
    PoseGraphEdge e;
    e.source = s.id;
    e.target = t.id;
    e.kind = PoseGraphEdge::Kind::kOdometry;
    const Eigen::Isometry3d T_odo = source.T_W_F.inverse() * target.T_W_F;
    *icp_failed = false;
    if (useTracker(source, target, c)) {
        const PairResult eval = evaluateAlignment(s, t, T_odo, tauOf(c), c.icp.num_threads);
        setFromPair(e, eval, c);
        e.information = trackerInformation(target.odometry_information, T_odo);
        e.information_source = PoseGraphEdge::Information::kTracker;
        e.reason = "tracked transform, tracker's information";
        return e;
    }
    const PairResult icp = multiScaleIcp(s, t, T_odo, c.icp);
    Eigen::Isometry3d T = T_odo;
    *icp_failed = !icp.success;
    if (icp.success) {
        T = icp.T_source_target;
    } else {
        e.reason = "ICP failed (" + icp.reason + "); odometry transform kept";
    }
    PairResult eval = evaluateAlignment(s, t, T, tauOf(c), c.icp.num_threads);
    if (eval.num_correspondences < 6) {
        // No usable overlap: keep the chain connected with a weak unit information.
        eval.information = Matrix6d::Identity();
        if (e.reason.empty()) e.reason = "no overlap; unit information";
    }
    setFromPair(e, eval, c);
    return e;
}

namespace {

enum class LoopOutcome { kRansacFailed, kRejected, kTurned, kMoved, kAccepted };

/// A verified loop candidate that is not kept: its alignment figures, kept = false, the reason.
void reject(PoseGraphEdge& e, const PairResult& eval, const RegistrationConfig& c,
            std::string reason) {
    setFromPair(e, eval, c);
    e.kept = false;
    e.line_process = 0.0;
    e.reason = std::move(reason);
}

/// Mean of the fragment's prepared points (its frame).
Eigen::Vector3d centroidOf(const FragmentIndex& f) {
    const PointCloud& pts = f.coarse.cloud();
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3f& p : pts.points) c += p.cast<double>();
    if (!pts.empty()) c /= static_cast<double>(pts.size());
    return c;
}

/// The angle between two rotations, degrees.
double turnedDeg(const Eigen::Isometry3d& from, const Eigen::Isometry3d& to) {
    return lie::rotationAngle(from.inverse() * to) * 180.0 / std::numbers::pi;
}

/// Whether T stays in the guided search's window around the odometry: it turns no further than
/// max_rotation_deg from it and moves the target's centroid `c` no further than radius_m (per
/// axis, plus one bin).
bool withinWindow(const Eigen::Vector3d& c, const Eigen::Isometry3d& T,
                  const Eigen::Isometry3d& T_odo, const GuidedSearchConfig& g) {
    return turnedDeg(T_odo, T) <= g.max_rotation_deg &&
           (T * c - T_odo * c).cwiseAbs().maxCoeff() <= g.radius_m + g.bin_m;
}

/// Loop-closure candidate (s, t). Starting alignments: for a pair of one tracking segment
/// (`T_odo` set), the odometry-guided search's vote peaks, and FPFH + RANSAC's (only when no
/// guided start passes, with c.ransac_only_when_unguided; before them otherwise, and alone across
/// segments). Each is refined by coarse ICP. Within a segment a candidate must agree with the
/// odometry (turned by at most max_loop_rotation_deviation_deg, moved by at most
/// guided.max_offset_sigmas deviations of the drift prior) and they are ranked by overlap times
/// the prior; across segments by overlap. The best goes on to the overlap test and the
/// multi-scale refinement. `ransac_ran` (optional) is set when FPFH + RANSAC ran.
LoopOutcome loopEdge(const FragmentIndex& s, const FragmentIndex& t, const RegistrationConfig& c,
                     const std::optional<Eigen::Isometry3d>& T_odo, PoseGraphEdge* out,
                     bool* ransac_ran = nullptr) {
    struct Start {
        Eigen::Isometry3d T;
        const char* method;
        bool guided;
    };
    const Eigen::Vector3d centroid = centroidOf(t);
    const double sigma = odometryPriorSigma(c.guided, t.id > s.id ? t.id - s.id : s.id - t.id);
    struct Verified {
        PairResult eval;
        const char* method = "";
        bool guided = false;
        double score = 0.0;        ///< overlap, times the odometry prior within a segment
        std::string disagreement;  ///< why it disagrees with the odometry (empty: it agrees)
        LoopOutcome outcome = LoopOutcome::kAccepted;  ///< kTurned / kMoved when it disagrees
    };
    std::optional<Verified> best, first;
    auto verify = [&](const Start& start) {
        Eigen::Isometry3d T = start.T;
        // A start turned from the odometry by more than twice the allowed deviation is not one
        // ICP turns back: it is verified where it is, and the odometry check rejects it.
        const bool hopeless = T_odo && c.max_loop_rotation_deviation_deg > 0.0 &&
                              turnedDeg(*T_odo, T) > 2.0 * c.max_loop_rotation_deviation_deg;
        if (!hopeless && !s.levels.empty() && !t.levels.empty() && !c.icp.voxel_sizes_m.empty()) {
            const PairResult icp = icpPointToPlane(s.levels[0], t.levels[0].cloud(), T,
                                                   c.icp.distance_factor * c.icp.voxel_sizes_m[0],
                                                   c.loop_icp_iterations, c.icp.relative_change,
                                                   c.icp.min_normal_spread, c.icp.num_threads);
            if (icp.success) T = icp.T_source_target;
        }
        // A guided start that ICP slid out of the search window (along a wall, most often) is
        // no longer what the votes found.
        if (start.guided && !withinWindow(centroid, T, *T_odo, c.guided)) return;
        Verified v{evaluateAlignment(s, t, T, tauOf(c), c.icp.num_threads),
                   start.method,
                   start.guided,
                   0.0,
                   {},
                   LoopOutcome::kAccepted};
        v.score = v.eval.overlap;
        if (T_odo) {
            // Walls, floor and ceiling match as well after a quarter turn or a slide of a metre,
            // and the odometry drifts by a few degrees and centimetres per fragment: it is a
            // prior on the drift (and ranks a slide along a wall below the truth).
            const double turned_deg = turnedDeg(*T_odo, T);
            const double moved_m = (T * centroid - *T_odo * centroid).norm();
            const double max_moved_m = c.guided.max_offset_sigmas * sigma;
            if (c.max_loop_rotation_deviation_deg > 0.0 &&
                turned_deg > c.max_loop_rotation_deviation_deg) {
                v.disagreement = fmt2("rejected: turned %.1f deg from the odometry (max %.0f)",
                                      turned_deg, c.max_loop_rotation_deviation_deg);
                v.outcome = LoopOutcome::kTurned;
            } else if (c.guided.max_offset_sigmas > 0.0 && moved_m > max_moved_m) {
                v.disagreement = fmt2("rejected: moved %.2f m from the odometry (max %.2f)",
                                      moved_m, max_moved_m);
                v.outcome = LoopOutcome::kMoved;
            }
            v.score *= std::exp(-0.5 * moved_m * moved_m / (sigma * sigma));
        }
        if (!first) first = v;
        if (v.disagreement.empty() && (!best || v.score > best->score)) best = std::move(v);
    };
    auto verifyRansac = [&]() {
        if (ransac_ran != nullptr) *ransac_ran = true;
        const PairResult r = ransacFeatureMatching(s, t, c.ransac, pairSeed(c.seed, s.id, t.id));
        if (r.success) verify({r.T_source_target, "FPFH + RANSAC", false});
    };
    const bool guided = T_odo && c.guided.enabled;
    const bool ransac_first = !guided || !c.ransac_only_when_unguided;
    if (ransac_first) verifyRansac();
    if (guided) {
        for (const GuidedCandidate& g : guidedCandidates(s, t, *T_odo, sigma, c.guided))
            verify({g.T_source_target, "odometry-guided search", true});
    }
    if (!ransac_first && !(best && best->eval.overlap >= c.min_overlap)) verifyRansac();
    if (!first) return LoopOutcome::kRansacFailed;  // no start, or every guided start slid away
    PoseGraphEdge& e = *out;
    e.source = s.id;
    e.target = t.id;
    e.kind = PoseGraphEdge::Kind::kLoop;
    if (!best) {
        reject(e, first->eval, c, first->disagreement);
        return first->outcome;
    }
    PairResult eval = best->eval;
    if (eval.overlap < c.min_overlap) {
        reject(e, eval, c, fmt2("rejected: overlap %.3f < %.2f", eval.overlap, c.min_overlap));
        return LoopOutcome::kRejected;
    }
    const PairResult fine = multiScaleIcp(s, t, eval.T_source_target, c.icp);
    if (fine.success &&
        (!best->guided || withinWindow(centroid, fine.T_source_target, *T_odo, c.guided))) {
        const PairResult refined =
            evaluateAlignment(s, t, fine.T_source_target, tauOf(c), c.icp.num_threads);
        if (refined.overlap >= c.min_overlap) eval = refined;
    }
    setFromPair(e, eval, c);
    e.reason = std::string("found by ") + best->method;
    return LoopOutcome::kAccepted;
}

}  // namespace

PoseGraphEdge registerLoopPair(const FragmentIndex& source, const FragmentIndex& target,
                               const RegistrationConfig& config,
                               const std::optional<Eigen::Isometry3d>& T_odometry) {
    PoseGraphEdge e;
    e.source = source.id;
    e.target = target.id;
    e.kind = PoseGraphEdge::Kind::kLoop;
    if (loopEdge(source, target, config, T_odometry, &e) == LoopOutcome::kRansacFailed) {
        e.kept = false;
        e.line_process = 0.0;
        e.reason = "rejected: no alignment to verify (RANSAC failed, no guided start)";
    }
    return e;
}

std::optional<Eigen::Isometry3d> odometryBetween(const Fragment& a, const Fragment& b) {
    if (a.segment != b.segment) return std::nullopt;
    return a.T_W_F.inverse() * b.T_W_F;
}

namespace {

bool edgeLess(const PoseGraphEdge& a, const PoseGraphEdge& b) {
    return a.source != b.source ? a.source < b.source : a.target < b.target;
}

Status checkInputs(const std::vector<Fragment>& fragments,
                   const std::vector<PreparedFragment>& prepared, const RegistrationConfig& c) {
    if (fragments.empty()) return invalidArgument("registration: no fragments");
    if (fragments.size() != prepared.size()) {
        return invalidArgument("registration: " + std::to_string(fragments.size()) +
                               " fragments but " + std::to_string(prepared.size()) +
                               " prepared fragments");
    }
    for (size_t i = 0; i < fragments.size(); ++i) {
        if (fragments[i].id != i || prepared[i].id != i) {
            return invalidArgument("registration: fragment " + std::to_string(i) + " has id " +
                                   std::to_string(fragments[i].id) + " (prepared " +
                                   std::to_string(prepared[i].id) + "); ids must be 0..n-1");
        }
        if (!fragments[i].T_W_F.matrix().allFinite()) {
            return invalidArgument("registration: fragment " + std::to_string(i) +
                                   " has a non-finite odometry pose");
        }
    }
    if (c.icp.voxel_sizes_m.empty() || c.icp.iterations.size() != c.icp.voxel_sizes_m.size()) {
        return invalidArgument(
            "registration: icp.voxel_sizes_m and icp.iterations must be non-empty and of equal "
            "length");
    }
    return Status::ok();
}

std::vector<FragmentIndex> buildIndices(const std::vector<Fragment>& fragments,
                                        const std::vector<PreparedFragment>& prepared,
                                        const RegistrationConfig& c) {
    std::vector<FragmentIndex> idx(fragments.size());
    const RegistrationConfig inner = innerConfig(c);
    detail::parallelFor(c.num_threads, fragments.size(), [&](size_t i) {
        idx[i] = buildFragmentIndex(fragments[i], prepared[i], inner.icp);
    });
    return idx;
}

/// True when the poses of `graph` place e's target where e's transform does, within the
/// refinement pass's settled tolerances.
bool settled(const PoseGraph& graph, const PoseGraphEdge& e, const RegistrationConfig& c) {
    if (!(c.refinement_settled_m > 0.0 && c.refinement_settled_deg > 0.0)) return false;
    const Eigen::Isometry3d now = graph.T_W_F[e.source].inverse() * graph.T_W_F[e.target];
    const Eigen::Isometry3d delta = e.T_source_target.inverse() * now;
    return delta.translation().norm() <= c.refinement_settled_m &&
           turnedDeg(e.T_source_target, now) <= c.refinement_settled_deg;
}

/// The refinement pass; returns how many edges it re-aligned and how many it left settled.
std::pair<int, int> refineWithIndex(PoseGraph& graph, const std::vector<const FragmentIndex*>& idx,
                                    const RegistrationConfig& c, const ProgressCallback& progress) {
    const RegistrationConfig inner = innerConfig(c);
    std::vector<size_t> todo;
    int num_settled = 0;
    for (size_t k = 0; k < graph.edges.size(); ++k) {
        // An edge with the tracker's information keeps the tracked transform: ICP would slide
        // it along what the tracker says the geometry leaves free.
        PoseGraphEdge& e = graph.edges[k];
        if (!e.kept || e.information_source == PoseGraphEdge::Information::kTracker) continue;
        if (settled(graph, e, c)) {
            e.line_process = 1.0;
            ++num_settled;
            report(progress);
            continue;
        }
        todo.push_back(k);
    }
    detail::parallelFor(c.num_threads, todo.size(), [&](size_t n) {
        PoseGraphEdge& e = graph.edges[todo[n]];
        const FragmentIndex& s = *idx[e.source];
        const FragmentIndex& t = *idx[e.target];
        const Eigen::Isometry3d init = graph.T_W_F[e.source].inverse() * graph.T_W_F[e.target];
        const PairResult icp = multiScaleIcp(s, t, init, inner.icp);
        if (icp.success) {
            const PairResult eval =
                evaluateAlignment(s, t, icp.T_source_target, tauOf(inner), inner.icp.num_threads);
            if (e.kind == PoseGraphEdge::Kind::kLoop && eval.overlap < c.min_overlap) {
                setFromPair(e, eval, c);
                e.kept = false;
                e.reason = fmt2("refinement: overlap %.3f < %.2f", eval.overlap, c.min_overlap);
            } else if (eval.num_correspondences >= 6) {
                setFromPair(e, eval, c);
            }
        }
        e.line_process = 1.0;
        report(progress);
    });
    return {static_cast<int>(todo.size()), num_settled};
}

Result<RegistrationOutcome> finishGraph(PoseGraph graph,
                                        const std::vector<const FragmentIndex*>& idx,
                                        const RegistrationConfig& c, const PairStats& stats,
                                        const ProgressCallback& progress) {
    RegistrationOutcome out;
    out.stats = stats;
    Stopwatch watch;
    Result<posegraph::PoseGraphReport> first = posegraph::optimisePoseGraph(graph, c.pose_graph);
    if (!first.isOk()) return first.status();
    out.first = *first;
    out.optimise_seconds = watch.lap();
    if (c.refinement_pass) {
        std::tie(out.refinement_realigned, out.refinement_settled) =
            refineWithIndex(graph, idx, c, progress);
        out.refinement_seconds = watch.lap();
        Result<posegraph::PoseGraphReport> second =
            posegraph::optimisePoseGraph(graph, c.pose_graph);
        if (!second.isOk()) return second.status();
        out.refined = *second;
        out.refined_ran = true;
        out.optimise_seconds += watch.lap();
    }
    out.graph = std::move(graph);
    return out;
}

/// The box of `f`'s prepared points in the world at its odometry pose T_W_F.
Eigen::AlignedBox3d worldBox(const Fragment& f, const FragmentIndex& idx) {
    Eigen::AlignedBox3d box;
    for (const Eigen::Vector3f& p : idx.coarse.cloud().points)
        box.extend(f.T_W_F * p.cast<double>());
    return box;
}

/// The pairs the offline stage registers, in (i, j) order: every consecutive pair, every pair of
/// different segments, and the pairs of one segment that could overlap
/// (RegistrationConfig::candidate_drift_sigmas), at most max_candidates_per_fragment of them per
/// later fragment; `skipped` counts the others.
std::vector<std::pair<uint32_t, uint32_t>> candidatePairs(const std::vector<Fragment>& fragments,
                                                          const std::vector<FragmentIndex>& idx,
                                                          const RegistrationConfig& c,
                                                          int* skipped) {
    const uint32_t n = static_cast<uint32_t>(fragments.size());
    std::vector<std::pair<uint32_t, uint32_t>> all;
    for (uint32_t i = 0; i < n; ++i)
        for (uint32_t j = i + 1; j < n; ++j) all.emplace_back(i, j);
    // Overlap of each loop candidate of one segment predicted at the odometry; consecutive pairs
    // and pairs of different segments are always registered (kAlways, above any overlap).
    constexpr double kAlways = 2.0;
    std::vector<double> predicted(all.size(), kAlways);
    // Without the translation check (guided.max_offset_sigmas = 0) loops may lie anywhere from
    // the odometry: every pair is registered.
    if (c.candidate_drift_sigmas > 0.0 && c.guided.max_offset_sigmas > 0.0) {
        std::vector<Eigen::AlignedBox3d> boxes(n);
        for (uint32_t i = 0; i < n; ++i) boxes[i] = worldBox(fragments[i], idx[i]);
        detail::parallelFor(c.num_threads, all.size(), [&](size_t k) {
            const auto [i, j] = all[k];
            const std::optional<Eigen::Isometry3d> T_odo =
                odometryBetween(fragments[i], fragments[j]);
            if (j == i + 1 || !T_odo) return;
            const double radius =
                tauOf(c) + c.candidate_drift_sigmas * odometryPriorSigma(c.guided, j - i);
            // Boxes farther apart than the radius share no point within it.
            const bool apart = boxes[i].isEmpty() || boxes[j].isEmpty() ||
                               boxes[i].exteriorDistance(boxes[j]) > radius;
            predicted[k] =
                apart ? 0.0 : evaluateAlignment(idx[i], idx[j], *T_odo, radius, 1).overlap;
        });
    }
    // Per later fragment, the candidates of its segment that could pass, most overlap first.
    std::vector<std::vector<size_t>> by_target(n);
    for (size_t k = 0; k < all.size(); ++k)
        if (predicted[k] >= c.min_overlap) by_target[all[k].second].push_back(k);
    std::vector<char> keep(all.size(), 0);
    for (std::vector<size_t>& ks : by_target) {
        std::stable_sort(ks.begin(), ks.end(),
                         [&](size_t a, size_t b) { return predicted[a] > predicted[b]; });
        size_t loops = 0;
        for (const size_t k : ks) {
            const bool always = predicted[k] == kAlways;
            if (!always && c.max_candidates_per_fragment > 0 &&
                loops >= static_cast<size_t>(c.max_candidates_per_fragment))
                continue;
            if (!always) ++loops;
            keep[k] = 1;
        }
    }
    std::vector<std::pair<uint32_t, uint32_t>> pairs;
    *skipped = 0;
    for (size_t k = 0; k < all.size(); ++k) {
        if (keep[k]) {
            pairs.push_back(all[k]);
        } else {
            ++*skipped;
        }
    }
    return pairs;
}

std::vector<const FragmentIndex*> pointers(const std::vector<FragmentIndex>& idx) {
    std::vector<const FragmentIndex*> p;
    for (const FragmentIndex& f : idx) p.push_back(&f);
    return p;
}

}  // namespace

namespace {

/// buildPoseGraph on checked inputs and their indices.
PoseGraph buildPoseGraphWith(const std::vector<Fragment>& fragments,
                             const std::vector<FragmentIndex>& idx,
                             const RegistrationConfig& config, const ProgressCallback& progress,
                             PairStats* stats_out) {
    const RegistrationConfig inner = innerConfig(config);
    int skipped = 0;
    const std::vector<std::pair<uint32_t, uint32_t>> pairs =
        candidatePairs(fragments, idx, config, &skipped);
    std::vector<std::optional<PoseGraphEdge>> edges(pairs.size());
    std::vector<int> outcome(pairs.size(), 0);  // 0 odo ok, 1 odo icp failed, 2.. loop outcomes
    std::vector<char> ransac_ran(pairs.size(), 0);
    detail::parallelFor(config.num_threads, pairs.size(), [&](size_t k) {
        const auto [i, j] = pairs[k];
        if (j == i + 1) {
            bool failed = false;
            edges[k] = odometryEdge(idx[i], idx[j], fragments[i], fragments[j], inner, &failed);
            outcome[k] = failed ? 1 : 0;
        } else {
            PoseGraphEdge e;
            bool ran = false;
            const LoopOutcome o = loopEdge(idx[i], idx[j], inner,
                                           odometryBetween(fragments[i], fragments[j]), &e, &ran);
            outcome[k] = 2 + static_cast<int>(o);
            ransac_ran[k] = ran ? 1 : 0;
            if (o != LoopOutcome::kRansacFailed) edges[k] = std::move(e);
        }
        report(progress);
    });
    PoseGraph graph;
    for (const Fragment& f : fragments) graph.T_W_F.push_back(f.T_W_F);
    PairStats stats;
    stats.loop_pairs_skipped = skipped;
    for (size_t k = 0; k < pairs.size(); ++k) {
        stats.ransac_runs += ransac_ran[k];
        switch (outcome[k]) {
            case 0:
                ++stats.odometry_pairs;
                break;
            case 1:
                ++stats.odometry_pairs;
                ++stats.odometry_icp_failed;
                break;
            case 2 + static_cast<int>(LoopOutcome::kRansacFailed):
                ++stats.loop_pairs_tried;
                ++stats.ransac_failed;
                break;
            case 2 + static_cast<int>(LoopOutcome::kRejected):
                ++stats.loop_pairs_tried;
                ++stats.overlap_rejected;
                break;
            case 2 + static_cast<int>(LoopOutcome::kTurned):
                ++stats.loop_pairs_tried;
                ++stats.rotation_rejected;
                break;
            case 2 + static_cast<int>(LoopOutcome::kMoved):
                ++stats.loop_pairs_tried;
                ++stats.translation_rejected;
                break;
            default:
                ++stats.loop_pairs_tried;
                ++stats.loops_accepted;
                break;
        }
        if (edges[k]) graph.edges.push_back(std::move(*edges[k]));
    }
    std::stable_sort(graph.edges.begin(), graph.edges.end(), edgeLess);
    if (stats_out != nullptr) *stats_out = stats;
    return graph;
}

}  // namespace

Result<PoseGraph> buildPoseGraph(const std::vector<Fragment>& fragments,
                                 const std::vector<PreparedFragment>& prepared,
                                 const RegistrationConfig& config, const ProgressCallback& progress,
                                 PairStats* stats_out) {
    PLUMB_RETURN_IF_ERROR(checkInputs(fragments, prepared, config));
    const std::vector<FragmentIndex> idx = buildIndices(fragments, prepared, config);
    return buildPoseGraphWith(fragments, idx, config, progress, stats_out);
}

Status refineEdges(PoseGraph& graph, const std::vector<Fragment>& fragments,
                   const std::vector<PreparedFragment>& prepared, const RegistrationConfig& config,
                   const ProgressCallback& progress) {
    PLUMB_RETURN_IF_ERROR(checkInputs(fragments, prepared, config));
    if (graph.T_W_F.size() != fragments.size()) {
        return invalidArgument("refinement: the graph has " + std::to_string(graph.T_W_F.size()) +
                               " nodes for " + std::to_string(fragments.size()) + " fragments");
    }
    for (const PoseGraphEdge& e : graph.edges) {
        if (e.source >= fragments.size() || e.target >= fragments.size()) {
            return invalidArgument("refinement: an edge names a missing fragment");
        }
    }
    const std::vector<FragmentIndex> idx = buildIndices(fragments, prepared, config);
    refineWithIndex(graph, pointers(idx), config, progress);
    return Status::ok();
}

Result<RegistrationOutcome> registerFragments(const std::vector<Fragment>& fragments,
                                              const std::vector<PreparedFragment>& prepared,
                                              const RegistrationConfig& config,
                                              const ProgressCallback& progress) {
    PLUMB_RETURN_IF_ERROR(checkInputs(fragments, prepared, config));
    PairStats stats;
    Stopwatch watch;
    const std::vector<FragmentIndex> idx = buildIndices(fragments, prepared, config);
    const double index_seconds = watch.lap();
    PoseGraph graph = buildPoseGraphWith(fragments, idx, config, progress, &stats);
    const double pairs_seconds = watch.lap();
    Result<RegistrationOutcome> out =
        finishGraph(std::move(graph), pointers(idx), config, stats, progress);
    if (out.isOk()) {
        out->index_seconds = index_seconds;
        out->pairs_seconds = pairs_seconds;
    }
    return out;
}

// ---- LiveRegistrar ----

LiveRegistrar::LiveRegistrar(RegistrationConfig config, TaskRunner run_optimisation)
    : config_(std::move(config)), run_optimisation_(std::move(run_optimisation)) {}

LiveRegistrar::~LiveRegistrar() { waitBackground(); }

void LiveRegistrar::waitBackground() {
    if (!background_.valid()) return;
    std::vector<Eigen::Isometry3d> poses = background_.get();
    // The optimisation ran on a snapshot of the graph with as many nodes as it has now (every
    // change to the graph waits for it first).
    if (poses.size() == graph_.T_W_F.size()) graph_.T_W_F = std::move(poses);
}

std::vector<Eigen::Isometry3d> LiveRegistrar::poses() {
    waitBackground();
    return graph_.T_W_F;
}

PoseGraph LiveRegistrar::graph() {
    waitBackground();
    return graph_;
}

Status LiveRegistrar::addFragment(Fragment fragment) {
    if (fragment.id != fragments_.size()) {
        return invalidArgument("live registration: expected fragment " +
                               std::to_string(fragments_.size()) + ", got " +
                               std::to_string(fragment.id));
    }
    if (config_.icp.voxel_sizes_m.empty() ||
        config_.icp.iterations.size() != config_.icp.voxel_sizes_m.size()) {
        return invalidArgument("live registration: icp levels and iterations differ in length");
    }
    Result<PreparedFragment> prepared = prepareFragment(fragment, config_.prepare);
    if (!prepared.isOk()) return prepared.status();
    auto index = std::make_unique<FragmentIndex>(
        buildFragmentIndex(fragment, prepared.value(), config_.icp));
    waitBackground();  // decisions below use the poses of the finished optimisation

    const uint32_t k = fragment.id;
    const RegistrationConfig inner = innerConfig(config_);
    if (k == 0) {
        graph_.T_W_F.push_back(fragment.T_W_F);
    } else {
        bool failed = false;
        PoseGraphEdge odo =
            odometryEdge(*index_.back(), *index, fragments_.back(), fragment, inner, &failed);
        ++stats_.odometry_pairs;
        if (failed) ++stats_.odometry_icp_failed;
        graph_.T_W_F.push_back(graph_.T_W_F.back() * odo.T_source_target);
        graph_.edges.push_back(std::move(odo));

        // Candidates by predicted overlap under the current estimates.
        const Eigen::Isometry3d& T_W_k = graph_.T_W_F.back();
        const PointCloud& pts = index->coarse.cloud();
        const float r2 = static_cast<float>(config_.live.candidate_distance_m *
                                            config_.live.candidate_distance_m);
        std::vector<std::pair<double, uint32_t>> scored;
        for (uint32_t j = 0; j + 1 < k; ++j) {
            const Eigen::Isometry3d T_jk = graph_.T_W_F[j].inverse() * T_W_k;
            const Eigen::Matrix3f R = T_jk.rotation().cast<float>();
            const Eigen::Vector3f t = T_jk.translation().cast<float>();
            size_t near = 0;
            for (const Eigen::Vector3f& p : pts.points) {
                uint32_t idx = 0;
                float d2 = 0.0f;
                if (index_[j]->coarse.nearest(R * p + t, r2, &idx, &d2)) ++near;
            }
            const double predicted =
                pts.empty() ? 0.0 : static_cast<double>(near) / static_cast<double>(pts.size());
            if (predicted >= config_.live.min_predicted_overlap) scored.emplace_back(predicted, j);
        }
        std::sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) {
            return a.first != b.first ? a.first > b.first : a.second < b.second;
        });
        if (scored.size() > static_cast<size_t>(config_.live.max_candidates)) {
            scored.resize(static_cast<size_t>(config_.live.max_candidates));
        }
        std::sort(scored.begin(), scored.end(),
                  [](const auto& a, const auto& b) { return a.second < b.second; });
        std::vector<std::optional<PoseGraphEdge>> loops(scored.size());
        std::vector<LoopOutcome> outcomes(scored.size(), LoopOutcome::kRansacFailed);
        std::vector<char> ransac_ran(scored.size(), 0);
        detail::parallelFor(config_.num_threads, scored.size(), [&](size_t c) {
            PoseGraphEdge e;
            const uint32_t j = scored[c].second;
            bool ran = false;
            outcomes[c] = loopEdge(*index_[j], *index, inner,
                                   odometryBetween(fragments_[j], fragment), &e, &ran);
            ransac_ran[c] = ran ? 1 : 0;
            if (outcomes[c] != LoopOutcome::kRansacFailed) loops[c] = std::move(e);
        });
        for (size_t c = 0; c < scored.size(); ++c) {
            ++stats_.loop_pairs_tried;
            stats_.ransac_runs += ransac_ran[c];
            if (outcomes[c] == LoopOutcome::kRansacFailed) ++stats_.ransac_failed;
            if (outcomes[c] == LoopOutcome::kRejected) ++stats_.overlap_rejected;
            if (outcomes[c] == LoopOutcome::kTurned) ++stats_.rotation_rejected;
            if (outcomes[c] == LoopOutcome::kMoved) ++stats_.translation_rejected;
            if (outcomes[c] == LoopOutcome::kAccepted) ++stats_.loops_accepted;
            if (loops[c]) graph_.edges.push_back(std::move(*loops[c]));
        }
        std::stable_sort(graph_.edges.begin(), graph_.edges.end(), edgeLess);
    }
    fragments_.push_back(std::move(fragment));
    prepared_.push_back(std::move(prepared.value()));
    index_.push_back(std::move(index));

    // Re-optimisation of a snapshot, run by the program's runner (or here); its poses are
    // adopted at the next wait.
    PoseGraph snapshot = graph_;
    const posegraph::PoseGraphConfig pg = config_.pose_graph;
    auto task = std::make_shared<std::packaged_task<std::vector<Eigen::Isometry3d>()>>(
        [snapshot = std::move(snapshot), pg]() mutable {
            // On failure the snapshot's poses are returned unchanged.
            (void)posegraph::optimisePoseGraph(snapshot, pg);
            return snapshot.T_W_F;
        });
    background_ = task->get_future();
    if (run_optimisation_) {
        run_optimisation_([task] { (*task)(); });
    } else {
        (*task)();
    }
    return Status::ok();
}

Result<RegistrationOutcome> LiveRegistrar::finish(const ProgressCallback& progress) {
    waitBackground();
    if (fragments_.empty()) return failedPrecondition("live registration: no fragments added");
    std::vector<const FragmentIndex*> idx;
    for (const auto& p : index_) idx.push_back(p.get());
    return finishGraph(graph_, idx, config_, stats_, progress);
}

}  // namespace plumb::registration
