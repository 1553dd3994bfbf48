// SPDX-License-Identifier: Apache-2.0
#include "backend/report/floorplan_svg.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "common/geometry/polygon.hpp"
#include "common/io/text_file.hpp"

namespace plumb::layout {
namespace {

/// Points of fragment i in L (a stride subsample of at most `max_points`), finite ones only.
template <typename Fn>
void forEachPointL(const std::vector<Fragment>& fragments,
                   const std::vector<Eigen::Isometry3d>& T_W_F, const Layout& layout,
                   size_t max_points, Fn&& fn) {
    const Eigen::Isometry3d T_L_W = layout.T_W_L.inverse();
    for (size_t i = 0; i < fragments.size() && i < T_W_F.size(); ++i) {
        const auto& pts = fragments[i].points_F.points;
        const size_t stride =
            std::max<size_t>(1, (pts.size() + max_points - 1) / std::max<size_t>(1, max_points));
        const Eigen::Isometry3d T_L_F = T_L_W * T_W_F[i];
        for (size_t k = 0; k < pts.size(); k += stride) {
            if (pts[k].allFinite()) fn(i, Eigen::Vector3d(T_L_F * pts[k].cast<double>()));
        }
    }
}

}  // namespace

SeenFloor seenFloor(const std::vector<Fragment>& fragments,
                    const std::vector<Eigen::Isometry3d>& T_W_F, const Layout& layout,
                    double cell_m, double max_height_m, size_t max_points_per_fragment) {
    SeenFloor seen;
    seen.cell_m = cell_m;
    std::vector<Eigen::Vector2d> xy;
    forEachPointL(fragments, T_W_F, layout, max_points_per_fragment,
                  [&](size_t, const Eigen::Vector3d& p) {
                      if (p.z() >= -0.3 && p.z() <= max_height_m) xy.push_back(p.head<2>());
                  });
    if (xy.empty() || !(cell_m > 0.0)) return seen;
    Eigen::Vector2d lo = xy.front(), hi = xy.front();
    for (const Eigen::Vector2d& p : xy) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    lo -= Eigen::Vector2d::Constant(2.0 * cell_m);  // room for the closing and the contour
    const int w = static_cast<int>(std::ceil((hi.x() - lo.x()) / cell_m)) + 3;
    const int h = static_cast<int>(std::ceil((hi.y() - lo.y()) / cell_m)) + 3;
    if (static_cast<double>(w) * h > 25e6) return seen;  // not a room
    cv::Mat mask = cv::Mat::zeros(h, w, CV_8U);
    for (const Eigen::Vector2d& p : xy) {
        mask.at<uint8_t>(static_cast<int>((p.y() - lo.y()) / cell_m),
                         static_cast<int>((p.x() - lo.x()) / cell_m)) = 255;
    }
    cv::morphologyEx(mask, mask, cv::MORPH_CLOSE,
                     cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
    auto centre = [&](int u, int v) {
        return Eigen::Vector2d(lo.x() + (u + 0.5) * cell_m, lo.y() + (v + 0.5) * cell_m);
    };
    const double cell_area = cell_m * cell_m;
    for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
            if (mask.at<uint8_t>(v, u) == 0) continue;
            seen.area_m2 += cell_area;
            if (insidePolygon(layout.room_polygon_L, centre(u, v))) {
                seen.area_in_room_m2 += cell_area;
            }
        }
    }
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(mask, contours, cv::RETR_CCOMP, cv::CHAIN_APPROX_SIMPLE);
    for (const std::vector<cv::Point>& c : contours) {
        std::vector<cv::Point> simple;
        cv::approxPolyDP(c, simple, 0.7, true);
        if (simple.size() < 3) continue;
        Outline2 o;
        for (const cv::Point& q : simple) o.push_back(centre(q.x, q.y));
        seen.outlines.push_back(std::move(o));
    }
    return seen;
}

std::vector<Eigen::Vector2d> cameraPath(const std::vector<Fragment>& fragments,
                                        const std::vector<Eigen::Isometry3d>& T_W_F,
                                        const Layout& layout) {
    std::vector<Eigen::Vector2d> path;
    const Eigen::Isometry3d T_L_W = layout.T_W_L.inverse();
    for (size_t i = 0; i < fragments.size() && i < T_W_F.size(); ++i) {
        if (fragments[i].frames.empty()) {
            path.push_back((T_L_W * T_W_F[i].translation()).head<2>());
            continue;
        }
        for (const FragmentFrame& f : fragments[i].frames) {
            if (!f.tracking_ok || !f.T_F_C.matrix().allFinite()) continue;
            path.push_back((T_L_W * (T_W_F[i] * f.T_F_C.translation())).head<2>());
        }
    }
    return path;
}

FloorplanOverlays floorplanOverlays(const std::vector<Fragment>& fragments,
                                    const std::vector<Eigen::Isometry3d>& T_W_F,
                                    const Layout& layout) {
    FloorplanOverlays o;
    o.fragment_outlines = fragmentOutlines(fragments, T_W_F, layout);
    o.seen = seenFloor(fragments, T_W_F, layout);
    o.camera_path_L = cameraPath(fragments, T_W_F, layout);
    return o;
}

FloorplanFigures floorplanFigures(const Layout& layout, const SeenFloor& seen) {
    FloorplanFigures f;
    const std::vector<Eigen::Vector2d>& poly = layout.room_polygon_L;
    if (poly.size() < 3) return f;
    Eigen::Vector2d lo = poly.front(), hi = poly.front();
    for (const Eigen::Vector2d& p : poly) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    f.width_m = hi.x() - lo.x();
    f.depth_m = hi.y() - lo.y();
    f.area_m2 = polygonArea(poly);
    f.edge_walls = polygonEdgeWalls(layout);
    f.wall_bounded_fraction = wallBoundedFraction(layout);
    // Orientation: counter-clockwise (positive shoelace sum) is the layout's convention.
    double twice = 0.0;
    const size_t n = poly.size();
    for (size_t k = 0; k < n; ++k) {
        const Eigen::Vector2d& p = poly[k];
        const Eigen::Vector2d& q = poly[(k + 1) % n];
        twice += p.x() * q.y() - q.x() * p.y();
        f.edge_lengths_m.push_back((q - p).norm());
    }
    const double sign = twice >= 0.0 ? 1.0 : -1.0;
    for (size_t k = 0; k < n; ++k) {
        const Eigen::Vector2d to_next = poly[(k + 1) % n] - poly[k];
        const Eigen::Vector2d to_prev = poly[(k + n - 1) % n] - poly[k];
        const double cross = to_next.x() * to_prev.y() - to_next.y() * to_prev.x();
        double angle = std::atan2(sign * cross, to_next.dot(to_prev)) * 180.0 / std::numbers::pi;
        if (angle < 0.0) angle += 360.0;
        f.corner_angles_deg.push_back(angle);
    }
    if (!seen.outlines.empty() && f.area_m2 > 0.0) {
        f.seen_fraction = std::min(1.0, seen.area_in_room_m2 / f.area_m2);
    }
    f.partial = f.wall_bounded_fraction < kClosedRoomWallFraction ||
                (f.seen_fraction >= 0.0 && f.seen_fraction < kMinSeenFloorFraction);
    return f;
}

namespace {

constexpr const char* kSvgText = "font-family=\"sans-serif\" font-size=\"14\"";

/// The drawing area in L (metres) and its mapping to SVG pixels (L's y points up, SVG's down).
struct SvgCanvas {
    Eigen::Vector2d lo, hi;
    double scale = 100.0;  // px per metre

    double X(const Eigen::Vector2d& p) const { return (p.x() - lo.x()) * scale; }
    double Y(const Eigen::Vector2d& p) const { return (hi.y() - p.y()) * scale; }
    double width() const { return (hi.x() - lo.x()) * scale; }
    double height() const { return (hi.y() - lo.y()) * scale; }
    /// "x,y x,y ..." of an SVG polygon or polyline.
    std::string points(const std::vector<Eigen::Vector2d>& pts) const {
        std::string s;
        for (const auto& p : pts) s += fmt::format("{:.1f},{:.1f} ", X(p), Y(p));
        return s;
    }
};

/// Bounds over the room, the walls, the fragments and the path (the seen floor is clipped to the
/// room), 1 m of margin for lengths, dimensions and the scale bar, at least 8 m wide (the
/// header's width) with the drawing centred, 0.8 m more on top for the header (room size,
/// warning) and 0.3 m below for the legend.
SvgCanvas floorplanCanvas(const Layout& layout, const FloorplanOverlays& overlays) {
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
    for (const Outline2& o : overlays.fragment_outlines) {
        for (const auto& p : o) grow(p);
    }
    for (const auto& p : overlays.camera_path_L) grow(p);
    if (lo.x() > hi.x()) {
        lo = Eigen::Vector2d(0, 0);
        hi = Eigen::Vector2d(1, 1);
    }
    const double margin = 1.0;
    lo -= Eigen::Vector2d(margin, margin);
    hi += Eigen::Vector2d(margin, margin);
    const double min_width_m = 8.0;
    if (hi.x() - lo.x() < min_width_m) {
        const double grow_x = 0.5 * (min_width_m - (hi.x() - lo.x()));
        lo.x() -= grow_x;
        hi.x() += grow_x;
    }
    hi.y() += 0.8;
    lo.y() -= 0.3;
    return SvgCanvas{lo, hi};
}

/// The room's area with its clip path and the seen area shaded inside it.
std::string roomSvg(const SvgCanvas& c, const std::vector<Eigen::Vector2d>& poly,
                    const FloorplanOverlays& overlays, const FloorplanFigures& fig) {
    std::string svg = fmt::format(
        "<defs><clipPath id=\"floorplan-room-clip\"><polygon points=\"{}\"/></clipPath>"
        "</defs>\n<polygon id=\"room\" points=\"{}\" fill=\"#f6f3ec\" stroke=\"none\"/>\n",
        c.points(poly), c.points(poly));
    if (overlays.seen.outlines.empty()) return svg;
    std::string d;
    for (const Outline2& o : overlays.seen.outlines) {
        for (size_t k = 0; k < o.size(); ++k) {
            d += fmt::format("{}{:.1f},{:.1f} ", k == 0 ? "M" : "L", c.X(o[k]), c.Y(o[k]));
        }
        d += "Z ";
    }
    svg += fmt::format(
        "<path id=\"seen\" d=\"{}\" fill=\"#e2d6b8\" fill-rule=\"evenodd\" "
        "stroke=\"none\" clip-path=\"url(#floorplan-room-clip)\">"
        "<title>seen: {:.1f} m2 of the room ({:.0f} %)</title></path>\n",
        d, overlays.seen.area_in_room_m2, 100.0 * std::max(0.0, fig.seen_fraction));
    return svg;
}

/// The fragments' outlines (dotted) and the camera path (at most 600 points whatever the frame
/// count).
std::string fragmentsAndPathSvg(const SvgCanvas& c, const FloorplanOverlays& overlays) {
    std::string svg =
        "<g id=\"fragments\" fill=\"none\" stroke=\"#9ab\" stroke-width=\"1\" "
        "stroke-dasharray=\"4 3\">\n";
    for (size_t i = 0; i < overlays.fragment_outlines.size(); ++i) {
        const Outline2& o = overlays.fragment_outlines[i];
        if (o.size() >= 3) {
            svg += fmt::format("<polygon points=\"{}\"><title>fragment {}</title></polygon>\n",
                               c.points(o), i);
        }
    }
    svg += "</g>\n";
    if (overlays.camera_path_L.size() >= 2) {
        const size_t stride = (overlays.camera_path_L.size() + 599) / 600;
        std::vector<Eigen::Vector2d> path;
        for (size_t k = 0; k < overlays.camera_path_L.size(); k += stride) {
            path.push_back(overlays.camera_path_L[k]);
        }
        path.push_back(overlays.camera_path_L.back());
        svg += fmt::format(
            "<polyline id=\"path\" points=\"{}\" fill=\"none\" stroke=\"#2a9d8f\" "
            "stroke-width=\"2\"><title>camera path</title></polyline>\n",
            c.points(path));
    }
    return svg;
}

/// The outline edge by edge: solid where a wall bounds it, dashed where it was inferred (the
/// edge of the seen floor, a step joining two walls); each edge's length outside it; the
/// corners with their angles.
std::string outlineSvg(const SvgCanvas& c, const std::vector<Eigen::Vector2d>& poly,
                       const FloorplanFigures& fig) {
    std::string svg = "<g id=\"outline\" stroke=\"#555\" stroke-width=\"1.5\">\n";
    std::string lengths = fmt::format("<g id=\"lengths\" {} fill=\"#333\">\n", kSvgText);
    for (size_t k = 0; k < poly.size(); ++k) {
        const Eigen::Vector2d& a = poly[k];
        const Eigen::Vector2d& b = poly[(k + 1) % poly.size()];
        const bool seen = fig.edge_walls[k] >= 0;
        svg += fmt::format(
            "<line class=\"{}\" x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\"{}>"
            "<title>{}, {:.2f} m</title></line>\n",
            seen ? "seen" : "inferred", c.X(a), c.Y(a), c.X(b), c.Y(b),
            seen ? "" : " stroke-dasharray=\"6 4\"",
            seen ? fmt::format("on wall {}", fig.edge_walls[k]) : std::string("inferred"),
            fig.edge_lengths_m[k]);
        if (fig.edge_lengths_m[k] < 0.5) continue;  // no room for the label
        const Eigen::Vector2d dir = (b - a) / fig.edge_lengths_m[k];
        const Eigen::Vector2d out(dir.y(), -dir.x());  // right of a counter-clockwise edge
        const Eigen::Vector2d at = 0.5 * (a + b) + 0.3 * out;
        lengths += fmt::format(
            "<text class=\"{}\" x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\" "
            "dominant-baseline=\"middle\">{:.2f} m</text>\n",
            seen ? "seen" : "inferred", c.X(at), c.Y(at), fig.edge_lengths_m[k]);
    }
    svg += "</g>\n" + lengths + "</g>\n";
    svg += "<g id=\"corners\" fill=\"#555\">\n";
    for (size_t k = 0; k < poly.size(); ++k) {
        svg += fmt::format(
            "<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"4\"><title>corner {}: {:.1f} deg"
            "</title></circle>\n",
            c.X(poly[k]), c.Y(poly[k]), k, fig.corner_angles_deg[k]);
    }
    svg += "</g>\n";
    return svg;
}

/// Dimension lines: the width below the room, the depth left of it.
std::string dimensionsSvg(const SvgCanvas& c, const std::vector<Eigen::Vector2d>& poly,
                          const FloorplanFigures& fig) {
    Eigen::Vector2d plo = poly.front(), phi = poly.front();
    for (const Eigen::Vector2d& p : poly) {
        plo = plo.cwiseMin(p);
        phi = phi.cwiseMax(p);
    }
    const Eigen::Vector2d w0(plo.x(), plo.y() - 0.65), w1(phi.x(), plo.y() - 0.65);
    const Eigen::Vector2d d0(plo.x() - 0.65, plo.y()), d1(plo.x() - 0.65, phi.y());
    std::string svg = fmt::format(
        "<g id=\"dimensions\" stroke=\"#777\" stroke-width=\"1\" {} fill=\"#333\">\n"
        "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\"/>"
        "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\"/>"
        "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\"/>\n"
        "<text class=\"width\" x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\" "
        "stroke=\"none\">{:.2f} m</text>\n",
        kSvgText, c.X(w0), c.Y(w0), c.X(w1), c.Y(w1), c.X(w0), c.Y(w0) - 6, c.X(w0), c.Y(w0) + 6,
        c.X(w1), c.Y(w1) - 6, c.X(w1), c.Y(w1) + 6, 0.5 * (c.X(w0) + c.X(w1)), c.Y(w0) + 20,
        fig.width_m);
    svg += fmt::format(
        "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\"/>"
        "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\"/>"
        "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\"/>\n"
        "<text class=\"depth\" x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\" "
        "stroke=\"none\" transform=\"rotate(-90 {:.1f} {:.1f})\">{:.2f} m</text>\n</g>\n",
        c.X(d0), c.Y(d0), c.X(d1), c.Y(d1), c.X(d0) - 6, c.Y(d0), c.X(d0) + 6, c.Y(d0), c.X(d1) - 6,
        c.Y(d1), c.X(d1) + 6, c.Y(d1), c.X(d0) - 10, 0.5 * (c.Y(d0) + c.Y(d1)), c.X(d0) - 10,
        0.5 * (c.Y(d0) + c.Y(d1)), fig.depth_m);
    return svg;
}

/// The walls, blue where Manhattan-snapped, red at a free angle, each labelled with its id.
std::string wallsSvg(const SvgCanvas& c, const Layout& layout) {
    std::string svg = "<g id=\"walls\" stroke-width=\"6\" stroke-linecap=\"round\">\n";
    for (const LayoutPlane* w : layout.walls()) {
        svg += fmt::format(
            "<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"{}\">"
            "<title>wall {}{}, {:.2f} m</title></line>\n",
            c.X(w->start_L), c.Y(w->start_L), c.X(w->end_L), c.Y(w->end_L),
            w->manhattan_snapped ? "#1f5fa8" : "#c0392b", w->id,
            w->manhattan_snapped ? " (Manhattan-snapped)" : " (free angle)",
            (w->end_L - w->start_L).norm());
        const Eigen::Vector2d mid = 0.5 * (w->start_L + w->end_L);
        const Eigen::Vector2d lab = mid + 0.25 * w->normal_L.head<2>();
        svg += fmt::format(
            "<text x=\"{:.1f}\" y=\"{:.1f}\" {} text-anchor=\"middle\" stroke=\"none\" "
            "fill=\"#333\">{}</text>\n",
            c.X(lab), c.Y(lab), kSvgText, w->id);
    }
    svg += "</g>\n";
    return svg;
}

/// The header: the room's size, area, seen share and ceiling; a warning for a partial scan.
std::string headerSvg(const Layout& layout, const FloorplanFigures& fig) {
    // A mostly inferred outline is the seen part's, not the room's.
    const bool closed = fig.wall_bounded_fraction >= kClosedRoomWallFraction;
    std::string size =
        fmt::format("{} {:.2f} m \u00d7 {:.2f} m, {:.1f} m\u00b2", closed ? "room" : "seen part",
                    fig.width_m, fig.depth_m, fig.area_m2);
    if (fig.seen_fraction >= 0.0) {
        size += fmt::format(", {:.0f} % of it seen", 100.0 * fig.seen_fraction);
    }
    size += layout.ceiling_height_m > 0.0
                ? fmt::format(", ceiling {:.2f} m", layout.ceiling_height_m)
                : std::string(", ceiling not seen");
    std::string svg = fmt::format(
        "<text id=\"size\" x=\"10\" y=\"24\" {} font-weight=\"bold\" fill=\"#222\">{}</text>\n",
        kSvgText, size);
    if (!fig.partial) return svg;
    std::string why;
    if (fig.wall_bounded_fraction < kClosedRoomWallFraction) {
        why = fmt::format(
            "{:.0f} % of the outline lies on seen walls; dashed edges are "
            "inferred",
            100.0 * fig.wall_bounded_fraction);
    }
    if (fig.seen_fraction >= 0.0 && fig.seen_fraction < kMinSeenFloorFraction) {
        why += fmt::format("{}{:.0f} % of the room's area was seen", why.empty() ? "" : "; ",
                           100.0 * fig.seen_fraction);
    }
    svg += fmt::format(
        "<text id=\"partial\" x=\"10\" y=\"48\" {} font-weight=\"bold\" fill=\"#b7791f\">"
        "partial scan: {}</text>\n",
        kSvgText, why);
    return svg;
}

/// Scale bar: 1 m in the lower-left margin, the legend beside it.
std::string scaleAndLegendSvg(const SvgCanvas& c) {
    const Eigen::Vector2d s0(c.lo.x() + 0.2, c.lo.y() + 0.3), s1(c.lo.x() + 1.2, c.lo.y() + 0.3);
    std::string svg = fmt::format(
        "<g id=\"scale\"><line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" "
        "stroke=\"black\" stroke-width=\"3\"/><text x=\"{:.1f}\" y=\"{:.1f}\" {} "
        "text-anchor=\"middle\">1 m</text></g>\n",
        c.X(s0), c.Y(s0), c.X(s1), c.Y(s1), 0.5 * (c.X(s0) + c.X(s1)), c.Y(s0) - 8, kSvgText);
    svg += fmt::format(
        "<text id=\"legend\" x=\"{:.1f}\" y=\"{:.1f}\" font-family=\"sans-serif\" "
        "font-size=\"12\" fill=\"#555\">solid outline: on a seen wall \u00b7 dashed: inferred "
        "\u00b7 shaded: seen area \u00b7 green: camera path \u00b7 dotted: fragments</text>\n",
        c.X(s1) + 20, c.Y(s0) + 5);
    return svg;
}

}  // namespace

std::string floorplanSvg(const Layout& layout, const FloorplanOverlays& overlays) {
    const std::vector<Eigen::Vector2d>& poly = layout.room_polygon_L;
    const FloorplanFigures fig = floorplanFigures(layout, overlays.seen);
    const SvgCanvas c = floorplanCanvas(layout, overlays);
    const double width = c.width(), height = c.height();
    std::string svg = fmt::format(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{:.0f}\" height=\"{:.0f}\" "
        "viewBox=\"0 0 {:.1f} {:.1f}\">\n"
        "<title>plumb floor plan (layout frame L, metres)</title>\n"
        "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
        width, height, width, height);
    const bool room = poly.size() >= 3;
    if (room) svg += roomSvg(c, poly, overlays, fig);
    svg += fragmentsAndPathSvg(c, overlays);
    if (room) svg += outlineSvg(c, poly, fig) + dimensionsSvg(c, poly, fig);
    svg += wallsSvg(c, layout);
    if (room) svg += headerSvg(layout, fig);
    svg += scaleAndLegendSvg(c);
    svg += "</svg>\n";
    return svg;
}

Status writeFloorplanSvg(const std::filesystem::path& path, const Layout& layout,
                         const FloorplanOverlays& overlays) {
    return io::writeText(path, floorplanSvg(layout, overlays));
}

std::vector<Outline2> fragmentOutlines(const std::vector<Fragment>& fragments,
                                       const std::vector<Eigen::Isometry3d>& T_W_F,
                                       const Layout& layout, size_t max_points_per_fragment) {
    std::vector<std::vector<Eigen::Vector2d>> xy(std::min(fragments.size(), T_W_F.size()));
    forEachPointL(fragments, T_W_F, layout, max_points_per_fragment,
                  [&](size_t i, const Eigen::Vector3d& p) { xy[i].push_back(p.head<2>()); });
    std::vector<Outline2> out;
    for (std::vector<Eigen::Vector2d>& pts : xy) {
        // A fragment with fewer than 3 points has no outline.
        out.push_back(pts.size() < 3 ? Outline2{} : convexHull(std::move(pts)));
    }
    return out;
}

}  // namespace plumb::layout
