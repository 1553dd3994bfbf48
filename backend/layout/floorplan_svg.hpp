// SPDX-License-Identifier: Apache-2.0
#pragma once

// The floor plan (`floorplan.svg`): the room polygon with its outline solid where a wall bounds
// it and dashed where it was inferred (polygonEdgeWalls), the walls (snapped walls in one colour,
// free-angle walls in another), optional fragment outlines, a 1 m scale bar and, when less than
// kClosedRoomWallFraction of the outline lies on walls, a "partial scan" warning; seen from above
// in the layout frame L (x right, y up on the page).

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

/// The SVG document text. `outlines` may be empty.
std::string floorplanSvg(const Layout& layout, const std::vector<Outline2>& outlines = {});

/// Writes floorplanSvg() to `path`. kIoError when the file cannot be written.
Status writeFloorplanSvg(const std::filesystem::path& path, const Layout& layout,
                         const std::vector<Outline2>& outlines = {});

/// The convex hull (counter-clockwise) of each fragment's points in L's x/y, with the poses
/// T_W_F (parallel to `fragments`); at most `max_points_per_fragment` points are used per
/// fragment (stride subsample). Fragments with fewer than 3 points give an empty outline.
std::vector<Outline2> fragmentOutlines(const std::vector<Fragment>& fragments,
                                       const std::vector<Eigen::Isometry3d>& T_W_F,
                                       const Layout& layout, size_t max_points_per_fragment = 5000);

}  // namespace plumb::layout
