// SPDX-License-Identifier: Apache-2.0
#pragma once

// report.html: one self-contained page (inline SVG and CSS, pictures as base64 PNG rendered by
// plumb's own rasteriser, backend/report/mesh_render.hpp; nothing is fetched) that puts the full
// method and the --no-layout baseline side by side. In order: the run (version, date, command
// line, total time including tracking and fusion), accuracy (ATE, reconstruction error, wall
// planarity and wall-to-wall angles, layout errors), pictures of the model, warnings (tracking
// failures and unobserved directions, alternation not converged, walls not found, partial
// coverage), a per-wall table, the floor plan, top views with the camera path (coloured by its
// error with ground truth), the reconstruction-error map (the model from above coloured by the
// distance to the ground-truth surface; without one, why not), the pose graph, the energy of every
// alternation step and the time per stage. Every number comes from metrics.json, so the page and
// the file never disagree; the pictures come from the meshes (ReportFigures).
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <Eigen/Geometry>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "backend/report/mesh_render.hpp"
#include "common/cloud/point_cloud.hpp"
#include "common/core/status.hpp"
#include "common/layout/layout.hpp"

namespace plumb::backend {

/// The camera path drawn on a top view: positions in the world frame and, with ground truth,
/// each position's ATE error (NaN where a pose had no ground-truth partner).
struct TopViewTrajectory {
    std::vector<Eigen::Vector3d> positions_W;
    std::vector<double> errors_m;  ///< empty, or one per position
};

/// Top view (x-y of the layout frame when a layout is given, else of the world with the first
/// camera's up as +z) of a mesh: a plan rendered by the rasteriser (backend/report/mesh_render)
/// and embedded as a PNG in an SVG that draws, over it, the layout's walls, the camera path
/// (coloured by its error when errors are given, with a colour bar) and a 1 m scale bar. The
/// vector part stays small: at most `max_segments` path segments whatever the number of frames.
std::string topViewSvg(const TriangleMesh& mesh, const std::optional<Layout>& layout,
                       const TopViewTrajectory& trajectory = {}, int size_px = 460,
                       size_t max_segments = 300);

/// The up frame U of the report's pictures (z against gravity): the layout frame L when a
/// layout is given, else the world turned so that the camera convention's -y (the first
/// frame's up) becomes +z. Returns T_U_W.
Eigen::Isometry3d reportUpFrame(const std::optional<Layout>& layout);

/// A picture of the model for the report: a caption and a `data:image/png;base64,` URI.
struct ModelView {
    std::string caption;
    std::string png_data_uri;
};

/// Pictures of `mesh` (world frame) rendered by plumb's own rasteriser
/// (backend/report/mesh_render.hpp): an oblique view from above with the top of the room cut
/// away, and a perspective view. `size_px`: width of each picture.
std::vector<ModelView> renderModelViews(const TriangleMesh& mesh,
                                        const std::optional<Layout>& layout, int size_px = 560);

/// Top of the fixed colour scale of the reconstruction-error map, metres: 0 is green, half of it
/// yellow, this value red; larger errors are clipped to red. Fixed (not scaled to the data) so
/// that maps of different runs compare by eye.
inline constexpr double kReconErrorScaleMaxM = 0.05;

/// Colour of a reconstruction error on the fixed scale: green (0, 200, 48) at 0 m, yellow
/// (255, 200, 48) at kReconErrorScaleMaxM / 2, red (255, 0, 48) at kReconErrorScaleMaxM and
/// beyond (linear in between; negative or NaN errors count as 0).
Color3u8 reconErrorColour(double error_m);

/// The reconstruction-error map: the model's points seen from straight above (x-y of the report's
/// up frame U, reportUpFrame(); the top of the room cut away like the other top views), each a
/// small square coloured by its distance to the ground-truth surface (reconErrorColour), the
/// highest point winning each pixel. `svg` embeds the picture as a PNG with a colour bar, its
/// legend and a 1 m scale bar.
struct ReconErrorMap {
    RgbImage image;
    std::string svg;
    size_t points_drawn = 0;  ///< points below the cut, drawn (possibly hidden by higher ones)
    Eigen::Isometry3d T_U_W = Eigen::Isometry3d::Identity();
    double px_per_m = 1.0;
    Eigen::Vector2d origin_px = Eigen::Vector2d::Zero();  ///< pixel of x = y = 0 of U

    /// Pixel (x right, y down) of a world point (x-y of U; height ignored).
    Eigen::Vector2d pixel(const Eigen::Vector3d& p_W) const {
        const Eigen::Vector3d p_U = T_U_W * p_W;
        return {origin_px.x() + px_per_m * p_U.x(), origin_px.y() - px_per_m * p_U.y()};
    }
};

/// The map of `points_W` (estimate's world frame) with one error per point (metres; NaN points
/// are not drawn). Preconditions (checked): as many errors as points, positive size.
ReconErrorMap reconErrorMap(const std::vector<Eigen::Vector3f>& points_W,
                            const std::vector<double>& errors_m,
                            const std::optional<Layout>& layout, int size_px = 460);

/// The map of a mesh's vertices against ground-truth surface points: each vertex is mapped into
/// the ground-truth frame by `T_gt_est` (the evaluation's ATE alignment) and measured to its
/// closest ground-truth point (eval::closestPointDistances, the measure of the report's
/// reconstruction error). At most `max_points` vertices, evenly strided, are measured and drawn.
/// Errors: an empty mesh or ground truth, non-finite points.
Result<ReconErrorMap> reconErrorMap(const TriangleMesh& mesh, const Eigen::Isometry3d& T_gt_est,
                                    const std::vector<Eigen::Vector3f>& gt_points_gt,
                                    const std::optional<Layout>& layout, int size_px = 460,
                                    size_t max_points = 400'000);

/// The same map from errors already measured: `vertex_errors_m` holds one error per mesh vertex
/// (VariantEvaluation::vertex_errors_m); the same vertices as above are drawn. Errors: an empty
/// mesh, or not one error per vertex.
Result<ReconErrorMap> reconErrorMap(const TriangleMesh& mesh,
                                    const std::vector<double>& vertex_errors_m,
                                    const std::optional<Layout>& layout, int size_px = 460,
                                    size_t max_points = 400'000);

struct ReportFigures {
    std::string floorplan_svg;                     ///< the layout stage's floor plan, if any
    std::map<std::string, std::string> top_views;  ///< variant name -> SVG
    std::vector<ModelView> model_views;            ///< the main variant's mesh, rendered
    /// The main variant's reconstruction-error map (ReconErrorMap::svg); empty without it.
    std::string recon_error_svg;
    /// Why there is no reconstruction-error map (shown instead of it), e.g. no ground truth.
    std::string recon_error_note = "no ground-truth surface came with the input";
};

/// The page. `metrics` is the metrics.json document (see backend/pipeline/pipeline.hpp).
std::string renderReportHtml(const nlohmann::json& metrics, const ReportFigures& figures);

}  // namespace plumb::backend
