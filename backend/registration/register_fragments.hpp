// SPDX-License-Identifier: Apache-2.0
#pragma once

// Initial registration of fragments (the paper's §3.1 after Choi, Zhou, Koltun CVPR 2015;
// reference §3.2-3.7):
//   1. consecutive pairs (i, i+1): multi-scale ICP initialised from odometry (coloured ICP when
//      both fragments carry colour, point-to-plane otherwise; IcpConfig::colour);
//   2. non-consecutive pairs: FPFH matching + seeded RANSAC + ICP refinement, accepted when at
//      least `min_overlap` of the smaller fragment lies within τ of the other;
//   3. a pose graph with line processes (backend/posegraph/pose_graph.hpp) that prunes wrong
//      loop closures by itself;
//   4. a refinement pass: every surviving edge is re-aligned by multi-scale ICP from the
//      optimised relative pose and the graph optimised again.
// Offline (buildPoseGraph / registerFragments: all pairs after capture) and live (LiveRegistrar:
// each arriving fragment against candidates chosen by predicted overlap, the graph re-optimised
// by a task the program runs where it likes) modes. Edge convention: see pose_graph.hpp (T_W_target
// ≈ T_W_source * T_s_t).
//
// Determinism: every pair is a pure function of its two fragments, the configuration and a seed
// derived from (seed, source, target); pairs run in parallel but their results are gathered by
// index, so outputs are identical for any thread count and run.

#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "backend/posegraph/pose_graph.hpp"
#include "backend/registration/guided_search.hpp"
#include "backend/registration/pair_registration.hpp"
#include "backend/registration/prepared_fragment.hpp"
#include "common/config/schema.hpp"
#include "common/core/progress_callback.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"

namespace plumb::registration {

using posegraph::PoseGraph;
using posegraph::PoseGraphEdge;

struct LiveConfig {
    /// A previous fragment is a loop candidate when at least this fraction of the new fragment's
    /// points, placed with the current pose estimates, lies within candidate_distance_m of it.
    double min_predicted_overlap = 0.15;
    /// Proximity radius of the predicted overlap (tolerates drift), metres.
    double candidate_distance_m = 0.3;
    /// At most this many candidates per new fragment (highest predicted overlap first).
    int max_candidates = 8;
};
void describe(config::Schema& s, LiveConfig& c);

struct RegistrationConfig {
    /// Downsampling, normals, FPFH.
    PrepareConfig prepare;
    /// Multi-scale ICP (odometry edges, loop and refinement-pass alignment): coloured where both
    /// fragments carry colour (icp.colour), point-to-plane otherwise.
    IcpConfig icp;
    /// Feature matching and RANSAC (loop closures).
    RansacConfig ransac;
    /// Odometry-guided loop search between fragments of one tracking segment.
    GuidedSearchConfig guided;
    /// Line-process pose graph; its max_correspondence_distance_m is also the τ of the overlap
    /// test and of the information matrices.
    posegraph::PoseGraphConfig pose_graph;
    /// Live mode candidate selection.
    LiveConfig live;
    /// Loop closures need at least this overlap (fraction of the smaller fragment; paper: 30 %).
    double min_overlap = 0.3;
    /// Loop closures between fragments of one tracking segment whose relative rotation differs
    /// from the device odometry's by more than this are rejected, degrees (0 = no check). Walls,
    /// floor and ceiling match just as well after a quarter or half turn, so in a bare room
    /// RANSAC and the overlap test accept such symmetric matches; odometry drifts by a few
    /// degrees, not by 90. Pairs from different segments (tracking lost in between) are not
    /// checked: their odometry is unknown.
    double max_loop_rotation_deviation_deg = 30.0;
    /// ICP iterations at the coarsest level when verifying a RANSAC loop candidate.
    int loop_icp_iterations = 30;
    /// Within a tracking segment the odometry-guided starts are verified first, and FPFH +
    /// RANSAC (the feature matching is most of a pair's cost) runs only when none of them passes
    /// the overlap test in agreement with the odometry. Off: RANSAC's start is verified beside
    /// the guided ones for every pair. Pairs of different segments always use RANSAC.
    bool ransac_only_when_unguided = true;
    /// Offline, a non-consecutive pair of one tracking segment is registered only when, at the
    /// odometry poses, at least min_overlap of the smaller fragment lies within
    /// τ + candidate_drift_sigmas × σ of the other, σ the drift prior's deviation for the pair
    /// (guided.drift_per_fragment_m × sqrt(fragments apart)). An alignment the overlap test
    /// accepts has min_overlap within τ; the odometry places it within that radius wherever it
    /// drifted by less than candidate_drift_sigmas × σ, so only pairs that could not pass are
    /// skipped. Pairs of different segments (no odometry) are always registered, and so is every
    /// pair when guided.max_offset_sigmas is 0 (loops may then lie anywhere from the odometry).
    /// 0 = every pair.
    double candidate_drift_sigmas = 2.0;
    /// Offline, at most this many loop candidates of its own segment per fragment (pairs (i, j)
    /// with i < j - 1 for fragment j), those with the highest overlap predicted at the odometry
    /// as above: the pairs registered grow with the fragments, not with their square. 0 = no
    /// limit.
    int max_candidates_per_fragment = 8;
    /// Overlap edges weigh by the point-to-plane information over their overlap
    /// (PoseGraphEdge::Information::kPlane), scaled to the trace of Choi's Λ, instead of Choi's
    /// point-to-point Λ. Off: with it, wrong loop closures that slid along a corridor cost little
    /// and are kept (BENCHMARKS.md).
    bool plane_information = false;
    /// Odometry edges of fragments that carry the tracker's information
    /// (Fragment::odometry_information) keep the tracked transform and weigh it by that
    /// information (PoseGraphEdge::Information::kTracker), and the refinement pass leaves them
    /// alone. Fragment-to-fragment ICP slides along what the depth does not pin (a corridor, a
    /// plain wall) and Choi's point-to-point Λ calls every direction certain; the tracker knew
    /// better, colour included. False: ICP and Choi's Λ, as for loop closures.
    bool tracker_odometry = true;
    /// Run the refinement pass (re-ICP of surviving edges, optimise again).
    bool refinement_pass = true;
    /// The refinement pass leaves an edge as registered when the optimised poses agree with its
    /// transform within refinement_settled_m and refinement_settled_deg: its multi-scale ICP
    /// would start inside the basin of the alignment ICP already converged to and return it
    /// (measured: within 0.6 mm for 25 of 26 such edges, BENCHMARKS.md). Edges the optimisation
    /// moved further (pulled by the others, or kept as the odometry when ICP failed) are
    /// re-aligned. Metres and degrees; either 0 = re-align every edge.
    double refinement_settled_m = 0.01;
    double refinement_settled_deg = 0.25;
    /// Seed of the RANSAC generators (each pair uses a seed derived from it and the pair).
    uint64_t seed = 1;
    /// Worker threads (0 = all); results do not depend on it.
    int num_threads = 0;
};
void describe(config::Schema& s, RegistrationConfig& c);

/// Counts of the pair stage.
struct PairStats {
    int odometry_pairs = 0;
    int odometry_icp_failed = 0;  ///< odometry edges that kept the odometry transform
    int loop_pairs_tried = 0;
    int loop_pairs_skipped = 0;  ///< could not overlap at the odometry (candidate_drift_sigmas)
    int ransac_failed = 0;
    /// Loop pairs whose FPFH + RANSAC ran (the others were settled by the odometry-guided
    /// search: RegistrationConfig::ransac_only_when_unguided).
    int ransac_runs = 0;
    int overlap_rejected = 0;
    int rotation_rejected = 0;     ///< turned too far from the odometry (max_loop_rotation_...)
    int translation_rejected = 0;  ///< moved too far from the odometry (guided.max_offset_...)
    int loops_accepted = 0;
};

/// The odometry edge (s, s+1) between consecutive fragments, built from their indices `s`, `t`
/// and the fragments themselves. When `target` carries the tracker's information, both share a
/// segment and c.tracker_odometry is on: the tracked transform, weighed by that information
/// (PoseGraphEdge::Information::kTracker, see pose_graph.hpp), with the overlap figures at it.
/// Otherwise multi-scale ICP from the odometry relative pose and Choi's Λ; `icp_failed` says
/// whether the ICP failed and the odometry transform was kept.
posegraph::PoseGraphEdge odometryEdge(const FragmentIndex& s, const FragmentIndex& t,
                                      const Fragment& source, const Fragment& target,
                                      const RegistrationConfig& c, bool* icp_failed);

/// The device odometry from fragment a to fragment b (T_a_b = T_W_a^-1 T_W_b), when both belong
/// to one tracking segment; across segments there is none.
std::optional<Eigen::Isometry3d> odometryBetween(const Fragment& a, const Fragment& b);

/// One loop-closure candidate (source, target) registered exactly as the registration stage does
/// it: FPFH + RANSAC and, with `T_odometry` (the device odometry between two fragments of one
/// tracking segment), the odometry-guided starts; coarse ICP from every start, the odometry
/// checks, the overlap test, and multi-scale ICP of the accepted alignment. Returns the loop edge;
/// when nothing was accepted it is not kept and `reason` says why. The stage runs its pairs in
/// parallel and each pair single-threaded; here `config`'s thread counts apply to the pair.
PoseGraphEdge registerLoopPair(const FragmentIndex& source, const FragmentIndex& target,
                               const RegistrationConfig& config,
                               const std::optional<Eigen::Isometry3d>& T_odometry);

/// Builds the pose graph of `fragments` (ids must be 0..n-1 in order; `prepared[i]` must belong
/// to fragment i). Nodes start at the odometry poses T_W_F (re-anchored so node 0 is where
/// fragment 0 is). Edges, sorted by (source, target): one odometry edge per consecutive pair
/// (ICP result, or the odometry transform with reason set when ICP fails), and one loop edge per
/// non-consecutive pair whose RANSAC succeeded: kept when its overlap ≥ min_overlap, otherwise
/// kept = false with the reason. `progress` (may be empty) is called once per pair.
/// Errors: empty input, mismatched sizes or ids, invalid configuration.
Result<PoseGraph> buildPoseGraph(const std::vector<Fragment>& fragments,
                                 const std::vector<PreparedFragment>& prepared,
                                 const RegistrationConfig& config, const ProgressCallback& progress,
                                 PairStats* stats = nullptr);

/// Refinement pass (reference §3.7): every kept edge is re-aligned by multi-scale ICP from the
/// current relative pose T_W_s^-1 T_W_t, its Λ, overlap and RMSE recomputed; a loop edge whose
/// overlap falls below min_overlap is dropped (kept = false, reason). Edges with the tracker's
/// information, and edges the current poses already agree with (refinement_settled_m / _deg),
/// are left as they are. Line processes are reset.
Status refineEdges(PoseGraph& graph, const std::vector<Fragment>& fragments,
                   const std::vector<PreparedFragment>& prepared, const RegistrationConfig& config,
                   const ProgressCallback& progress);

struct RegistrationOutcome {
    PoseGraph graph;
    PairStats stats;
    posegraph::PoseGraphReport first;    ///< optimisation of the initial graph
    posegraph::PoseGraphReport refined;  ///< optimisation after the refinement pass
    bool refined_ran = false;
    double index_seconds = 0.0;       ///< the fragments' ICP pyramids, k-d trees and features
    double pairs_seconds = 0.0;       ///< registering the pairs (odometry and loop candidates)
    double refinement_seconds = 0.0;  ///< the refinement pass's ICP
    /// Edges the refinement pass re-aligned, and those it left as registered because the
    /// optimised poses already agreed with them (RegistrationConfig::refinement_settled_m).
    int refinement_realigned = 0;
    int refinement_settled = 0;
    double optimise_seconds = 0.0;  ///< both pose-graph optimisations
};

/// The whole offline stage: build, optimise (prune), refine, optimise again.
Result<RegistrationOutcome> registerFragments(const std::vector<Fragment>& fragments,
                                              const std::vector<PreparedFragment>& prepared,
                                              const RegistrationConfig& config,
                                              const ProgressCallback& progress);

/// Runs a task to its end: at once on the calling thread, or on a thread the program owns. The
/// task holds copies of what it needs (no reference into its LiveRegistrar).
using TaskRunner = std::function<void(std::function<void()> task)>;

/// Live mode: fragments arrive one at a time. addFragment() prepares the fragment, registers it
/// against its predecessor (ICP from odometry) and against earlier fragments chosen by predicted
/// overlap under the current pose estimates (FPFH + RANSAC + ICP + overlap test), then hands a
/// re-optimisation of a snapshot of the graph to `run_optimisation` (threads belong to programs:
/// a program that wants it in the background runs it on a thread of its own; without a runner it
/// runs at once, inside addFragment()). The next addFragment() (or poses(), graph(), finish(),
/// the destructor) first waits for that optimisation, so every decision uses the same poses
/// whatever the timing: the final result depends on the fragments and the configuration only.
/// Not thread-safe: one caller.
class LiveRegistrar {
  public:
    explicit LiveRegistrar(RegistrationConfig config, TaskRunner run_optimisation = {});
    ~LiveRegistrar();
    LiveRegistrar(const LiveRegistrar&) = delete;
    LiveRegistrar& operator=(const LiveRegistrar&) = delete;

    /// Adds the next fragment (ids must arrive as 0, 1, 2, ...). Errors: an out-of-order id or a
    /// fragment that cannot be prepared (it is then not added).
    Status addFragment(Fragment fragment);

    /// Current pose estimates (waits for the background optimisation).
    std::vector<Eigen::Isometry3d> poses();
    /// The graph so far (waits for the background optimisation). Edges are not pruned yet.
    PoseGraph graph();
    size_t size() const { return fragments_.size(); }
    const std::vector<Fragment>& fragments() const { return fragments_; }
    const std::vector<PreparedFragment>& prepared() const { return prepared_; }

    /// Final optimisation with pruning, the refinement pass and the last optimisation.
    Result<RegistrationOutcome> finish(const ProgressCallback& progress = {});

  private:
    void waitBackground();

    RegistrationConfig config_;
    TaskRunner run_optimisation_;
    std::vector<Fragment> fragments_;
    std::vector<PreparedFragment> prepared_;
    std::vector<std::unique_ptr<FragmentIndex>> index_;
    PoseGraph graph_;
    PairStats stats_;
    std::future<std::vector<Eigen::Isometry3d>> background_;
};

}  // namespace plumb::registration
