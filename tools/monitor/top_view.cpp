// SPDX-License-Identifier: Apache-2.0
#include "tools/monitor/top_view.hpp"

#include <algorithm>
#include <cmath>

#include "common/geometry/polygon.hpp"

namespace plumb::monitor {

Eigen::Isometry3d viewFromWorld(const Layout* layout) {
    if (layout != nullptr) return layout->T_W_L.inverse();
    Eigen::Isometry3d T_V_W = Eigen::Isometry3d::Identity();
    Eigen::Matrix3d R;
    R << 1, 0, 0,  //
        0, 0, 1,   //
        0, -1, 0;  // z_V = -y_W (camera y points down)
    T_V_W.linear() = R;
    return T_V_W;
}

double CoverageGrid::coverageFraction() const {
    return cells_of_interest > 0
               ? static_cast<double>(covered_of_interest) / static_cast<double>(cells_of_interest)
               : 0.0;
}

CoverageGrid computeCoverage(const std::vector<Eigen::Vector2d>& points_V,
                             const std::vector<Eigen::Vector2d>& room_polygon_V,
                             const CoverageConfig& config) {
    CoverageGrid grid;
    grid.cell_m = config.cell_m;
    grid.room_polygon = room_polygon_V.size() >= 3;
    const std::vector<Eigen::Vector2d> region =
        grid.room_polygon ? room_polygon_V : convexHull(points_V);
    if (region.size() < 3) return grid;

    Eigen::Vector2d lo = region[0], hi = region[0];
    for (const auto& p : region) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    const double side = std::max(hi.x() - lo.x(), hi.y() - lo.y());
    if (!(side > 0.0) || !std::isfinite(side)) return grid;
    const int cap = std::max(1, config.max_cells_per_side);
    if (side / grid.cell_m > cap) grid.cell_m = side / cap;  // coarsen huge regions
    grid.origin_V = lo;
    grid.width = std::max(1, static_cast<int>(std::ceil((hi.x() - lo.x()) / grid.cell_m)));
    grid.height = std::max(1, static_cast<int>(std::ceil((hi.y() - lo.y()) / grid.cell_m)));

    std::vector<uint8_t> covered(static_cast<size_t>(grid.width) * grid.height, 0);
    for (const auto& p : points_V) {
        const double fx = std::floor((p.x() - lo.x()) / grid.cell_m);
        const double fy = std::floor((p.y() - lo.y()) / grid.cell_m);
        if (!(fx >= 0 && fy >= 0 && fx < grid.width && fy < grid.height)) continue;
        covered[static_cast<size_t>(fy) * grid.width + static_cast<size_t>(fx)] = 1;
    }
    for (int iy = 0; iy < grid.height; ++iy) {
        for (int ix = 0; ix < grid.width; ++ix) {
            const Eigen::Vector2d centre = lo + grid.cell_m * Eigen::Vector2d(ix + 0.5, iy + 0.5);
            if (!insidePolygon(region, centre)) continue;
            ++grid.cells_of_interest;
            if (covered[static_cast<size_t>(iy) * grid.width + ix]) {
                ++grid.covered_of_interest;
            } else {
                grid.gaps.emplace_back(ix, iy);
            }
        }
    }
    return grid;
}

}  // namespace plumb::monitor
