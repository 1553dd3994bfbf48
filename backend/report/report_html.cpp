// SPDX-License-Identifier: Apache-2.0
#include "backend/report/report_html.hpp"

#include "backend/report/mesh_render.hpp"
#include "backend/report/png_encode.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace plumb::backend {

namespace {

std::string escape(const std::string& text) {
    std::string out;
    for (char c : text) {
        switch (c) {
            case '<':
                out += "&lt;";
                break;
            case '>':
                out += "&gt;";
                break;
            case '&':
                out += "&amp;";
                break;
            case '"':
                out += "&quot;";
                break;
            default:
                out += c;
        }
    }
    return out;
}

/// A number at a JSON path ("ate/rmse_m"), or nullopt.
std::optional<double> number(const nlohmann::json& j, const std::string& path) {
    const nlohmann::json* node = &j;
    size_t start = 0;
    while (start <= path.size()) {
        const size_t end = std::min(path.find('/', start), path.size());
        const std::string key = path.substr(start, end - start);
        if (!node->is_object() || !node->contains(key)) return std::nullopt;
        node = &(*node)[key];
        start = end + 1;
    }
    if (!node->is_number()) return std::nullopt;
    return node->get<double>();
}

std::string cell(const std::optional<double>& v, double scale, int digits) {
    if (!v) return "<td class=na>—</td>";
    return fmt::format("<td>{:.{}f}</td>", *v * scale, digits);
}

struct Row {
    const char* label;
    const char* path;
    double scale;
    int digits;
    bool lower_is_better;
};

constexpr Row kRows[] = {
    {"ATE RMSE (cm)", "ate/rmse_m", 100.0, 2, true},
    {"ATE median (cm)", "ate/median_m", 100.0, 2, true},
    {"Reconstruction error, mean (cm)", "recon/mean_m", 100.0, 2, true},
    {"Reconstruction error, median (cm)", "recon/median_m", 100.0, 2, true},
    {"Completeness (share of GT within threshold)", "recon/completeness", 1.0, 3, false},
    {"Wall planarity, mean RMS (mm)", "mean_wall_rms_m", 1000.0, 2, true},
    {"Wall-to-wall angle, max error (deg)", "max_wall_angle_error_deg", 1.0, 2, true},
    {"Layout: mean wall angle error (deg)", "layout/mean_wall_angle_error_deg", 1.0, 2, true},
    {"Layout: mean wall offset error (cm)", "layout/mean_abs_wall_offset_error_m", 100.0, 2, true},
};

std::string comparisonTable(const nlohmann::json& variants) {
    std::ostringstream out;
    std::vector<std::string> names;
    for (const char* preferred : {"full", "baseline"})
        if (variants.contains(preferred)) names.push_back(preferred);
    out << "<table><tr><th>measure</th>";
    for (const auto& n : names)
        out << "<th>"
            << (n == "full" ? "plumb (layout + global registration)" : "baseline (--no-layout)")
            << "</th>";
    if (names.size() == 2) out << "<th>change</th>";
    out << "</tr>\n";
    for (const Row& row : kRows) {
        std::vector<std::optional<double>> values;
        for (const auto& n : names) values.push_back(number(variants[n], row.path));
        if (std::none_of(values.begin(), values.end(), [](const auto& v) { return v.has_value(); }))
            continue;
        out << "<tr><td>" << row.label << "</td>";
        for (const auto& v : values) out << cell(v, row.scale, row.digits);
        if (values.size() == 2) {
            if (values[0] && values[1] && std::abs(*values[1]) > 1e-12) {
                const double change = (*values[0] - *values[1]) / std::abs(*values[1]) * 100.0;
                const bool better = row.lower_is_better ? change < 0.0 : change > 0.0;
                out << fmt::format("<td class={}>{:+.1f} %</td>", better ? "good" : "bad", change);
            } else {
                out << "<td class=na>—</td>";
            }
        }
        out << "</tr>\n";
    }
    out << "</table>\n";
    return out.str();
}

std::string energyChart(const nlohmann::json& energies) {
    if (!energies.is_array() || energies.empty()) return "<p class=na>No alternation ran.</p>";
    std::vector<double> e;
    for (const auto& it : energies)
        if (it.contains("energy") && it["energy"].is_number())
            e.push_back(it["energy"].get<double>());
    if (e.empty()) return "<p class=na>No energies recorded.</p>";
    const double lo = *std::min_element(e.begin(), e.end());
    const double hi = *std::max_element(e.begin(), e.end());
    const double span = hi > lo ? hi - lo : 1.0;
    const int w = 420, h = 160, pad = 30;
    std::ostringstream out;
    out << fmt::format("<svg width={} height={} viewBox='0 0 {} {}'>", w, h, w, h);
    out << fmt::format("<rect x=0 y=0 width={} height={} fill='#fafafa' stroke='#ccc'/>", w, h);
    out << "<polyline fill=none stroke='#1f6feb' stroke-width=2 points='";
    for (size_t i = 0; i < e.size(); ++i) {
        const double x = pad + (w - 2 * pad) * (e.size() == 1 ? 0.5 : double(i) / (e.size() - 1));
        const double y = h - pad - (h - 2 * pad) * (e[i] - lo) / span;
        out << fmt::format("{:.1f},{:.1f} ", x, y);
    }
    out << "'/>";
    out << fmt::format("<text x=4 y=14 font-size=11>E = {:.4g}</text>", hi);
    out << fmt::format("<text x=4 y={} font-size=11>E = {:.4g}</text>", h - 6, lo);
    out << fmt::format("<text x={} y={} font-size=11>{} iterations</text>", w - 110, h - 6,
                       e.size());
    out << "</svg>";
    return out.str();
}

std::string stageTable(const nlohmann::json& stages) {
    if (!stages.is_array() || stages.empty()) return "";
    std::ostringstream out;
    out << "<table><tr><th>stage</th><th>seconds</th></tr>\n";
    double total = 0.0;
    for (const auto& s : stages) {
        const double sec = s.value("seconds", 0.0);
        total += sec;
        out << fmt::format("<tr><td>{}</td><td>{:.2f}</td></tr>\n",
                           escape(s.value("name", std::string("?"))), sec);
    }
    out << fmt::format("<tr><th>total</th><th>{:.2f}</th></tr></table>\n", total);
    return out.str();
}

/// The depth self-calibration: the learned table, its coverage and the main variant's accuracy
/// from the raw depth and with the table.
std::string selfCalibrationSection(const nlohmann::json& metrics) {
    const nlohmann::json& sc = metrics["self_calibration"];
    std::ostringstream out;
    out << "<h2>Depth self-calibration</h2>\n<p>The depth distortion table <b>"
        << escape(sc.value("table", std::string("?"))) << "</b> was learned from "
        << sc.value("frames", 0) << " frames (one in " << sc.value("frame_step", 1)
        << ") of the reconstruction from the raw depth ("
        << escape(sc.value("raw_reconstruction", std::string("?"))) << ") in "
        << sc.value("iterations", nlohmann::json::array()).size() << " iterations ("
        << (sc.value("converged", false) ? "converged" : "stopped at the iteration limit")
        << "); this reconstruction used it. Cells covered (of 6400) per depth bin 1/3/5/7/9 m:";
    for (const auto& c : sc.value("covered_cells", nlohmann::json::array())) out << " " << c;
    out << ".</p>\n";
    const nlohmann::json before = sc.value("before", nlohmann::json::object());
    const nlohmann::json& variants = metrics.value("variants", nlohmann::json::object());
    const auto main = variants.find(variants.contains("full") ? "full" : "baseline");
    if (!before.empty() && main != variants.end()) {
        out << "<table><tr><th></th><th>ATE RMSE</th><th>mean reconstruction error</th></tr>";
        auto row = [&](const char* name, double ate, double recon) {
            out << fmt::format("<tr><td>{}</td><td>{:.2f} cm</td><td>{:.2f} cm</td></tr>", name,
                               100.0 * ate, 100.0 * recon);
        };
        row("raw depth", before.value("ate_rmse_m", 0.0), before.value("recon_mean_m", 0.0));
        const nlohmann::json& m = *main;
        row("self-calibrated", m.contains("ate") ? m["ate"].value("rmse_m", 0.0) : 0.0,
            m.contains("recon") ? m["recon"].value("mean_m", 0.0) : 0.0);
        out << "</table>\n";
    }
    return out.str();
}

}  // namespace

Eigen::Isometry3d reportUpFrame(const std::optional<Layout>& layout) {
    if (layout) return layout->T_W_L.inverse();
    // Camera convention: x right, y down, z forward. U = Rx(-90 deg) W maps -y to +z.
    Eigen::Isometry3d T_U_W = Eigen::Isometry3d::Identity();
    T_U_W.linear() = Eigen::AngleAxisd(-M_PI / 2.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
    return T_U_W;
}

std::vector<ModelView> renderModelViews(const TriangleMesh& mesh,
                                        const std::optional<Layout>& layout, int size_px) {
    std::vector<ModelView> views;
    if (mesh.triangles.empty()) return views;
    const Eigen::Isometry3d T_U_W = reportUpFrame(layout);
    MeshRenderConfig c;
    c.width_px = size_px;
    c.height_px = size_px * 3 / 4;
    c.cull_back_faces = true;  // TSDF surfaces face the free space: see in through near walls
    if (layout && layout->ceiling_height_m > 0.5) {
        c.cut_above_z_m = layout->ceiling_height_m - 0.25;
    } else {
        c.cut_top_fraction = 0.12;
    }
    // Look at the walls from the side they face: the area-weighted mean horizontal normal of the
    // steep triangles (TSDF surfaces face the free space) points from the walls towards where the
    // scan saw them from. A closed room has none; then any azimuth will do.
    Eigen::Vector2d facing = Eigen::Vector2d::Zero();
    for (const Eigen::Vector3i& t : mesh.triangles) {
        const Eigen::Vector3d a = T_U_W * mesh.vertices[t[0]].cast<double>();
        const Eigen::Vector3d b = T_U_W * mesh.vertices[t[1]].cast<double>();
        const Eigen::Vector3d c3 = T_U_W * mesh.vertices[t[2]].cast<double>();
        const Eigen::Vector3d n = (b - a).cross(c3 - a);  // |n| = 2 * area
        if (std::abs(n.z()) < 0.5 * n.norm()) facing += n.head<2>();
    }
    const double azimuth_deg =
        facing.norm() > 1e-9 ? std::atan2(facing.y(), facing.x()) * 180.0 / M_PI : -60.0;
    c.projection = RenderProjection::kOrthographic;
    c.elevation_deg = 55.0;
    c.azimuth_deg = azimuth_deg - 20.0;
    views.push_back({"oblique view from above (ceiling cut away)",
                     pngDataUri(renderMesh(mesh, T_U_W, c).image)});
    c.projection = RenderProjection::kPerspective;
    c.elevation_deg = 30.0;
    c.azimuth_deg = azimuth_deg + 25.0;
    views.push_back({"perspective view", pngDataUri(renderMesh(mesh, T_U_W, c).image)});
    return views;
}

std::string topViewSvg(const TriangleMesh& mesh, const std::optional<Layout>& layout, int size_px,
                       size_t max_points) {
    const Eigen::Isometry3d T_L_W =
        layout ? layout->T_W_L.inverse() : Eigen::Isometry3d::Identity();
    std::vector<Eigen::Vector2d> xy;
    const size_t step = std::max<size_t>(1, mesh.vertices.size() / std::max<size_t>(1, max_points));
    for (size_t i = 0; i < mesh.vertices.size(); i += step) {
        const Eigen::Vector3d p = T_L_W * mesh.vertices[i].cast<double>();
        // Without a layout the camera convention (y down) makes x-z the floor plane.
        xy.emplace_back(p.x(), layout ? p.y() : p.z());
    }
    if (layout)
        for (const auto& v : layout->room_polygon_L) xy.push_back(v);
    if (xy.empty()) return "<p class=na>empty mesh</p>";
    Eigen::Vector2d lo = xy.front(), hi = xy.front();
    for (const auto& p : xy) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    const double extent = std::max({hi.x() - lo.x(), hi.y() - lo.y(), 0.5});
    const double pad = 16.0;
    const double scale = (size_px - 2 * pad) / extent;
    auto X = [&](const Eigen::Vector2d& p) { return pad + (p.x() - lo.x()) * scale; };
    auto Y = [&](const Eigen::Vector2d& p) { return size_px - pad - (p.y() - lo.y()) * scale; };
    std::ostringstream out;
    out << fmt::format("<svg width={0} height={0} viewBox='0 0 {0} {0}'>", size_px);
    out << fmt::format("<rect width={0} height={0} fill='#fff' stroke='#ccc'/>", size_px);
    const size_t n_mesh = xy.size() - (layout ? layout->room_polygon_L.size() : 0);
    out << "<g fill='#555' fill-opacity='0.35'>";
    for (size_t i = 0; i < n_mesh; ++i)
        out << fmt::format("<rect x='{:.1f}' y='{:.1f}' width='1' height='1'/>", X(xy[i]),
                           Y(xy[i]));
    out << "</g>";
    if (layout) {
        for (const LayoutPlane* w : layout->walls()) {
            out << fmt::format(
                "<line x1='{:.1f}' y1='{:.1f}' x2='{:.1f}' y2='{:.1f}' stroke='{}' "
                "stroke-width='2'/>",
                X(w->start_L), Y(w->start_L), X(w->end_L), Y(w->end_L),
                w->manhattan_snapped ? "#d73a49" : "#e36209");
        }
    }
    out << fmt::format(
        "<line x1='{:.1f}' y1='{:.1f}' x2='{:.1f}' y2='{:.1f}' stroke='#000' stroke-width='3'/>",
        pad, size_px - 6.0, pad + scale, size_px - 6.0);
    out << fmt::format("<text x='{:.1f}' y='{}' font-size='10'>1 m</text>", pad + scale + 4,
                       size_px - 3);
    out << "</svg>";
    return out.str();
}

std::string renderReportHtml(const nlohmann::json& metrics, const ReportFigures& figures) {
    std::ostringstream out;
    out << "<!doctype html><html><head><meta charset='utf-8'><title>plumb report</title><style>"
           "body{font-family:sans-serif;margin:2em;max-width:1100px;color:#222}"
           "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ddd;padding:4px "
           "8px;text-align:right}td:first-child,th:first-child{text-align:left}"
           ".good{color:#1a7f37}.bad{color:#cf222e}.na{color:#999}.row{display:flex;gap:2em;"
           "flex-wrap:wrap}h2{border-bottom:1px solid #eee}"
           "</style></head><body>\n";
    out << "<h1>plumb reconstruction report</h1>\n";
    out << "<p>Input: <b>" << escape(metrics.value("input", std::string("?"))) << "</b>; "
        << metrics.value("fragments", 0) << " fragments, " << metrics.value("frames", 0)
        << " frames. Ground truth: " << escape(metrics.value("ground_truth", std::string("none")))
        << ".</p>\n";
    if (metrics.contains("variants")) {
        out << "<h2>Accuracy</h2>\n" << comparisonTable(metrics["variants"]);
        for (const auto& [name, v] : metrics["variants"].items()) {
            if (!v.contains("notes") || v["notes"].empty()) continue;
            out << "<p class=na>" << escape(name) << ": ";
            for (const auto& n : v["notes"]) out << escape(n.get<std::string>()) << "; ";
            out << "</p>\n";
        }
    }
    if (!figures.model_views.empty()) {
        out << "<h2 id=model>Model</h2><div class=row>\n";
        for (const ModelView& v : figures.model_views) {
            if (v.png_data_uri.empty()) continue;
            out << "<figure><img class=model alt='" << escape(v.caption) << "' src='"
                << v.png_data_uri << "'><figcaption>" << escape(v.caption)
                << "</figcaption></figure>\n";
        }
        out << "</div>\n";
    }
    if (metrics.contains("self_calibration")) out << selfCalibrationSection(metrics);
    if (!figures.floorplan_svg.empty())
        out << "<h2>Floor plan</h2>\n" << figures.floorplan_svg << "\n";
    if (!figures.top_views.empty()) {
        out << "<h2>Top views</h2><div class=row>\n";
        for (const char* name : {"full", "baseline"}) {
            const auto it = figures.top_views.find(name);
            if (it == figures.top_views.end()) continue;
            out << "<div><h3>" << (std::string(name) == "full" ? "plumb" : "baseline (--no-layout)")
                << "</h3>" << it->second << "</div>\n";
        }
        out << "</div>\n";
    }
    if (metrics.contains("registration")) {
        const auto& r = metrics["registration"];
        out << "<h2>Pose graph</h2><p>" << r.value("odometry_edges", 0) << " odometry edges, "
            << r.value("loop_edges", 0) << " loop closures, " << r.value("pruned_edges", 0)
            << " pruned by the line process, " << r.value("rejected_edges", 0)
            << " candidates rejected before it (overlap, or disagreeing with the odometry).</p>\n";
    }
    out << "<h2>Energy per alternation iteration</h2>\n"
        << energyChart(metrics.value("energies", nlohmann::json::array())) << "\n";
    out << "<h2>Time per stage</h2>\n"
        << stageTable(metrics.value("stages", nlohmann::json::array())) << "\n";
    out << "</body></html>\n";
    return out.str();
}

}  // namespace plumb::backend
