// SPDX-License-Identifier: Apache-2.0
#pragma once

// World-frame layout estimation, the second half of the paper's §3.2 (reference §4.6-4.10).
// Inputs are the cached per-fragment planes (fragment_planes.hpp) and the current fragment poses
// T_W_F; only this part re-runs in each outer iteration of Algorithm 1.
//
//   1. every labelled point group (fragment i, plane l) and its plane go to the world frame;
//   2. second T-linkage over the groups (hypotheses = the groups' planes, residual = mean
//      |n.p + d| of a group's points) -> dominant planes, each refitted to its groups' points;
//   3. base plane = the dominant plane with the largest occupied area (cells of its own 2-D grid)
//      among those with (almost) all other points on one side and, when a gravity hint is given,
//      roughly horizontal;
//   4. occupancy grid of all points on the base plane, closed, hole-filled; its outer contour is
//      the morphological boundary dO (Iwanowski 2007);
//   5. walls (Eq. 6-7): |n . n_base| < tau1 and mean distance of the plane's projected points to
//      dO < tau2; reaching the ceiling unless nothing was seen over their top (furniture shows
//      what stands behind it above its top; a wall scanned from close by shows nothing beyond
//      it); near-coplanar walls merged; the opposite horizontal plane (ceiling or floor); then
//      walls must bound the space the camera moved in (below);
//   6. weak-Manhattan snapping: walls made exactly vertical; those within snap_angle of a multiple
//      of 90 degrees from the largest wall are made exactly orthogonal/parallel to it, the others
//      keep their angle; offsets re-estimated with the normals fixed;
//   7. layout frame L: z up (the floor normal), floor at z = 0, x along the largest wall's normal;
//      the room polygon from the walls in the order the boundary contour meets them; a wall the
//      polygon follows along several long edges is one layout wall per edge.
//
// Walls bound the space the camera moved in. The camera positions (every tracked frame's,
// T_W_F * T_F_C; a fragment without frames gives its origin) are occupied cells of the base grid
// (path_occupancy_radius_m around each), and so are lines of sight from each fragment's middle
// camera to its points, so the boundary dO encloses the path and the space seen from it. A wall's
// room side is the side of it where the room region (the filled contour) lies, probed along its
// extent; the rules, in this order:
//   a. camera behind: of the camera positions whose projection falls within the wall's extent
//      and that face it across the room region (the straight way from the camera to the wall
//      stays in it), more than max_camera_behind_fraction lie farther than
//      camera_behind_margin_m behind the wall (outside the room) -> not a wall ("camera behind
//      it": a counter front or room divider seen from its far side, a plane that would leave the
//      path outside the polygon). The extent is the pieces the wall's points cover, split at gaps
//      wider than wall_piece_gap_m. In a U-shaped room the other arm's path lies behind a side
//      wall of the notch, within its extent, but across the notch, outside the room; and a wall
//      coplanar with a furniture face elsewhere in the room is two pieces, with the path between
//      them behind neither;
//   b. stacked walls: of two walls within stacked_wall_angle_deg of parallel, facing the same way
//      (room sides agree), whose planes are more than wall_merge_offset_m and at most
//      stacked_wall_max_gap_m apart, the inner one (nearer the room, i.e. in front of the other)
//      is not a wall ("in front of wall N": a counter, tall cabinet or shelf front before the
//      wall behind it). A recess of a wall shallower than stacked_wall_max_gap_m is therefore
//      drawn as the straight outer wall;
//   c. block sides: a wall whose points (95 %) lie within the slab between such an outer wall and
//      the rejected inner front (10 cm margin) is that block's side, not a wall ("side of a block
//      in front of wall N").
// The fraction of camera positions inside the final room polygon is reported
// (LayoutDiagnostics::path_inside_fraction).
//
// Deterministic; the result depends only on the inputs and the configuration. Thread-safe:
// estimateLayout and toJson keep no state between calls.

#include <nlohmann/json_fwd.hpp>

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "backend/layout/fragment_planes.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "common/layout/layout.hpp"

namespace plumb::config {
class Schema;
}

namespace plumb::layout {

/// Parameters of world-frame layout estimation. Defaults and their reasons: docs/layout.md.
struct LayoutConfig {
    /// Second T-linkage inlier scale, metres: larger than the fragment tau because residual
    /// misregistration adds up (reference §4.6: 1.5x; 2x tolerates 3 cm / 1 deg pose errors).
    double tau_m = 0.025;
    /// Preferences vanish beyond cutoff_factor * tau.
    double cutoff_factor = 5.0;
    /// Two groups whose planes differ by more than this never share a dominant plane, degrees.
    double max_group_angle_deg = 10.0;
    /// At most this many points per group enter residuals and fits (caps dense fragments).
    int max_group_points = 400;
    /// Dominant planes with less occupied area are ignored, m^2.
    double min_dominant_area_m2 = 0.3;
    /// Cell size of the occupancy grids (plane areas and the base-plane grid), metres.
    double grid_cell_m = 0.05;
    /// A base-grid cell is occupied with at least this many projected sample points.
    int min_cell_points = 2;
    /// Morphological closing of the base grid: elliptic kernel diameter, cells.
    int closing_kernel_cells = 5;
    /// Base plane: at least this fraction of the points farther than base_side_margin_m from it
    /// must lie on one side (the room envelope).
    double base_min_one_sided = 0.95;
    double base_side_margin_m = 0.1;
    /// Up direction of an upright camera in the camera frame (x right, y down, z forward:
    /// (0, -1, 0)); ICL-NUIM's y-flipped frames use (0, 1, 0). The fragments' first-frame
    /// rotations average it into a gravity hint. Zero disables the hint (then the base plane is
    /// taken as the floor).
    Eigen::Vector3d camera_up_C = Eigen::Vector3d(0.0, -1.0, 0.0);
    /// With the hint, base-plane candidates must be within this angle of horizontal, degrees.
    double base_max_tilt_deg = 30.0;
    /// Eq. 6: walls need |n . n_base| < tau1 (cos 80 deg: within 10 deg of vertical).
    double tau1 = 0.17;
    /// Eq. 7: walls need a mean distance of their points to the boundary dO below tau2, metres.
    double tau2_m = 0.25;
    /// Walls with less occupied area are dropped, m^2.
    double min_wall_area_m2 = 0.3;
    /// Walls span floor to ceiling: with a ceiling, a wall's points (99th percentile) must come
    /// within this distance of it, metres (furniture fronts and shelves never do) ... A handheld
    /// camera at 1.5 m with a 49 degree vertical field of view sees the top of a 2.6 m wall only
    /// from 2.4 m away, so a wall scanned from closer ends 0.3 m or more below the ceiling; a
    /// 1.9-2.0 m shelf or wardrobe in a 2.6-2.7 m room stays 0.6-0.7 m below it.
    double wall_top_margin_m = 0.5;
    /// ... unless the space above its top was never seen: a plane short of the ceiling is
    /// furniture only when lines of sight pass over its top (more than wall_top_seen_margin_m
    /// above it, to points more than that beyond it) along at least this fraction of its extent
    /// (of the pieces its points cover, wall_piece_gap_m).
    /// A wardrobe or shelf shows the wall or ceiling behind it above its top; a wall scanned from
    /// too close for its top to be in view (a 2.8-3 m ceiling, a narrow room) has nothing seen
    /// beyond it. 0: every plane short of the ceiling is rejected.
    double wall_top_seen_fraction = 0.3;
    double wall_top_seen_margin_m = 0.1;
    /// ... and a plane short of the ceiling narrower than this, metres, is rejected whatever the
    /// lines of sight show: a cabinet's or wardrobe's side (0.4-0.8 m deep) offers too few of them.
    double wall_top_unseen_min_length_m = 1.0;
    /// ... and without one, they must span at least this height, metres.
    double min_wall_height_m = 1.2;
    /// Walls closer than this in angle (degrees) and offset (metres) are merged.
    double wall_merge_angle_deg = 5.0;
    double wall_merge_offset_m = 0.05;
    /// Opposite horizontal plane: within this angle of the base (degrees) and at least this far
    /// from it (metres).
    double opposite_max_angle_deg = 10.0;
    double min_room_height_m = 1.8;
    /// Weak Manhattan: walls within this angle of a multiple of 90 degrees from the reference
    /// wall are snapped to it exactly, degrees (reference §4.10 starts at 5). The layout-
    /// constrained registration then pulls the fragments onto the snapped walls, so snapping a
    /// wall that is not square moves the model: keep this below the angle of real rooms' walls
    /// that are meant to be off square.
    double snap_angle_deg = 1.5;
    /// Offsets are re-estimated over the plane's points within this distance, metres.
    double refit_band_m = 0.06;
    /// Room polygon: contour runs shorter than this many cells are ignored.
    int min_contour_run_cells = 4;
    /// Step 7: a plane the room polygon follows along several edges at least this long, metres,
    /// is one layout wall per edge, all on the plane (coplanar walls apart: the ends of the two
    /// arms of a U, the two sides of an alcove's opening), so that each has its own segment;
    /// otherwise its wall is the longest edge. 0: one layout wall per plane.
    double wall_split_min_edge_m = 0.5;
    /// Walls bound the camera's space (rules a-c above). Cells of the base grid within this
    /// distance of a camera position are occupied, metres (0: the path is not added). 0.3 m:
    /// the person holding the camera stands there, and 6 cells cover a 1.2 m gap to the seen
    /// floor a camera held at 1.4 m pitched down 8 degrees leaves around it.
    double path_occupancy_radius_m = 0.3;
    /// Lines of sight are free space: this many lines per fragment, from its middle camera to its
    /// points (a stride subsample), are occupied cells of the base grid (0: none). They join the
    /// path to the floor it saw from afar (a camera pitched down 8 degrees at 1.4 m sees no floor
    /// within 1.2 m of itself, and the path would be left outside the seen space).
    int free_space_rays_per_fragment = 300;
    /// Rule a: a wall with more than this fraction of the camera positions within its extent
    /// behind it is not a wall. A true wall has none behind it; 0.1 tolerates a path that grazes
    /// the end of a wall through a doorway.
    double max_camera_behind_fraction = 0.1;
    /// Rule a: camera positions closer than this to the wall count on neither side, metres.
    double camera_behind_margin_m = 0.1;
    /// Rule a, the top test (wall_top_seen_fraction) and the room polygon: a wall's extent is the
    /// pieces its points cover along it, split where they leave a gap wider than this, metres;
    /// camera positions and lines of sight count only within a piece, and the boundary contour
    /// is put on the wall only within 0.3 m of one. A gap where furniture hides a wall holds only
    /// camera positions in front of it and no line of sight over it, so splitting there changes
    /// nothing; a larger value joins a wall with a coplanar furniture face across open floor.
    double wall_piece_gap_m = 0.5;
    /// Rule b: walls within this angle of parallel may be stacked, degrees.
    double stacked_wall_angle_deg = 10.0;
    /// Rule b: the inner of two same-facing parallel walls at most this far apart is rejected,
    /// metres: kitchen counters and tall cabinets are 0.6 m deep, wardrobes 0.6, shelves 0.3-0.4
    /// (0 disables rules b and c).
    double stacked_wall_max_gap_m = 0.8;
};
void describe(config::Schema& s, LayoutConfig& c);

/// A dominant plane of the second clustering, in the world frame.
struct DominantPlane {
    int id = 0;
    Eigen::Vector3d normal_W = Eigen::Vector3d::UnitZ();
    double d_W = 0.0;
    double area_m2 = 0.0;  ///< occupied cells of its own grid x cell area
    int num_groups = 0;
    int num_points = 0;
    double rms_m = 0.0;
    std::vector<int> fragments;  ///< fragments contributing a group
};

/// Why a dominant plane is or is not a wall.
struct WallDecision {
    int plane_id = 0;
    bool kept = false;
    double abs_dot_base = 0.0;         ///< |n . n_base| (Eq. 6)
    double boundary_distance_m = 0.0;  ///< g(dO, pi) (Eq. 7)
    /// How far the plane's points stay below the ceiling (above the floor when the base is the
    /// ceiling), 99th percentile; without an opposite plane, min_wall_height_m minus its span.
    double top_gap_m = 0.0;
    /// For a plane short of the ceiling: the fraction of its extent over whose top lines of sight
    /// pass (LayoutConfig::wall_top_seen_fraction); -1 when not measured.
    double top_seen_fraction = -1.0;
    /// Rule a: the fraction of the camera positions within the wall's extent that lie behind it
    /// (outside the room); -1 when no camera position falls within its extent or the plane was
    /// rejected before.
    double camera_behind_fraction = -1.0;
    std::string reason;  ///< "wall", "base plane", "not vertical", "far from boundary",
                         ///< "too small", "does not reach the ceiling",
                         ///< "too low", "merged into N", "opposite plane", "camera behind it",
                         ///< "in front of wall N", "side of a block in front of wall N"
};

/// What the weak-Manhattan step did to one wall.
struct SnapDecision {
    int plane_id = 0;
    double angle_to_reference_deg = 0.0;  ///< before snapping, in [0, 180)
    double residual_deg = 0.0;            ///< distance to the nearest multiple of 90
    bool snapped = false;
    bool reference = false;
    Eigen::Vector3d normal_before_W = Eigen::Vector3d::Zero();  ///< verticalised, unsnapped
};

struct LayoutDiagnostics {
    int num_fragments = 0;
    int num_groups = 0;
    int num_hypotheses = 0;  ///< = groups (each group's plane is a hypothesis)
    int num_clusters = 0;    ///< second T-linkage clusters (before the area test)
    std::vector<DominantPlane> dominant_planes;
    int base_plane_id = -1;
    std::string base_kind;  ///< "floor" or "ceiling"
    int opposite_plane_id = -1;
    bool floor_inferred = false;  ///< no floor plane seen: z = 0 at the lowest points
    Eigen::Vector3d up_hint_W = Eigen::Vector3d::Zero();
    int grid_width = 0;
    int grid_height = 0;
    int occupied_cells = 0;
    int boundary_cells = 0;
    std::vector<WallDecision> walls;
    std::vector<SnapDecision> snapping;
    std::string polygon_method;    ///< "walls" (contour order) or "contour" (fallback)
    int num_camera_positions = 0;  ///< camera positions the wall rules used
    /// Fraction of the camera positions inside the room polygon (1 when there are none).
    double path_inside_fraction = 1.0;
    double ms_clustering = 0.0;
    double ms_grid = 0.0;
    double ms_total = 0.0;
};

struct LayoutEstimate {
    Layout layout;
    LayoutDiagnostics diagnostics;
};

/// Estimates the layout. `fragments`, `planes` and `T_W_F` are parallel (same size, same order;
/// planes[i] from extractFragmentPlanes(fragments[i])). Errors: size mismatch, non-rigid or
/// non-finite poses, no planes at all, no base plane, an invalid configuration.
Result<LayoutEstimate> estimateLayout(const std::vector<Fragment>& fragments,
                                      const std::vector<FragmentPlanes>& planes,
                                      const std::vector<Eigen::Isometry3d>& T_W_F,
                                      const LayoutConfig& config = {});

/// Diagnostics as a JSON object (for reports).
nlohmann::json toJson(const LayoutDiagnostics& diagnostics);

}  // namespace plumb::layout
