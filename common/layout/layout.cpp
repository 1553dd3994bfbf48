// SPDX-License-Identifier: Apache-2.0
#include "common/layout/layout.hpp"

#include <fmt/format.h>

#include <cmath>

namespace plumb {
namespace {

constexpr double kMinEdgeLengthM = 1e-3;

bool onSegment(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& p) {
    return std::min(a.x(), b.x()) <= p.x() && p.x() <= std::max(a.x(), b.x()) &&
           std::min(a.y(), b.y()) <= p.y() && p.y() <= std::max(a.y(), b.y());
}

/// True when the closed segments [a, b] and [c, e] share at least one point.
bool segmentsTouch(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c,
                   const Eigen::Vector2d& e) {
    const double d1 = cross2(c, e, a), d2 = cross2(c, e, b);
    const double d3 = cross2(a, b, c), d4 = cross2(a, b, e);
    if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) {
        return true;
    }
    return (d1 == 0 && onSegment(c, e, a)) || (d2 == 0 && onSegment(c, e, b)) ||
           (d3 == 0 && onSegment(a, b, c)) || (d4 == 0 && onSegment(a, b, e));
}

}  // namespace

const char* toString(LayoutPlaneKind kind) {
    switch (kind) {
        case LayoutPlaneKind::kFloor:
            return "floor";
        case LayoutPlaneKind::kCeiling:
            return "ceiling";
        case LayoutPlaneKind::kWall:
            return "wall";
    }
    return "unknown";
}

Result<LayoutPlaneKind> parseLayoutPlaneKind(const std::string& text) {
    if (text == "floor") return LayoutPlaneKind::kFloor;
    if (text == "ceiling") return LayoutPlaneKind::kCeiling;
    if (text == "wall") return LayoutPlaneKind::kWall;
    return invalidArgument(
        fmt::format("unknown layout plane kind '{}' (expected floor, ceiling or wall)", text));
}

std::vector<const LayoutPlane*> Layout::walls() const {
    std::vector<const LayoutPlane*> out;
    for (const LayoutPlane& p : planes) {
        if (p.kind == LayoutPlaneKind::kWall) out.push_back(&p);
    }
    return out;
}

const LayoutPlane* Layout::firstOf(LayoutPlaneKind kind) const {
    for (const LayoutPlane& p : planes) {
        if (p.kind == kind) return &p;
    }
    return nullptr;
}

std::vector<int> polygonEdgeWalls(const Layout& layout, double tolerance_m) {
    const std::vector<Eigen::Vector2d>& poly = layout.room_polygon_L;
    std::vector<int> out(poly.size(), -1);
    const std::vector<const LayoutPlane*> walls = layout.walls();
    for (size_t k = 0; k < poly.size(); ++k) {
        const Eigen::Vector2d& a = poly[k];
        const Eigen::Vector2d& b = poly[(k + 1) % poly.size()];
        double best = tolerance_m;
        for (const LayoutPlane* w : walls) {
            const Eigen::Vector2d n = w->normal_L.head<2>();
            if (n.norm() < 0.5) continue;  // not a vertical plane
            const double da = std::abs(n.dot(a) + w->d_L), db = std::abs(n.dot(b) + w->d_L);
            if (std::max(da, db) > best) continue;
            const Eigen::Vector2d along = w->end_L - w->start_L;
            const double length = along.norm();
            if (length > 0.0) {
                const double t = along.dot(0.5 * (a + b) - w->start_L) / length;
                if (t < -tolerance_m || t > length + tolerance_m) continue;
            }
            best = std::max(da, db);
            out[k] = w->id;
        }
    }
    return out;
}

double polygonArea(const std::vector<Eigen::Vector2d>& polygon) {
    double twice = 0.0;
    for (size_t k = 0; k < polygon.size(); ++k) {
        const Eigen::Vector2d& p = polygon[k];
        const Eigen::Vector2d& q = polygon[(k + 1) % polygon.size()];
        twice += p.x() * q.y() - q.x() * p.y();
    }
    return 0.5 * std::abs(twice);
}

double wallBoundedFraction(const Layout& layout, double tolerance_m) {
    const std::vector<Eigen::Vector2d>& poly = layout.room_polygon_L;
    if (poly.size() < 3) return 0.0;
    const std::vector<int> edge_walls = polygonEdgeWalls(layout, tolerance_m);
    double on_walls = 0.0, perimeter = 0.0;
    for (size_t k = 0; k < poly.size(); ++k) {
        const double length = (poly[(k + 1) % poly.size()] - poly[k]).norm();
        perimeter += length;
        if (edge_walls[k] >= 0) on_walls += length;
    }
    return perimeter > 0.0 ? on_walls / perimeter : 0.0;
}

HessianPlane transformPlane(const HessianPlane& plane_A, const Eigen::Isometry3d& T_B_A) {
    HessianPlane plane_B;
    plane_B.normal = T_B_A.linear() * plane_A.normal;
    plane_B.d = plane_A.d - plane_B.normal.dot(T_B_A.translation());
    return plane_B;
}

HessianPlane planeInWorld(const Layout& layout, const LayoutPlane& plane) {
    return transformPlane(HessianPlane{plane.normal_L, plane.d_L}, layout.T_W_L);
}

Result<Layout> makeRoomLayout(const std::vector<Eigen::Vector2d>& polygon_L,
                              double ceiling_height_m) {
    const size_t n = polygon_L.size();
    if (n < 3) {
        return invalidArgument(
            fmt::format("room polygon has {} vertices; at least 3 are needed", n));
    }
    if (!std::isfinite(ceiling_height_m) || ceiling_height_m <= 0.0) {
        return invalidArgument(
            fmt::format("ceiling height must be positive, got {} m", ceiling_height_m));
    }
    double twice_area = 0.0;
    for (size_t k = 0; k < n; ++k) {
        const Eigen::Vector2d& a = polygon_L[k];
        const Eigen::Vector2d& b = polygon_L[(k + 1) % n];
        if (!a.allFinite()) {
            return invalidArgument(fmt::format("room polygon vertex {} is not finite", k));
        }
        if ((b - a).norm() < kMinEdgeLengthM) {
            return invalidArgument(fmt::format(
                "room polygon edge {} ({} -> {}) is shorter than 1 mm", k, k, (k + 1) % n));
        }
        twice_area += a.x() * b.y() - b.x() * a.y();
    }
    if (twice_area <= 0.0) {
        return invalidArgument(
            fmt::format("room polygon is clockwise or degenerate (signed area {} m^2); it must be "
                        "counter-clockwise seen from above",
                        0.5 * twice_area));
    }
    // Simple polygon: non-adjacent edges never touch.
    for (size_t i = 0; i < n; ++i) {
        for (size_t j = i + 2; j < n; ++j) {
            if (i == 0 && j == n - 1) continue;  // adjacent through the wrap-around
            if (segmentsTouch(polygon_L[i], polygon_L[(i + 1) % n], polygon_L[j],
                              polygon_L[(j + 1) % n])) {
                return invalidArgument(
                    fmt::format("room polygon is not simple: edges {} and {} intersect", i, j));
            }
        }
    }

    Layout layout;
    layout.room_polygon_L = polygon_L;
    layout.ceiling_height_m = ceiling_height_m;
    LayoutPlane floor;
    floor.id = 0;
    floor.kind = LayoutPlaneKind::kFloor;
    floor.normal_L = Eigen::Vector3d::UnitZ();
    floor.d_L = 0.0;
    layout.planes.push_back(floor);
    LayoutPlane ceiling;
    ceiling.id = 1;
    ceiling.kind = LayoutPlaneKind::kCeiling;
    ceiling.normal_L = -Eigen::Vector3d::UnitZ();
    ceiling.d_L = ceiling_height_m;  // -z + h = 0 at z = h
    layout.planes.push_back(ceiling);
    for (size_t k = 0; k < n; ++k) {
        const Eigen::Vector2d& a = polygon_L[k];
        const Eigen::Vector2d& b = polygon_L[(k + 1) % n];
        const Eigen::Vector2d e = (b - a).normalized();
        LayoutPlane wall;
        wall.id = static_cast<int>(2 + k);
        wall.kind = LayoutPlaneKind::kWall;
        // The interior of a counter-clockwise polygon lies left of each edge: rotate e by +90 deg.
        wall.normal_L = Eigen::Vector3d(-e.y(), e.x(), 0.0);
        wall.d_L = -wall.normal_L.head<2>().dot(a);
        wall.start_L = a;
        wall.end_L = b;
        layout.planes.push_back(wall);
    }
    return layout;
}

}  // namespace plumb
