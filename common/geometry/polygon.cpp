// SPDX-License-Identifier: Apache-2.0
#include "common/geometry/polygon.hpp"

namespace plumb {

double signedArea(const std::vector<Eigen::Vector2d>& polygon) {
    double area = 0.0;
    for (size_t i = 0; i < polygon.size(); ++i) {
        area += cross2(polygon[i], polygon[(i + 1) % polygon.size()]);
    }
    return 0.5 * area;
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
