// SPDX-License-Identifier: Apache-2.0
#pragma once

// Top-view geometry of the monitor: the view frame V (z up), fragment outlines and the coverage
// grid. Pure functions, no I/O.
//
// View frame V: with a layout, V = the layout frame L (gravity-aligned, floor at z = 0), so
// T_V_W = T_W_L^-1. Without one, the world frame W is the camera frame of the first frame
// (x right, y down, z forward; DESIGN.md), and a handheld scan starts roughly level, so "up" is
// taken as -y_W: V = (x_W, z_W, -y_W), a proper rotation (det = +1).

#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <vector>

#include "common/layout/layout.hpp"

namespace plumb::monitor {

/// T_V_W: world -> view frame (see the header comment).
Eigen::Isometry3d viewFromWorld(const Layout* layout);

struct CoverageConfig {
    /// Edge length of a coverage cell on the floor, metres.
    double cell_m = 0.25;
    /// Largest number of cells along one side (the grid is coarsened beyond it).
    int max_cells_per_side = 256;
};

/// A top-view coverage grid: a cell is covered when at least one observed point (any height)
/// projects into it. Cells of interest are those whose centre lies inside the room polygon when
/// a layout is known, else inside the convex hull of all observed points. Gaps are cells of
/// interest that are not covered: unseen floor the user should still walk to.
struct CoverageGrid {
    double cell_m = 0.25;                                ///< cell edge length, metres
    Eigen::Vector2d origin_V = Eigen::Vector2d::Zero();  ///< corner of cell (0, 0) in V, metres
    int width = 0;                                       ///< cells along x
    int height = 0;                                      ///< cells along y
    bool room_polygon = false;  ///< cells of interest come from the layout's room polygon
    int64_t cells_of_interest = 0;
    int64_t covered_of_interest = 0;
    std::vector<Eigen::Vector2i> gaps;  ///< (ix, iy) of uncovered cells of interest
    /// covered_of_interest / cells_of_interest (0 when there are no cells of interest).
    double coverageFraction() const;
};

/// Builds the grid from observed points already in V (only x, y are used) and the room polygon in
/// V (empty: none).
CoverageGrid computeCoverage(const std::vector<Eigen::Vector2d>& points_V,
                             const std::vector<Eigen::Vector2d>& room_polygon_V,
                             const CoverageConfig& config);

}  // namespace plumb::monitor
