// SPDX-License-Identifier: Apache-2.0
#pragma once

// report.html: one self-contained page (inline SVG and CSS, pictures as base64 PNG rendered by
// plumb's own rasteriser, backend/report/mesh_render.hpp; nothing is fetched) that puts the full
// method and the --no-layout baseline side by side. In order: the run (version, date, command
// line, total time including tracking and fusion), accuracy (ATE, reconstruction error, wall
// planarity and wall-to-wall angles, layout errors), pictures of the model, warnings (tracking
// failures and unobserved directions, alternation not converged, walls not found, partial
// coverage), a per-wall table, the floor plan, top views with the camera path (coloured by its
// error with ground truth), the pose graph, the energy of every alternation step and the time per
// stage. Every number comes from metrics.json, so the page and the file never disagree; the
// pictures come from the meshes (ReportFigures).

#include <Eigen/Geometry>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/cloud/point_cloud.hpp"
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

struct ReportFigures {
    std::string floorplan_svg;                     ///< the layout stage's floor plan, if any
    std::map<std::string, std::string> top_views;  ///< variant name -> SVG
    std::vector<ModelView> model_views;            ///< the main variant's mesh, rendered
};

/// The page. `metrics` is the metrics.json document (see backend/pipeline/pipeline.hpp).
std::string renderReportHtml(const nlohmann::json& metrics, const ReportFigures& figures);

}  // namespace plumb::backend
