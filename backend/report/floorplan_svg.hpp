// SPDX-License-Identifier: Apache-2.0
#pragma once

// The floor plan (`floorplan.svg`), seen from above in the layout frame L (x right, y up on the
// page), drawn as the layout gives the room:
//  - the room polygon, with the area the scan saw shaded inside it (`seen`, clipped to it);
//  - its outline edge by edge, solid where a wall bounds it and dashed where it was inferred
//    (polygonEdgeWalls), each edge of 0.5 m or more with its length beside it (`lengths`), a
//    dot at every corner with its interior angle (`corners`);
//  - the walls (snapped walls in one colour, free-angle walls in another) with their ids;
//  - the room's width x depth (extent along L's x and y; x is normal to the largest wall) with
//    dimension lines, its area, how much of it was seen, the ceiling height or "ceiling not
//    seen" (`size`, `dimensions`); "seen part" instead of "room" when the outline is mostly
//    inferred;
//  - the fragment outlines (`fragments`) and the camera path (`path`);
//  - a "partial scan" warning (`partial`) when less than kClosedRoomWallFraction of the outline
//    lies on walls or less than kMinSeenFloorFraction of the room's area was seen;
//  - a 1 m scale bar and a legend.
// The ids in brackets are the SVG elements' (groups') ids. Algorithms here do no I/O except
// writeFloorplanSvg.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe;
// writeFloorplanSvg writes only its own file.

#include <Eigen/Geometry>
#include <filesystem>
#include <string>
#include <vector>

#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "common/layout/layout.hpp"

namespace plumb::layout {

/// A closed outline on the floor, x/y in L, metres.
using Outline2 = std::vector<Eigen::Vector2d>;

/// Below this fraction of the room's area seen, the plan warns of a partial scan. Furniture
/// hides the floor under it, and a handheld camera sees no floor within about a metre of
/// itself: complete scans of the simulated rooms see 41-59 % of them (600 frames at 30 Hz with
/// the ci camera: living_room 42 %, kitchen 41 %; one loop at 3 Hz: 47-59 %).
inline constexpr double kMinSeenFloorFraction = 0.25;

/// The area the scan saw, on a grid on the floor of L: cells where a point at most
/// max_height_m above the floor was seen (the floor or something standing on it), closed by one
/// cell.
struct SeenFloor {
    double cell_m = 0.05;
    /// Outer boundaries and holes of the seen cells (fill with the even-odd rule), x/y in L.
    std::vector<Outline2> outlines;
    double area_m2 = 0.0;          ///< seen cells x cell area
    double area_in_room_m2 = 0.0;  ///< of those, the cells whose centre is inside the polygon
};

/// The seen floor of `fragments` at the poses T_W_F (parallel), at most
/// `max_points_per_fragment` points per fragment (stride subsample).
SeenFloor seenFloor(const std::vector<Fragment>& fragments,
                    const std::vector<Eigen::Isometry3d>& T_W_F, const Layout& layout,
                    double cell_m = 0.05, double max_height_m = 2.0,
                    size_t max_points_per_fragment = 20000);

/// The camera path (every tracked frame's position T_W_F * T_F_C, a fragment's origin when it
/// lists no frames) in L's x/y, in frame order.
std::vector<Eigen::Vector2d> cameraPath(const std::vector<Fragment>& fragments,
                                        const std::vector<Eigen::Isometry3d>& T_W_F,
                                        const Layout& layout);

/// The convex hull (counter-clockwise) of each fragment's points in L's x/y, with the poses
/// T_W_F (parallel to `fragments`); at most `max_points_per_fragment` points are used per
/// fragment (stride subsample). Fragments with fewer than 3 points give an empty outline.
std::vector<Outline2> fragmentOutlines(const std::vector<Fragment>& fragments,
                                       const std::vector<Eigen::Isometry3d>& T_W_F,
                                       const Layout& layout, size_t max_points_per_fragment = 5000);

/// What the plan draws besides the layout; every member may be empty.
struct FloorplanOverlays {
    std::vector<Outline2> fragment_outlines;     ///< fragmentOutlines()
    SeenFloor seen;                              ///< seenFloor(); no outlines = not known
    std::vector<Eigen::Vector2d> camera_path_L;  ///< cameraPath()
};

/// The overlays of `fragments` at T_W_F: their outlines, seen floor and camera path.
FloorplanOverlays floorplanOverlays(const std::vector<Fragment>& fragments,
                                    const std::vector<Eigen::Isometry3d>& T_W_F,
                                    const Layout& layout);

/// The figures the plan states, from the layout (and the seen floor when known).
struct FloorplanFigures {
    double width_m = 0.0;                   ///< extent of the room polygon along L's x, metres
    double depth_m = 0.0;                   ///< ... along L's y, metres
    double area_m2 = 0.0;                   ///< the polygon's area
    std::vector<double> edge_lengths_m;     ///< polygon edge k (vertex k -> k + 1), metres
    std::vector<int> edge_walls;            ///< polygonEdgeWalls(): wall id or -1 (inferred)
    std::vector<double> corner_angles_deg;  ///< interior angle at vertex k, degrees
    double wall_bounded_fraction = 0.0;     ///< wallBoundedFraction()
    double seen_fraction = -1.0;            ///< seen area in the room / area; -1 when unknown
    bool partial = false;  ///< the outline or the seen area says the scan saw part of the room
};

FloorplanFigures floorplanFigures(const Layout& layout, const SeenFloor& seen = {});

/// The SVG document text.
std::string floorplanSvg(const Layout& layout, const FloorplanOverlays& overlays = {});

/// Writes floorplanSvg() to `path`. kIoError when the file cannot be written.
Status writeFloorplanSvg(const std::filesystem::path& path, const Layout& layout,
                         const FloorplanOverlays& overlays = {});

}  // namespace plumb::layout
