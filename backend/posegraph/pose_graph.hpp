// SPDX-License-Identifier: Apache-2.0
#pragma once

// Robust pose graph of fragments with line processes (Choi, Zhou, Koltun, CVPR 2015, §5;
// reference §3.5-3.6; the paper's §3.1).
//
// Edge convention (used everywhere in plumb's registration):
//   T_source_target maps points of the TARGET fragment into the SOURCE fragment frame,
//   p_source = T_source_target * p_target, so that  T_W_target ≈ T_W_source * T_source_target.
// This is the paper's T_{i,j} = T_i^-1 T_j for (i, j) = (source, target), and the Redwood
// registration `.log` entry "i j n" with T = T_i_j.
//
// Residual of an edge: the error transform acting on target-frame points
//   E = T_source_target^-1 * T_W_source^-1 * T_W_target,   e = Log(E) in se(3), (omega, upsilon),
// with cost f = e^T Λ e. Λ is Choi's information matrix Σ_q G_q^T G_q over the correspondences q
// (target frame), G_q = [-[q]_x | I_3] (reference §3.4), so f ≈ Σ ||T_W_source p - T_W_target
// q||^2.
//
// Objective (Choi Eq. (3)-(5)): E(T, L) = Σ_odometry f + Σ_loop l f + μ Σ_loop (√l - 1)^2.
// For fixed poses dE/dl = 0 gives the closed form l = (μ / (μ + f))^2, and substituting it yields
// the robust kernel ρ(f) = μ f / (μ + f) minimised by iteratively re-weighted Levenberg-Marquardt.
//
// Deviation from the Lee et al. paper: it writes the prior as Ψ(l) = √(1 - l^2). With that prior
// E is concave in l (its stationary point in l is a maximum) and the minimum sits only at
// l ∈ {0, 1}, a hard switch without a usable gradient; we implement Choi's μ(√l - 1)^2 (which is
// also what Open3D does) and document it here.
//
// μ = preference_loop_closure * τ^2 * mean_edges(Λ(5,5)) (Choi §5, Open3D): τ is the
// correspondence distance, Λ(5,5) the correspondence count of an edge (for an edge with another
// information, its num_correspondences).
//
// Odometry edges of fragments that carry the tracker's information (Fragment::
// odometry_information) weigh by it instead of Choi's Λ: Λ = Ad^T H Ad, H the tracker's J^T J of
// the alignment of the target fragment's first frame to the source fragment's model (left
// perturbation in the source frame, the photometric term weighed in), Ad = Ad(T_source_target)
// taking it to the target-frame linearisation. H is a sum over the frame's pixels in the same
// units as Choi's sum over fragment points (m^2 of point displacement), so it is as certain as
// the tracker was: far more than an overlap of subsampled points where depth and colour pinned
// the pose, nearly nothing along a corridor that neither pinned, and there loop closures and
// the layout can move the fragment.
//
// Choi's Λ is point-to-point and calls every direction of an overlap certain, also a slide along
// a corridor where ICP is free to drift. RegistrationConfig::plane_information (off by default)
// makes overlap edges weigh by the point-to-plane information over the same correspondences
// instead, Σ J^T J with J = [(q x n)^T, n^T], scaled so that its translation block has the trace
// of Choi's Λ (3 per correspondence).
//
// Thread-safety: the functions keep no state between calls and may run concurrently on
// different graphs.

#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "common/config/schema.hpp"
#include "common/core/status.hpp"
#include "common/geometry/lie.hpp"

namespace plumb::posegraph {

struct PoseGraphEdge {
    enum class Kind { kOdometry, kLoop };
    uint32_t source = 0;
    uint32_t target = 0;
    Kind kind = Kind::kOdometry;
    /// Maps target-fragment points into the source fragment frame (see the header comment).
    Eigen::Isometry3d T_source_target = Eigen::Isometry3d::Identity();
    /// Where `information` comes from.
    enum class Information {
        kChoi,   ///< Choi's Λ = Σ G^T G over the overlap's correspondences (reference §3.4)
        kPlane,  ///< point-to-plane Σ J^T J over the same correspondences, scaled to Choi's trace
        kTracker,  ///< the device tracker's J^T J (odometry edges)
    };
    /// 6x6 information matrix (rotation first), target-frame linearisation (reference §3.4).
    Matrix6d information = Matrix6d::Zero();
    Information information_source = Information::kChoi;
    /// Correspondences within τ at T_source_target; Λ(5,5) for Choi's information.
    double num_correspondences = 0.0;
    /// Fraction of the smaller fragment within the correspondence distance after alignment.
    double overlap = 0.0;
    /// RMSE of the inlier correspondences after alignment, metres.
    double inlier_rmse_m = 0.0;
    /// Line-process weight l in [0, 1] (1 for odometry edges).
    double line_process = 1.0;
    /// False when the edge was pruned (or rejected); `reason` says why.
    bool kept = true;
    std::string reason;
};

const char* toString(PoseGraphEdge::Kind kind);
/// "choi", "point_to_plane" or "tracker".
const char* toString(PoseGraphEdge::Information information);

struct PoseGraph {
    /// Fragment -> world poses, one per node (node i = fragment i).
    std::vector<Eigen::Isometry3d> T_W_F;
    std::vector<PoseGraphEdge> edges;
};

struct PoseGraphConfig {
    /// Line-process preference (Open3D preference_loop_closure; 5 for fragment registration).
    double preference_loop_closure = 5.0;
    /// Correspondence distance τ the information matrices were built with, metres.
    double max_correspondence_distance_m = 0.07;
    /// Loop edges with line-process weight below this are pruned (Choi, Open3D: 0.25).
    double edge_prune_threshold = 0.25;
    /// Maximum Levenberg-Marquardt iterations per optimisation round.
    int max_iterations = 100;
    /// Stop when the relative decrease of the robust cost falls below this.
    double relative_cost_tolerance = 1e-9;
    /// Stop when the step norm falls below this.
    double step_tolerance = 1e-9;
    /// Initial LM damping (relative to the diagonal of the normal equations).
    double initial_lambda = 1e-6;
    /// Forcing term of the inexact LM steps: each step's normal equations are solved by
    /// preconditioned conjugate gradients to this relative residual |r| / |b|. An inexact Newton
    /// step with forcing term η converges linearly at rate about η, so 1e-2 costs one or two
    /// more LM iterations than exact steps and saves the factorisations.
    double cg_relative_tolerance = 1e-2;
    /// Conjugate-gradient iterations with the odometry-chain preconditioner (block tridiagonal,
    /// loops reduced to their diagonal blocks) before the step is factorised; 0 factorises
    /// every graph from its first step.
    int chain_max_cg_iterations = 200;
    /// Conjugate-gradient iterations with an earlier step's factorisation as preconditioner
    /// before the step is factorised afresh (near the solution 1-3 are enough).
    int factor_max_cg_iterations = 10;
    /// Node whose pose is held fixed (the gauge); Choi and the paper fix T_0.
    int reference_node = 0;
};
void describe(config::Schema& s, PoseGraphConfig& c);

struct PoseGraphReport {
    int iterations = 0;         ///< LM iterations over all rounds
    int rounds = 0;             ///< optimise / prune rounds run
    double initial_cost = 0.0;  ///< robust cost before optimisation
    double final_cost = 0.0;    ///< robust cost after the last round
    double mu = 0.0;            ///< line-process weight μ used
    int num_loop_edges = 0;     ///< loop edges that entered (kept on input)
    int num_pruned = 0;         ///< loop edges pruned by the line process
    bool converged = false;     ///< the last round met a tolerance before max_iterations
    int factorisations = 0;     ///< sparse Cholesky factorisations over all rounds
    int cg_iterations = 0;      ///< preconditioned conjugate-gradient iterations over all rounds
};

/// Optimises `graph.T_W_F` in place (reference node fixed) with line processes on loop edges,
/// prunes loop edges with l < edge_prune_threshold (kept = false, reason set), and optimises again
/// without them (Open3D GlobalOptimization: optimise, prune, optimise). Edges already not kept on
/// input are ignored. Odometry edges are never pruned. Each LM step is an inexact Newton step:
/// matrix-free preconditioned conjugate gradients on the normal equations, preconditioned by the
/// odometry chain (block tridiagonal, O(n)) or, once one exists, by a sparse LDL^T factorisation
/// (Eigen SimplicialLDLT) of an earlier step; a step is factorised only when conjugate gradients
/// do not converge. Single-threaded and deterministic.
/// Errors: fewer than one node, an edge naming a missing node, a non-finite pose or information
/// matrix, a reference node out of range, or a graph whose kept edges do not connect every node
/// to the reference (the gauge would be free).
Result<PoseGraphReport> optimisePoseGraph(PoseGraph& graph, const PoseGraphConfig& config);

/// The residual e = Log(T_st^-1 T_W_s^-1 T_W_t) of an edge for the given poses.
Vector6d edgeResidual(const PoseGraphEdge& edge, const Eigen::Isometry3d& T_W_source,
                      const Eigen::Isometry3d& T_W_target);

/// The line-process weight μ of a graph (see the header comment); 0 for a graph without edges.
double lineProcessMu(const PoseGraph& graph, const PoseGraphConfig& config);

}  // namespace plumb::posegraph
