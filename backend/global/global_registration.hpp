// SPDX-License-Identifier: Apache-2.0
#pragma once

// Layout-constrained global multi-view registration (Lee, Yea, Park, Yoon, ICCV 2017, §3.3;
// reference §5). For fragment poses T_i = T_W_F[i] (fragment -> world) it minimises
//
//   E_R = Σ_i E_layout(i) + λ1 Σ_(i,j) E_frag(i, j) + λ2 Σ_(i,j) E_pair(i, j)        (Eq. 7)
//
//  - E_layout (Eq. 8): point-to-plane distances from fragment points to the layout planes they
//    belong to. A point x = T_i p is assigned to the nearest layout plane that passes every gate:
//    |n_L.x + d_L| < layout_max_distance_m; its normal agrees, n_L . (R_i n_p) > cos(angle) (both
//    point into the room); and it lies in the plane's support region: for a wall, its projection
//    on the floor falls within the wall segment extended by wall_margin_m and its height within
//    [0, ceiling height] ± margin; for floor and ceiling, inside the room polygon grown by
//    floor_margin_m. Without the support test furniture near an infinite wall's extension is
//    pulled onto it (the paper's Office1 failure, reference §5.2).
//  - E_frag (Eq. 9): point-to-plane distances between overlapping fragments, correspondences by
//    nearest neighbour in the other fragment's local k-d tree (query T_j^-1 T_i p), gated by
//    distance and normal angle, both directions.
//  - E_pair (Eq. 10): the pairwise-transform prior of the pose graph's kept edges,
//    e = Log(T_i_j^-1 T_i^-1 T_j), cost e^T Λ̂ e with Λ̂ = Λ / n, n the edge's correspondence
//    count (PairPrior::count; trace(Λ_translation)/3 for Choi's Λ = Σ G^T G), so e^T Λ̂ e is the
//    mean squared displacement of the edge's points, in m², like a point residual. A prior whose
//    information is the device tracker's has a weight of its own (tracked_pair_weight).
//
// Weights ("λ1, λ2 depending on the numbers of points and fragment pairs", paper §3.3; reference
// §5.5): every term is normalised by its count,
//   E = (1/N_L) Σ ρ(r_L) + w1 (1/N_F) Σ ρ(r_F) + (1/N_P) Σ w2 e^T Λ̂ e,
// i.e. λ1 = w1 N_L / N_F, λ2 = w2 N_L / N_P up to the common factor 1/N_L; ρ is the Huber
// kernel (squared below huber_delta_m). A term without correspondences drops out.
//
// Solver: Levenberg-Marquardt on the sparse 6N normal equations (Eigen SimplicialLDLT) with
// fragment 0 fixed (gauge) and the update T_i <- Exp(xi_i) T_i. Correspondences are fixed within
// one inner loop, where a step is accepted only if it lowers E (so E never increases); then they
// are re-established at the new poses (`rounds` times).
//
// Determinism: correspondence search and accumulation run in parallel over fragments and pairs,
// each writing its own slot; all sums are taken serially in a fixed order, so the result is
// bit-identical for any num_threads.
//
// Thread-safety: the functions keep no state between calls and may run concurrently;
// each parallelises internally over num_threads. GlobalCloud is immutable after preparation
// and its queries are thread-safe.

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "common/config/schema.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "common/geometry/lie.hpp"
#include "common/layout/layout.hpp"

namespace plumb::global {

/// A pairwise-transform prior (one kept pose-graph edge), the paper's T̃_{i,j}.
/// Same convention as backend/posegraph's PoseGraphEdge with (i, j) = (source, target):
/// T_i_j maps fragment-j points into fragment i (T_W_j ≈ T_W_i T_i_j) and `information` is
/// Choi's Σ G_q^T G_q over the edge's correspondences q in frame j (rotation first).
struct PairPrior {
    uint32_t i = 0;
    uint32_t j = 0;
    Eigen::Isometry3d T_i_j = Eigen::Isometry3d::Identity();
    Matrix6d information = Matrix6d::Identity();
    /// The n of Λ̂ = Λ / n: the edge's correspondence count. 0: trace(Λ_translation) / 3, which is
    /// the count for Choi's Λ. An information that is not Choi's (the tracker's, a sum over a
    /// frame's pixels) gives its count here, so that E_pair weighs it against the other priors
    /// as the pose graph does.
    double count = 0.0;
    /// The information is the device tracker's (an odometry edge within one tracking segment):
    /// the prior is weighed by GlobalConfig::tracked_pair_weight instead of pair_weight.
    bool tracked = false;
};

struct GlobalConfig {
    // --- fragment preparation ---
    /// Voxel size of the subsampled fragment clouds the energy is evaluated on, metres.
    double voxel_size_m = 0.03;
    /// At most this many subsampled points per fragment (evenly strided beyond).
    int max_points_per_fragment = 6000;

    // --- weights (Eq. 7, normalised by counts) ---
    // Measured on 600-frame living_room scans (loop / no loop; full method's recon error against
    // the Choi baseline's 1.43 / 1.45 cm): (w1, w2) = (1, 0.1) 1.17 / 1.16 cm, (1, 0.03) 1.14 /
    // 1.13, (1, 0.01) 1.11 / 1.11, (0.5, 0.01) 1.06 / 1.06. The pairwise prior is the pose
    // graph's own answer (its residual at the start is about 2 cm of mean point displacement per
    // edge), so a strong w2 holds the poses where the baseline left them; the layout term is the
    // new information.
    /// w1: weight of the mean fragment-to-fragment term relative to the mean layout term.
    double frag_weight = 0.5;
    /// w2: weight of the mean pairwise-prior term relative to the mean layout term, for the
    /// priors of loops and of odometry edges registered by ICP.
    double pair_weight = 0.01;
    // A tracked odometry prior is as certain as the tracker was, direction by direction (with
    // colour, about a millimetre where the tracking observed the motion), while a loop's prior
    // can be wrong (corridors keep a few wrong guided loops): the two get their own w2. With one
    // w2 for both, 0.01 let the coarse E_frag move fragments off their tracked odometry, and 0.1
    // held the wrong loops too (BENCHMARKS.md, "The pairwise prior's weight").
    /// w2 of the priors whose information is the device tracker's (PairPrior::tracked).
    double tracked_pair_weight = 1.0;
    /// Use E_layout (false = the Choi-style baseline: E_frag + E_pair only).
    bool use_layout = true;
    /// Huber threshold of the point residuals (E_layout, E_frag), metres.
    double huber_delta_m = 0.02;

    // --- fragment-fragment correspondences (C_ij) ---
    /// Maximum distance of a correspondence, metres (eps_F).
    double frag_max_distance_m = 0.05;
    /// Maximum angle between corresponding normals, degrees.
    double frag_max_normal_angle_deg = 30.0;
    /// Besides the priors' pairs, use every pair whose overlap (share of the smaller fragment's
    /// points with a correspondence) is at least min_overlap.
    bool frag_pairs_from_overlap = true;
    /// Minimum overlap of a pair found by overlap, fraction.
    double min_overlap = 0.1;

    // --- fragment-layout correspondences (C_i) ---
    /// Maximum point-to-layout-plane distance, metres (eps_L).
    double layout_max_distance_m = 0.10;
    /// Maximum angle between the point normal and the layout normal, degrees.
    double layout_max_normal_angle_deg = 30.0;
    /// Walls: how far beyond the wall segment's ends (and below the floor / above the ceiling)
    /// a point may project and still belong to the wall, metres (tau2).
    double wall_margin_m = 0.10;
    /// Floor and ceiling: how far outside the room polygon a point may lie, metres.
    double floor_margin_m = 0.10;

    // --- solver ---
    /// Correspondence rounds (re-established at the current poses before each inner loop).
    int rounds = 3;
    /// Maximum Levenberg-Marquardt iterations per round (inner loop).
    int max_iterations = 10;
    /// An inner loop stops when max_i |xi_i| (rad / m) of an accepted step falls below this.
    double step_tolerance = 1e-5;
    /// Initial LM damping relative to the diagonal (H + mu diag(H)).
    double initial_damping = 1e-4;
    /// Worker threads for correspondence search and accumulation (0 = TBB default).
    int num_threads = 0;
};

void describe(config::Schema& s, GlobalConfig& c);

/// The energy and its terms (Eq. 7 with the normalisation above), dimensionless weights applied.
struct EnergyTerms {
    double layout = 0.0;    ///< (1/N_L) Σ ρ(r_L), m²
    double frag = 0.0;      ///< w1 (1/N_F) Σ ρ(r_F), m²
    double pair = 0.0;      ///< (1/N_P) Σ w2 e^T Λ̂ e (each prior's w2), m²
    double total = 0.0;     ///< layout + frag + pair
    size_t num_layout = 0;  ///< N_L, fragment-layout correspondences
    size_t num_frag = 0;    ///< N_F, fragment-fragment correspondences
    size_t num_pair = 0;    ///< N_P, pair priors
};

/// One Levenberg-Marquardt iteration.
struct GlobalIteration {
    int round = 0;              ///< correspondence round
    int iteration = 0;          ///< LM iteration within the round
    EnergyTerms energy;         ///< energy after the iteration (= before when rejected)
    double damping = 0.0;       ///< mu used
    double max_step_rad = 0.0;  ///< max_i |omega_i| of the step
    double max_step_m = 0.0;    ///< max_i |upsilon_i| of the step
    bool accepted = false;
};

struct GlobalResult {
    std::vector<Eigen::Isometry3d> T_W_F;  ///< refined poses; T_W_F[0] is the input's
    EnergyTerms initial;                   ///< at the input poses, first round's correspondences
    EnergyTerms final;                     ///< at the output poses, last round's correspondences
    std::vector<GlobalIteration> iterations;
    int rounds = 0;
    bool converged = false;     ///< the last round ended on the step tolerance
    size_t num_frag_pairs = 0;  ///< fragment pairs with E_frag correspondences (last round)
    /// The paper's λ1 = w1 N_L / N_F and λ2 = w2 N_L / N_P (0 when a count is 0), last round;
    /// λ2 with pair_weight, the w2 of the priors that are not the tracker's.
    double lambda1 = 0.0;
    double lambda2 = 0.0;
};

/// A fragment's subsampled oriented cloud and its k-d tree, in the fragment frame. Build once
/// with prepareClouds() and reuse across calls (the alternation does).
class GlobalCloud {
  public:
    GlobalCloud();
    ~GlobalCloud();
    GlobalCloud(GlobalCloud&&) noexcept;
    GlobalCloud& operator=(GlobalCloud&&) noexcept;
    GlobalCloud(const GlobalCloud&) = delete;
    GlobalCloud& operator=(const GlobalCloud&) = delete;

    const std::vector<Eigen::Vector3d>& points() const { return points_; }
    const std::vector<Eigen::Vector3d>& normals() const { return normals_; }
    /// Index of the source point (in Fragment::points_F) each subsampled point is closest to.
    const std::vector<uint32_t>& sourceIndex() const { return source_index_; }
    size_t size() const { return points_.size(); }

    /// Nearest subsampled point to `query` (fragment frame); false when the cloud is empty.
    bool nearest(const Eigen::Vector3d& query, uint32_t* index, double* distance_sq) const;
    /// Nearest subsampled point closer to `query` than sqrt(max_distance_sq); false when there is
    /// none. The same point as nearest() when it is that close, found without searching beyond.
    /// A `hint` (a point index, or any larger value for none) bounds the search by its own
    /// distance: the result is the same, found sooner when the hint is near the nearest point.
    bool nearestWithin(const Eigen::Vector3d& query, double max_distance_sq, uint32_t* index,
                       double* distance_sq,
                       uint32_t hint = std::numeric_limits<uint32_t>::max()) const;

  private:
    friend Result<std::vector<GlobalCloud>> prepareClouds(const std::vector<Fragment>&,
                                                          const GlobalConfig&);
    struct Tree;
    std::vector<Eigen::Vector3d> points_;
    std::vector<Eigen::Vector3d> normals_;
    std::vector<uint32_t> source_index_;
    std::unique_ptr<Tree> tree_;
};

/// Voxel-subsamples each fragment (centroid and mean normal per voxel, deterministic) and builds
/// its k-d tree. kInvalidArgument when a fragment has points without normals or non-finite
/// values. Empty fragments give empty clouds (their poses are then held by E_pair alone).
Result<std::vector<GlobalCloud>> prepareClouds(const std::vector<Fragment>& fragments,
                                               const GlobalConfig& config);

/// The fragment pairs' correspondences of a previous refinement, kept by a caller that refines
/// the same clouds again (Algorithm 1's outer iterations) and handed to the next call: each
/// point's nearest-neighbour search then starts at the distance of its previous partner, which
/// bounds the nearest one's. Results never depend on it (any hint is a valid bound). One object
/// per sequence of calls; it is not shared between threads.
class MatchHints {
  public:
    MatchHints();
    ~MatchHints();
    MatchHints(MatchHints&&) noexcept;
    MatchHints& operator=(MatchHints&&) noexcept;

    struct Pairs;  ///< the correspondences (global_registration.cpp)
    std::unique_ptr<Pairs> pairs;
};

/// Refines T_W_F by minimising E_R (see the header comment). T_W_F[0] is held fixed. `layout`
/// is ignored when config.use_layout is false or it has no planes. Errors (kInvalidArgument):
/// size mismatch, an invalid pose, a prior with an index out of range, i == j, or a non-finite
/// or non-symmetric information matrix, a layout plane with a non-unit normal, a bad config.
/// `hints` (may be null) are read and then replaced by this call's last correspondences.
Result<GlobalResult> refinePoses(const std::vector<GlobalCloud>& clouds,
                                 std::vector<Eigen::Isometry3d> T_W_F,
                                 const std::vector<PairPrior>& priors, const Layout& layout,
                                 const GlobalConfig& config, MatchHints* hints = nullptr);

/// E_R at `T_W_F` with correspondences established there (no optimisation); the same gates,
/// weights and errors as refinePoses().
Result<EnergyTerms> evaluateEnergy(const std::vector<GlobalCloud>& clouds,
                                   const std::vector<Eigen::Isometry3d>& T_W_F,
                                   const std::vector<PairPrior>& priors, const Layout& layout,
                                   const GlobalConfig& config);

/// evaluateEnergy() with two layouts at the same poses: the same two results, with the fragment
/// pairs' correspondences (which do not depend on the layout) established once.
Result<std::array<EnergyTerms, 2>> evaluateEnergies(const std::vector<GlobalCloud>& clouds,
                                                    const std::vector<Eigen::Isometry3d>& T_W_F,
                                                    const std::vector<PairPrior>& priors,
                                                    const Layout& first, const Layout& second,
                                                    const GlobalConfig& config);

/// The registration step of Algorithm 1 after a layout step, with its test
/// (AlternationConfig::monotone_layout_steps).
struct LayoutStepOutcome {
    /// E_R at the given poses with the previous layout and with the new one (evaluateEnergies()).
    std::array<EnergyTerms, 2> energies;
    /// refinePoses() with the new layout; empty when the new layout raised E_R.
    std::optional<GlobalResult> step;
};

/// evaluateEnergies(previous, layout) at `T_W_F`, then, unless the new layout raised E_R,
/// refinePoses() with it from `T_W_F`, whose first round takes the correspondences the evaluation
/// just established there (the same ones) instead of establishing them again. The results of
/// those two calls, bit for bit. `hints` as for refinePoses().
Result<LayoutStepOutcome> refinePosesAfterLayoutStep(const std::vector<GlobalCloud>& clouds,
                                                     const std::vector<Eigen::Isometry3d>& T_W_F,
                                                     const std::vector<PairPrior>& priors,
                                                     const Layout& previous, const Layout& layout,
                                                     const GlobalConfig& config,
                                                     MatchHints* hints = nullptr);

/// Convenience: prepareClouds() then refinePoses().
Result<GlobalResult> refinePoses(const std::vector<Fragment>& fragments,
                                 std::vector<Eigen::Isometry3d> T_W_F,
                                 const std::vector<PairPrior>& priors, const Layout& layout,
                                 const GlobalConfig& config);

/// Which layout plane (index into layout.planes) each point of each cloud is assigned to at the
/// given poses (-1: none), with the gates of E_layout. For diagnostics and tests.
std::vector<std::vector<int>> layoutAssignments(const std::vector<GlobalCloud>& clouds,
                                                const std::vector<Eigen::Isometry3d>& T_W_F,
                                                const Layout& layout, const GlobalConfig& config);

}  // namespace plumb::global
