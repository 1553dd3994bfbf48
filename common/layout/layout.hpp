// SPDX-License-Identifier: Apache-2.0
#pragma once

// A room layout: floor, ceiling and walls in a gravity-aligned layout frame L (z up, floor at
// z = 0), plus the transform to the world frame W of the reconstruction. Planes are in Hessian
// form n.x + d = 0 with |n| = 1 (never the paper's [a,b,c,1]).

#include <Eigen/Geometry>
#include <filesystem>
#include <string>
#include <vector>

#include "common/core/status.hpp"

namespace plumb {

enum class LayoutPlaneKind { kFloor, kCeiling, kWall };

const char* toString(LayoutPlaneKind kind);

struct LayoutPlane {
    int id = 0;
    LayoutPlaneKind kind = LayoutPlaneKind::kWall;
    Eigen::Vector3d normal_L = Eigen::Vector3d::UnitZ();  ///< unit normal in L, points into room
    double d_L = 0.0;                                     ///< offset: n.x + d = 0 in L, metres
    /// Walls: the segment on the floor (x, y in L) the wall spans, metres.
    Eigen::Vector2d start_L = Eigen::Vector2d::Zero();
    Eigen::Vector2d end_L = Eigen::Vector2d::Zero();
    /// Walls: true when the weak-Manhattan step made it exactly orthogonal to a neighbour.
    bool manhattan_snapped = false;
};

struct Layout {
    /// Layout frame -> world frame (identity for ground truth expressed in L itself).
    Eigen::Isometry3d T_W_L = Eigen::Isometry3d::Identity();
    std::vector<LayoutPlane> planes;
    /// Room outline on the floor, counter-clockwise seen from above, x/y in L, metres.
    std::vector<Eigen::Vector2d> room_polygon_L;
    double ceiling_height_m = 0.0;  ///< floor-to-ceiling distance, 0 if unknown

    std::vector<const LayoutPlane*> walls() const;
};

}  // namespace plumb
