// SPDX-License-Identifier: Apache-2.0
#include "backend/layout/floorplan_svg.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <fstream>

namespace plumb::layout {
namespace {

/// Andrew's monotone chain, counter-clockwise.
Outline2 convexHull(std::vector<Eigen::Vector2d> pts) {
    std::sort(pts.begin(), pts.end(), [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
        return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
    });
    if (pts.size() < 3) return {};
    auto cross = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
        return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
    };
    Outline2 hull(2 * pts.size());
    size_t k = 0;
    for (size_t i = 0; i < pts.size(); ++i) {
        while (k >= 2 && cross(hull[k - 2], hull[k - 1], pts[i]) <= 0) --k;
        hull[k++] = pts[i];
    }
    for (size_t i = pts.size() - 1, t = k + 1; i > 0; --i) {
        while (k >= t && cross(hull[k - 2], hull[k - 1], pts[i - 1]) <= 0) --k;
        hull[k++] = pts[i - 1];
    }
    hull.resize(k - 1);
    return hull;
}

}  // namespace

std::string floorplanSvg(const Layout& layout, const std::vector<Outline2>& outlines) {
    // Bounds over everything drawn.
    Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
    auto grow = [&](const Eigen::Vector2d& p) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    };
    for (const auto& p : layout.room_polygon_L) grow(p);
    for (const LayoutPlane* w : layout.walls()) {
        grow(w->start_L);
        grow(w->end_L);
    }
    for (const Outline2& o : outlines) {
        for (const auto& p : o) grow(p);
    }
    if (lo.x() > hi.x()) {
        lo = Eigen::Vector2d(0, 0);
        hi = Eigen::Vector2d(1, 1);
    }
    const double margin = 0.6;  // metres around the drawing (room for the scale bar)
    lo -= Eigen::Vector2d(margin, margin);
    hi += Eigen::Vector2d(margin, margin);
    const double scale = 100.0;  // px per metre
    // At least 7 m wide (the warning's width), the drawing centred; 0.4 m more on top for it.
    const double min_width_m = 7.0;
    if (hi.x() - lo.x() < min_width_m) {
        const double grow_x = 0.5 * (min_width_m - (hi.x() - lo.x()));
        lo.x() -= grow_x;
        hi.x() += grow_x;
    }
    hi.y() += 0.4;
    const double width = (hi.x() - lo.x()) * scale, height = (hi.y() - lo.y()) * scale;
    // L's y points up; SVG's y points down.
    auto X = [&](const Eigen::Vector2d& p) { return (p.x() - lo.x()) * scale; };
    auto Y = [&](const Eigen::Vector2d& p) { return (hi.y() - p.y()) * scale; };
    auto points = [&](const std::vector<Eigen::Vector2d>& poly) {
        std::string s;
        for (const auto& p : poly) s += fmt::format("{:.1f},{:.1f} ", X(p), Y(p));
        return s;
    };

    std::string svg = fmt::format(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{:.0f}\" height=\"{:.0f}\" "
        "viewBox=\"0 0 {:.1f} {:.1f}\">\n"
        "<title>plumb floor plan (layout frame L, metres)</title>\n"
        "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
        width, height, width, height);
    svg +=
        "<g id=\"fragments\" fill=\"none\" stroke=\"#9ab\" stroke-width=\"1\" "
        "stroke-dasharray=\"4 3\">\n";
    for (const Outline2& o : outlines) {
        if (o.size() >= 3) svg += fmt::format("<polygon points=\"{}\"/>\n", points(o));
    }
    svg += "</g>\n";
    const std::vector<Eigen::Vector2d>& poly = layout.room_polygon_L;
    if (poly.size() >= 3) {
        svg +=
            fmt::format("<polygon id=\"room\" points=\"{}\" fill=\"#f3efe4\" stroke=\"none\"/>\n",
                        points(poly));
        // The outline edge by edge: solid where a wall bounds it, dashed where it was inferred
        // (the edge of the seen floor, a step joining two walls).
        const std::vector<int> edge_walls = polygonEdgeWalls(layout);
        svg += "<g id=\"outline\" stroke=\"#555\" stroke-width=\"1.5\">\n";
        for (size_t k = 0; k < poly.size(); ++k) {
            const Eigen::Vector2d& a = poly[k];
            const Eigen::Vector2d& b = poly[(k + 1) % poly.size()];
            const bool seen = edge_walls[k] >= 0;
            svg += fmt::format(
                "<line class=\"{}\" x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\"{}>"
                "<title>{}, {:.2f} m</title></line>\n",
                seen ? "seen" : "inferred", X(a), Y(a), X(b), Y(b),
                seen ? "" : " stroke-dasharray=\"6 4\"",
                seen ? fmt::format("on wall {}", edge_walls[k]) : std::string("inferred"),
                (b - a).norm());
        }
        svg += "</g>\n";
    }
    svg += "<g id=\"walls\" stroke-width=\"6\" stroke-linecap=\"round\">\n";
    for (const LayoutPlane* w : layout.walls()) {
        svg += fmt::format(
            "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"{}\">"
            "<title>wall {}{}</title></line>\n",
            X(w->start_L), Y(w->start_L), X(w->end_L), Y(w->end_L),
            w->manhattan_snapped ? "#1f5fa8" : "#c0392b", w->id,
            w->manhattan_snapped ? " (Manhattan-snapped)" : " (free angle)");
        const Eigen::Vector2d mid = 0.5 * (w->start_L + w->end_L);
        const Eigen::Vector2d lab = mid + 0.25 * w->normal_L.head<2>();
        svg += fmt::format(
            "<text x=\"{:.1f}\" y=\"{:.1f}\" font-family=\"sans-serif\" font-size=\"14\" "
            "text-anchor=\"middle\" stroke=\"none\" fill=\"#333\">{}</text>\n",
            X(lab), Y(lab), w->id);
    }
    svg += "</g>\n";
    // Scale bar: 1 m in the lower-left margin.
    const Eigen::Vector2d s0(lo.x() + 0.2, lo.y() + 0.25), s1(lo.x() + 1.2, lo.y() + 0.25);
    svg += fmt::format(
        "<g id=\"scale\"><line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" "
        "stroke=\"black\" stroke-width=\"3\"/><text x=\"{:.1f}\" y=\"{:.1f}\" "
        "font-family=\"sans-serif\" font-size=\"14\" text-anchor=\"middle\">1 m</text></g>\n",
        X(s0), Y(s0), X(s1), Y(s1), 0.5 * (X(s0) + X(s1)), Y(s0) - 8);
    if (layout.ceiling_height_m > 0) {
        svg += fmt::format(
            "<text x=\"{:.1f}\" y=\"{:.1f}\" font-family=\"sans-serif\" font-size=\"14\">"
            "ceiling {:.2f} m</text>\n",
            X(s1) + 20, Y(s0) + 5, layout.ceiling_height_m);
    }
    const double on_walls = wallBoundedFraction(layout);
    if (poly.size() >= 3 && on_walls < kClosedRoomWallFraction) {
        svg += fmt::format(
            "<text id=\"partial\" x=\"10\" y=\"24\" font-family=\"sans-serif\" font-size=\"14\" "
            "font-weight=\"bold\" fill=\"#b7791f\">partial scan: {:.0f} % of the outline lies on "
            "seen walls; dashed edges are inferred</text>\n",
            100.0 * on_walls);
    }
    svg += "</svg>\n";
    return svg;
}

Status writeFloorplanSvg(const std::filesystem::path& path, const Layout& layout,
                         const std::vector<Outline2>& outlines) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) return ioError(fmt::format("{}: cannot open for writing", path.string()));
    out << floorplanSvg(layout, outlines);
    out.flush();
    if (!out) return ioError(fmt::format("{}: write failed", path.string()));
    return Status::ok();
}

std::vector<Outline2> fragmentOutlines(const std::vector<Fragment>& fragments,
                                       const std::vector<Eigen::Isometry3d>& T_W_F,
                                       const Layout& layout, size_t max_points_per_fragment) {
    std::vector<Outline2> out;
    const Eigen::Isometry3d T_L_W = layout.T_W_L.inverse();
    for (size_t i = 0; i < fragments.size() && i < T_W_F.size(); ++i) {
        const auto& pts = fragments[i].points_F.points;
        const size_t stride = std::max<size_t>(1, (pts.size() + max_points_per_fragment - 1) /
                                                      std::max<size_t>(1, max_points_per_fragment));
        std::vector<Eigen::Vector2d> xy;
        const Eigen::Isometry3d T_L_F = T_L_W * T_W_F[i];
        for (size_t k = 0; k < pts.size(); k += stride) {
            if (!pts[k].allFinite()) continue;
            xy.push_back((T_L_F * pts[k].cast<double>()).head<2>());
        }
        out.push_back(convexHull(std::move(xy)));
    }
    return out;
}

}  // namespace plumb::layout
