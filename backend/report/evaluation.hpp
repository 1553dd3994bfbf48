// SPDX-License-Identifier: Apache-2.0
#pragma once

// Scores one reconstruction (a variant: the full method or the --no-layout baseline) against the
// ground truth that came with the input, with the measures of DESIGN.md "Measuring":
//  - ATE of the per-frame trajectory (Horn alignment; RMSE, median, max);
//  - reconstruction error: distance from every mesh vertex, mapped into the ground-truth frame by
//    the ATE alignment, to the closest ground-truth point (mean, median, RMS, p90, completeness);
//  - layout errors of the estimated layout against the ground-truth layout (same mapping);
//  - wall planarity and wall-to-wall angles measured on the mesh itself: for each reference wall
//    (ground-truth walls when known, else the estimated layout's), the mesh vertices within
//    `wall_band_m` of the wall's plane and inside its segment get a least-squares plane; planarity
//    is the RMS distance to that plane and the angles are taken between fitted planes. The same
//    reference walls serve every variant, so the numbers compare like with like.
//
// Thread-safety: the functions keep no state between calls and may run concurrently.

#include <Eigen/Geometry>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/cloud/point_cloud.hpp"
#include "common/core/status.hpp"
#include "common/eval/layout_metrics.hpp"
#include "common/eval/recon_metrics.hpp"
#include "common/eval/trajectory_metrics.hpp"
#include "common/io/trajectory.hpp"
#include "common/layout/layout.hpp"

namespace plumb::backend {

/// Whatever ground truth came with the input; every part is optional.
struct GroundTruth {
    std::optional<io::Trajectory> trajectory;  ///< camera -> world, GT world frame
    std::vector<Eigen::Vector3f> points;       ///< dense surface samples, GT world frame
    std::optional<Layout> layout;              ///< GT layout (T_W_L maps into the GT world)
    std::string description;                   ///< where it came from, for the report

    bool empty() const { return !trajectory && points.empty() && !layout; }
};

/// Loads the ground truth a dataset folder carries: `groundtruth.txt` (TUM) or `trajectory.log`,
/// `gt_points.ply`, `layout.json`. Missing files are fine; unreadable ones are errors.
Result<GroundTruth> loadGroundTruth(const std::filesystem::path& dataset_dir);

struct EvaluationConfig {
    /// Trajectory association and ATE settings.
    eval::TrajectoryEvalConfig trajectory;
    /// Reconstruction-error settings (completeness threshold).
    eval::ReconMetricsConfig recon;
    /// Layout matching gates.
    eval::LayoutMetricsConfig layout;
    /// Half-width of the slab around a reference wall whose mesh vertices measure planarity, m.
    double wall_band_m = 0.05;
    /// Margin kept from a wall segment's ends (corners and neighbouring walls), metres.
    double wall_end_margin_m = 0.15;
    /// Walls with fewer supporting vertices are not measured.
    size_t min_wall_vertices = 200;
};

struct WallFit {
    int reference_id = 0;
    size_t vertices = 0;
    double rms_m = 0.0;        ///< RMS distance of the slab's vertices to their fitted plane
    Eigen::Vector3d normal_W;  ///< fitted unit normal, estimate's world frame
};

struct WallAngle {
    int id_a = 0;
    int id_b = 0;
    double reference_deg = 0.0;  ///< angle between the reference walls
    double measured_deg = 0.0;   ///< angle between the fitted planes
};

struct VariantEvaluation {
    std::string name;
    std::optional<eval::TrajectoryEvaluation> trajectory;
    Eigen::Isometry3d T_gt_est = Eigen::Isometry3d::Identity();  ///< ATE alignment (or identity)
    std::optional<eval::ReconMetrics> recon;
    std::optional<eval::LayoutMetrics> layout;
    std::vector<WallFit> walls;
    std::vector<WallAngle> wall_angles;  ///< adjacent reference walls (consecutive segments)
    double mean_wall_rms_m = 0.0;
    double max_wall_angle_error_deg = 0.0;
    std::vector<std::string> notes;  ///< what could not be measured and why
    /// Each mesh vertex's distance to the closest ground-truth point after the ATE alignment
    /// (the reconstruction error's distances, in vertex order; empty when not measured).
    std::vector<double> vertex_errors_m;
};

/// Evaluates one variant. `layout` is the variant's estimated layout (none for the baseline);
/// `reference_layout` supplies the reference walls when the ground truth has no layout (give the
/// full method's estimate). Only unusable inputs fail; missing ground truth becomes a note.
/// `ground_truth_points`, when given, is the tree of ground_truth.points built once by the caller
/// for every variant (else it is built here).
Result<VariantEvaluation> evaluateVariant(const std::string& name, const io::Trajectory& trajectory,
                                          const TriangleMesh& mesh,
                                          const std::optional<Layout>& layout,
                                          const GroundTruth& ground_truth,
                                          const std::optional<Layout>& reference_layout,
                                          const EvaluationConfig& config = {},
                                          const eval::ClosestPoints* ground_truth_points = nullptr);

/// metrics.json form of an evaluation (metres and degrees; keys end in _m, _deg).
nlohmann::json toJson(const VariantEvaluation& evaluation);

}  // namespace plumb::backend
