// SPDX-License-Identifier: Apache-2.0
#pragma once

// A room layout: floor, ceiling and walls in a gravity-aligned layout frame L (z up, floor at
// z = 0), plus the transform to the world frame W of the reconstruction. Planes are in Hessian
// form n.x + d = 0 with |n| = 1 (never the paper's [a,b,c,1]).
//
// Thread-safety: value types; const access from several threads is safe, a write needs
// exclusive access; the free functions are pure.

#include <Eigen/Geometry>
#include <filesystem>
#include <string>
#include <vector>

#include "common/core/status.hpp"
#include "common/geometry/polygon.hpp"  // insidePolygon, signedArea (room polygons)

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

    /// The wall planes, in the order they appear in `planes`.
    std::vector<const LayoutPlane*> walls() const;
    /// The first plane of the given kind, nullptr if there is none.
    const LayoutPlane* firstOf(LayoutPlaneKind kind) const;
};

/// A plane n.x + d = 0 (|n| = 1) in a frame the owner names.
struct HessianPlane {
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
    double d = 0.0;  ///< metres

    /// Signed distance of x from the plane (positive on the side the normal points to), metres.
    double signedDistance(const Eigen::Vector3d& x) const { return normal.dot(x) + d; }
};

/// The plane in frame B from the plane in frame A and T_B_A (reference §0):
/// n_B = R n_A, d_B = d_A - n_B.t.
HessianPlane transformPlane(const HessianPlane& plane_A, const Eigen::Isometry3d& T_B_A);

/// A layout plane (given in L) expressed in the world frame with the layout's T_W_L.
HessianPlane planeInWorld(const Layout& layout, const LayoutPlane& plane);

/// Parses "floor" | "ceiling" | "wall".
Result<LayoutPlaneKind> parseLayoutPlaneKind(const std::string& text);

/// Which wall bounds each edge of the room polygon: element k is for edge k (vertex k -> k+1,
/// wrapping) and holds the id of the wall plane the edge lies on, or -1 when no wall does (the
/// boundary there was inferred: the edge of the seen floor, or a step joining two walls). An edge
/// lies on a wall when both its ends are within `tolerance_m` of the wall's line and its midpoint
/// is within the wall's segment (start_L..end_L, widened by `tolerance_m`).
std::vector<int> polygonEdgeWalls(const Layout& layout, double tolerance_m = 0.05);

/// The fraction of the room polygon's perimeter that lies on walls (polygonEdgeWalls != -1); 0
/// for a polygon with fewer than 3 vertices.
double wallBoundedFraction(const Layout& layout, double tolerance_m = 0.05);

/// The polygon's area (absolute value of the shoelace sum), m^2 for a polygon in metres.
double polygonArea(const std::vector<Eigen::Vector2d>& polygon);

/// A room counts as closed when at least this fraction of its outline lies on walls; below it
/// the outline is mostly the edge of the seen floor (the scan saw only part of the room).
inline constexpr double kClosedRoomWallFraction = 0.8;

/// Builds the layout of a prism-shaped room from its floor outline and height, with T_W_L =
/// identity:
///  - id 0: floor, n = (0, 0, 1), d = 0;
///  - id 1: ceiling, n = (0, 0, -1), d = height;
///  - id 2 + k: the wall over polygon edge k (vertex k -> vertex k+1, wrapping), normal pointing
///    into the room (the left side of a counter-clockwise edge), start_L/end_L = the edge.
/// The polygon must be simple, counter-clockwise seen from above (+z), with at least 3 vertices
/// and edges of at least 1 mm; the height must be positive. Errors say which condition failed.
Result<Layout> makeRoomLayout(const std::vector<Eigen::Vector2d>& polygon_L,
                              double ceiling_height_m);

}  // namespace plumb
