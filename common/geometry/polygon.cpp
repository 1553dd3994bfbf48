// SPDX-License-Identifier: Apache-2.0
#include "common/geometry/polygon.hpp"

#include <algorithm>

namespace plumb {

double signedArea(const std::vector<Eigen::Vector2d>& polygon) {
    double area = 0.0;
    for (size_t i = 0; i < polygon.size(); ++i) {
        area += cross2(polygon[i], polygon[(i + 1) % polygon.size()]);
    }
    return 0.5 * area;
}

std::vector<Eigen::Vector2d> convexHull(std::vector<Eigen::Vector2d> points) {
    std::sort(points.begin(), points.end(), [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
        return a.x() != b.x() ? a.x() < b.x() : a.y() < b.y();
    });
    points.erase(std::unique(points.begin(), points.end()), points.end());
    if (points.size() < 3) return points;
    std::vector<Eigen::Vector2d> hull(2 * points.size());
    size_t k = 0;
    for (const auto& p : points) {  // lower hull
        while (k >= 2 && cross2(hull[k - 2], hull[k - 1], p) <= 0) --k;
        hull[k++] = p;
    }
    for (size_t i = points.size() - 1, t = k + 1; i-- > 0;) {  // upper hull
        while (k >= t && cross2(hull[k - 2], hull[k - 1], points[i]) <= 0) --k;
        hull[k++] = points[i];
    }
    hull.resize(k - 1);  // the last point repeats the first
    return hull;
}

bool insidePolygon(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& q) {
    if (polygon.size() < 3) return false;
    bool inside = false;
    for (size_t k = 0, j = polygon.size() - 1; k < polygon.size(); j = k++) {
        const Eigen::Vector2d& a = polygon[k];
        const Eigen::Vector2d& b = polygon[j];
        if ((a.y() > q.y()) != (b.y() > q.y()) &&
            q.x() < (b.x() - a.x()) * (q.y() - a.y()) / (b.y() - a.y()) + a.x()) {
            inside = !inside;
        }
    }
    return inside;
}

}  // namespace plumb
