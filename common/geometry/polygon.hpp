// SPDX-License-Identifier: Apache-2.0
#pragma once

// Plane geometry of 2-D points and polygons (vertices in order, either orientation, the last
// joined to the first). Pure functions: thread-safe.

#include <Eigen/Core>
#include <vector>

namespace plumb {

/// The z component of the cross product a x b: positive when b turns counter-clockwise from a.
inline double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return a.x() * b.y() - a.y() * b.x();
}

/// Twice the signed area of triangle (a, b, c): positive when counter-clockwise.
inline double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
    return cross2(b - a, c - a);
}

/// The polygon's signed area (shoelace formula): positive when counter-clockwise.
double signedArea(const std::vector<Eigen::Vector2d>& polygon);

/// Convex hull (Andrew's monotone chain), counter-clockwise, without repeating the first vertex
/// and without collinear vertices. Fewer than 3 distinct points: those points, sorted by x then y.
std::vector<Eigen::Vector2d> convexHull(std::vector<Eigen::Vector2d> points);

/// True when `q` lies inside the polygon (even-odd rule; a point on an edge may count either
/// way). Any orientation; fewer than 3 vertices contain nothing.
bool insidePolygon(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& q);

}  // namespace plumb
