// SPDX-License-Identifier: Apache-2.0
#include "backend/report/report_html.hpp"

#include "backend/report/mesh_render.hpp"
#include "backend/report/png_encode.hpp"
#include "common/eval/recon_metrics.hpp"

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

/// Energy E of every accepted and rejected step of the alternation, against the step number,
/// with both axes drawn, ticks and labels.
std::string energyChart(const nlohmann::json& energies) {
    if (!energies.is_array() || energies.empty()) return "<p class=na>No alternation ran.</p>";
    std::vector<double> e;
    for (const auto& it : energies)
        if (it.contains("energy") && it["energy"].is_number())
            e.push_back(it["energy"].get<double>());
    if (e.empty()) return "<p class=na>No energies recorded.</p>";
    double lo = *std::min_element(e.begin(), e.end());
    double hi = *std::max_element(e.begin(), e.end());
    if (!(hi > lo)) {
        const double pad = std::max(std::abs(hi) * 0.05, 1e-12);
        lo -= pad;
        hi += pad;
    }
    const int w = 480, h = 220, left = 70, right = 16, top = 14, bottom = 42;
    const double pw = w - left - right, ph = h - top - bottom;
    auto X = [&](double i) { return left + pw * (e.size() == 1 ? 0.5 : i / double(e.size() - 1)); };
    auto Y = [&](double v) { return top + ph * (1.0 - (v - lo) / (hi - lo)); };
    std::ostringstream out;
    out << fmt::format("<svg class=energy width={} height={} viewBox='0 0 {} {}' font-size=11>", w,
                       h, w, h);
    out << fmt::format("<rect x=0 y=0 width={} height={} fill='#fafafa' stroke='#ccc'/>", w, h);
    // Axes.
    out << fmt::format(
        "<g class=axes stroke='#333'><line x1='{0}' y1='{1}' x2='{0}' y2='{2}'/>"
        "<line x1='{0}' y1='{2}' x2='{3}' y2='{2}'/></g>",
        left, top, top + ph, left + pw);
    // y ticks: 5 levels between lo and hi, with enough digits to tell them apart.
    const double magnitude = std::max(std::abs(lo), std::abs(hi));
    const int digits = std::clamp(
        3 + static_cast<int>(std::ceil(std::log10(std::max(1.0, magnitude / (hi - lo))))), 3, 12);
    for (int k = 0; k <= 4; ++k) {
        const double v = lo + (hi - lo) * k / 4.0;
        out << fmt::format(
            "<line x1={} y1='{:.1f}' x2={} y2='{:.1f}' stroke='#333'/><line x1={} y1='{:.1f}' "
            "x2={} y2='{:.1f}' stroke='#eee'/><text x={} y='{:.1f}' text-anchor=end>{:.{}g}</text>",
            left - 4, Y(v), left, Y(v), left + 1, Y(v), left + pw, Y(v), left - 6, Y(v) + 4, v,
            digits);
    }
    // x ticks: every step up to 10 steps, else 10 evenly.
    const size_t n = e.size();
    const size_t stride = std::max<size_t>(1, (n + 9) / 10);
    for (size_t i = 0; i < n; i += stride)
        out << fmt::format(
            "<line x1='{0:.1f}' y1={1} x2='{0:.1f}' y2={2} stroke='#333'/>"
            "<text x='{0:.1f}' y={3} text-anchor=middle>{4}</text>",
            X(double(i)), top + ph, top + ph + 4, top + ph + 16, i);
    out << fmt::format("<text x='{:.1f}' y={} text-anchor=middle>alternation step</text>",
                       left + pw / 2, h - 6);
    out << fmt::format(
        "<text transform='translate(14,{:.1f}) rotate(-90)' text-anchor=middle>energy E</text>",
        top + ph / 2);
    out << "<polyline fill=none stroke='#1f6feb' stroke-width=2 points='";
    for (size_t i = 0; i < n; ++i) out << fmt::format("{:.1f},{:.1f} ", X(double(i)), Y(e[i]));
    out << "'/>";
    for (size_t i = 0; i < n; ++i)
        out << fmt::format("<circle cx='{:.1f}' cy='{:.1f}' r=2.5 fill='#1f6feb'/>", X(double(i)),
                           Y(e[i]));
    out << "</svg>";
    return out.str();
}

/// Version, date, command line and the time of the whole run (metrics.json "run").
std::string runSection(const nlohmann::json& metrics) {
    if (!metrics.contains("run")) return "";
    const nlohmann::json& r = metrics["run"];
    std::ostringstream out;
    out << "<table class=run>";
    out << "<tr><td>plumb version</td><td>" << escape(r.value("version", std::string("?")))
        << "</td></tr>";
    out << "<tr><td>date (UTC)</td><td>" << escape(r.value("date_utc", std::string("?")))
        << "</td></tr>";
    if (r.contains("command_line"))
        out << "<tr><td>command line</td><td><code>"
            << escape(r.value("command_line", std::string())) << "</code></td></tr>";
    if (r.contains("total_seconds")) {
        out << fmt::format(
            "<tr><td>total time</td><td><b>{:.1f} s</b> (tracking and fusion {:.1f} s, backend "
            "{:.1f} s)</td></tr>",
            r.value("total_seconds", 0.0), r.value("tracking_fusion_seconds", 0.0),
            r.value("backend_seconds", 0.0));
    } else {
        out << fmt::format(
            "<tr><td>total time</td><td>backend {:.1f} s (tracking and fusion not measured "
            "here)</td></tr>",
            r.value("backend_seconds", 0.0));
    }
    out << "</table>\n";
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
    out << fmt::format("<tr><th>backend total</th><th>{:.2f}</th></tr></table>\n", total);
    return out.str();
}

/// The depth self-calibration: the learned table, its coverage and the main variant's accuracy
/// from the raw depth and with the table.
std::string selfCalibrationSection(const nlohmann::json& metrics) {
    const nlohmann::json& sc = metrics["self_calibration"];
    std::ostringstream out;
    if (sc.value("status", std::string()) == "not_determined") {
        out << "<h2>Depth self-calibration</h2>\n<p>No table was learned: "
            << escape(sc.value("reason", std::string("?")))
            << ". This reconstruction used the raw depth.</p>\n";
        return out.str();
    }
    out << "<h2>Depth self-calibration</h2>\n<p>The depth distortion table <b>"
        << escape(sc.value("table", std::string("?"))) << "</b> was learned from "
        << sc.value("frames", 0) << " frames (one in " << sc.value("frame_step", 1)
        << ") of a first reconstruction ("
        << escape(
               sc.value("first_reconstruction", sc.value("raw_reconstruction", std::string("?"))))
        << (sc.value("first_table", std::string("none")) == "none"
                ? ", from the raw depth"
                : ", with the bend learned from each frame's planes")
        << ") in " << sc.value("iterations", nlohmann::json::array()).size() << " iterations ("
        << (sc.value("converged", false) ? "converged" : "stopped at the iteration limit") << ")";
    const int rounds = sc.value("rounds", 1);
    if (rounds > 1) {
        out << ", refined in " << rounds
            << " rounds: each round after the first estimated it again, from the last round's "
               "table, at the poses of a reconstruction made with that table (the iterations are "
               "the last round's)";
    }
    out << "; this reconstruction used it. Cells covered (of 6400) per depth bin 1/3/5/7/9 m:";
    for (const auto& c : sc.value("covered_cells", nlohmann::json::array())) out << " " << c;
    out << ".";
    // What the scan cannot observe is fixed, not learned: say how.
    out << " The global scale is fixed by the mean factor of the "
        << fmt::format("{:g}", sc.value("gauge_bin_m", 1.0)) << " m bin being 1";
    const nlohmann::json planar = sc.value("planar", nlohmann::json::object());
    if (planar.value("cells_with_data", 0) > 0) {
        out << fmt::format(
            "; the scale growing with depth, which neither the planes nor the views observe, was "
            "set to 0 over the {} cells where the sensor has depth (the bend from the planes held "
            "{:+.3f} % a metre there)",
            planar.value("cells_with_data", 0),
            100.0 * planar.value("removed_depth_scale_per_m", 0.0));
    }
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
        row(sc.value("first_table", std::string("none")) == "none" ? "raw depth"
                                                                   : "bend from the planes",
            before.value("ate_rmse_m", 0.0), before.value("recon_mean_m", 0.0));
        for (const nlohmann::json& r : sc.value("round_results", nlohmann::json::array())) {
            const int round = r.value("round", 0);
            const nlohmann::json f = r.value("reconstruction_figures", nlohmann::json::object());
            if (round < 2 || !f.contains("ate_rmse_m")) continue;
            const std::string name = fmt::format("round {}: round {}'s table", round, round - 1);
            row(name.c_str(), f.value("ate_rmse_m", 0.0), f.value("recon_mean_m", 0.0));
        }
        const nlohmann::json& m = *main;
        row("self-calibrated", m.contains("ate") ? m["ate"].value("rmse_m", 0.0) : 0.0,
            m.contains("recon") ? m["recon"].value("mean_m", 0.0) : 0.0);
        out << "</table>\n";
    }
    return out.str();
}

/// The variant the page leads with: "full" when it ran, else "baseline".
const nlohmann::json* mainVariant(const nlohmann::json& metrics) {
    if (!metrics.contains("variants") || !metrics["variants"].is_object()) return nullptr;
    const nlohmann::json& v = metrics["variants"];
    for (const char* name : {"full", "baseline"})
        if (v.contains(name)) return &v[name];
    return nullptr;
}

/// The element of array `list` whose `key` equals `id`, or nullptr.
const nlohmann::json* findById(const nlohmann::json& list, const char* key, int id) {
    if (!list.is_array()) return nullptr;
    for (const auto& e : list)
        if (e.contains(key) && e[key].is_number_integer() && e[key].get<int>() == id) return &e;
    return nullptr;
}

std::string idList(const nlohmann::json& ids) {
    std::string out;
    for (const auto& id : ids) out += (out.empty() ? "" : ", ") + id.dump();
    return out;
}

/// One row per estimated wall of the main variant: normal and offset (layout frame), length,
/// planarity measured on the mesh, and the error against the matched ground-truth wall.
std::string wallTable(const nlohmann::json& metrics) {
    const nlohmann::json walls = metrics.value("layout_walls", nlohmann::json());
    if (!walls.is_array() || walls.empty()) return "<p class=na>No walls were estimated.</p>\n";
    const nlohmann::json* main = mainVariant(metrics);
    const nlohmann::json empty = nlohmann::json::object();
    const nlohmann::json& v = main ? *main : empty;
    const nlohmann::json fits = v.value("walls", nlohmann::json::array());
    const nlohmann::json gt = v.contains("layout")
                                  ? v["layout"].value("walls", nlohmann::json::array())
                                  : nlohmann::json::array();
    const bool has_gt = v.contains("layout");
    const bool by_gt = metrics.value("planarity_reference", std::string()) == "ground-truth layout";
    std::ostringstream out;
    out << "<table class=walls><tr><th>wall</th><th>normal (layout frame)</th><th>offset d "
           "(m)</th><th>length (m)</th><th>planarity RMS (mm)</th>";
    if (has_gt) out << "<th>GT wall</th><th>angle error (deg)</th><th>offset error (cm)</th>";
    out << "</tr>\n";
    for (const auto& w : walls) {
        const int id = w.value("id", -1);
        const nlohmann::json n = w.value("normal_L", nlohmann::json::array({0, 0, 0}));
        out << fmt::format(
            "<tr><td>{}{}</td><td>({:+.3f}, {:+.3f}, {:+.3f})</td><td>{:.3f}</td>"
            "<td>{:.2f}</td>",
            id, w.value("manhattan_snapped", false) ? " (snapped)" : "", n[0].get<double>(),
            n[1].get<double>(), n[2].get<double>(), w.value("offset_m", 0.0),
            w.value("length_m", 0.0));
        const nlohmann::json* match = findById(gt, "estimated_wall", id);
        const int ref = by_gt ? (match ? match->value("gt_wall", -1) : -1) : id;
        const nlohmann::json* fit = ref >= 0 ? findById(fits, "wall", ref) : nullptr;
        out << (fit ? fmt::format("<td>{:.2f}</td>", 1000.0 * fit->value("rms_m", 0.0))
                    : std::string("<td class=na>not measured</td>"));
        if (has_gt) {
            if (match) {
                out << fmt::format("<td>{}</td><td>{:.2f}</td><td>{:+.2f}</td>",
                                   match->value("gt_wall", -1),
                                   match->value("angle_error_deg", 0.0),
                                   100.0 * match->value("offset_error_m", 0.0));
            } else {
                out << "<td class=bad colspan=3>matches no ground-truth wall</td>";
            }
        }
        out << "</tr>\n";
    }
    out << "</table>\n";
    if (has_gt) {
        const nlohmann::json missing = v["layout"].value("unmatched_gt_walls", nlohmann::json());
        if (missing.is_array() && !missing.empty())
            out << "<p class=bad>Ground-truth walls not found: " << idList(missing) << ".</p>\n";
    }
    return out.str();
}

/// Everything in metrics.json that should make a user doubt the result, one line each.
std::vector<std::string> warnings(const nlohmann::json& metrics) {
    std::vector<std::string> w;
    if (metrics.value("status", std::string("complete")) != "complete")
        w.push_back("the run did not complete: " + metrics.value("status", std::string()));
    if (metrics.contains("tracking")) {
        const nlohmann::json& t = metrics["tracking"];
        const size_t failed = t.value("frames_tracking_failed", size_t{0});
        if (failed > 0)
            w.push_back(
                fmt::format("tracking failed on {} frames; they are not in the model", failed));
        const nlohmann::json lost = t.value("fragments_closed_by_tracking_loss", nlohmann::json());
        if (lost.is_array() && !lost.empty())
            w.push_back("fragments closed early by tracking loss: " + idList(lost));
        const nlohmann::json weak =
            t.value("fragments_with_unobserved_directions", nlohmann::json());
        if (weak.is_array() && !weak.empty())
            w.push_back(fmt::format(
                "{} frames (fragments {}) were tracked with a translation direction the depth "
                "hardly constrained (smallest / largest eigenvalue of the odometry's translation "
                "information below {:g}): their poses along it rest on the motion model",
                t.value("frames_in_fragments_with_unobserved_directions", size_t{0}), idList(weak),
                t.value("unobserved_direction_eigenvalue_ratio", 0.0)));
    }
    // A layout step that would raise E_R ends the block-coordinate descent where it is: the
    // poses are those of the last registration step, nothing to doubt.
    if (metrics.contains("alternation") && !metrics["alternation"].value("converged", true) &&
        metrics["alternation"].value("stop_reason", std::string()) !=
            "layout step raised the energy")
        w.push_back(
            fmt::format("the layout / registration alternation did not converge: {} after {} outer "
                        "iterations",
                        metrics["alternation"].value("stop_reason", std::string("?")),
                        metrics["alternation"].value("outer_iterations", 0)));
    const nlohmann::json walls = metrics.value("layout_walls", nlohmann::json());
    if (!walls.is_array()) {
        w.push_back("no room layout was found: no walls, no floor plan");
    } else if (walls.size() < 3) {
        w.push_back(fmt::format("only {} walls were found", walls.size()));
    }
    if (const nlohmann::json* main = mainVariant(metrics); main && main->contains("layout")) {
        const nlohmann::json missing =
            (*main)["layout"].value("unmatched_gt_walls", nlohmann::json());
        if (missing.is_array() && !missing.empty())
            w.push_back(fmt::format("{} of {} ground-truth walls were not found (walls {})",
                                    missing.size(), (*main)["layout"].value("gt_walls", 0),
                                    idList(missing)));
    }
    if (metrics.contains("outline_on_walls") && metrics["outline_on_walls"].is_number()) {
        const double f = metrics["outline_on_walls"].get<double>();
        if (f < kClosedRoomWallFraction)
            w.push_back(fmt::format(
                "partial coverage: {:.0f} % of the room outline lies on seen walls (the rest is "
                "inferred)",
                100.0 * f));
    }
    return w;
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

namespace {

/// Green (0) -> yellow (0.5) -> red (1).
std::string errorColour(double t) {
    t = std::clamp(t, 0.0, 1.0);
    const int r = static_cast<int>(std::round(255.0 * std::min(1.0, 2.0 * t)));
    const int g = static_cast<int>(std::round(200.0 * std::min(1.0, 2.0 * (1.0 - t))));
    return fmt::format("#{:02x}{:02x}30", r, g);
}

}  // namespace

std::string topViewSvg(const TriangleMesh& mesh, const std::optional<Layout>& layout,
                       const TopViewTrajectory& trajectory, int size_px, size_t max_segments) {
    const Eigen::Isometry3d T_U_W = reportUpFrame(layout);
    // The plan: the mesh and the camera path both decide the extent, so the path is never cut
    // off; a degenerate helper triangle through the path's corners widens the fit without
    // showing (zero area, never drawn).
    TriangleMesh plan_mesh = mesh;
    std::vector<Eigen::Vector3d> path_U;
    for (const auto& p : trajectory.positions_W) path_U.push_back(T_U_W * p);
    if (layout)
        for (const auto& v : layout->room_polygon_L) path_U.emplace_back(v.x(), v.y(), 0.0);
    if (!path_U.empty()) {
        Eigen::Vector3d lo = path_U.front(), hi = path_U.front();
        for (const auto& p : path_U) {
            lo = lo.cwiseMin(p);
            hi = hi.cwiseMax(p);
        }
        const Eigen::Isometry3d T_W_U = T_U_W.inverse();
        const int base = static_cast<int>(plan_mesh.vertices.size());
        double z = 0.0;  // the mesh's lowest point: never above the dollhouse cut
        if (!mesh.empty()) {
            z = std::numeric_limits<double>::infinity();
            for (const auto& v : mesh.vertices) z = std::min(z, (T_U_W * v.cast<double>()).z());
        }
        for (const Eigen::Vector3d& c :
             {Eigen::Vector3d(lo.x(), lo.y(), z), Eigen::Vector3d(hi.x(), hi.y(), z),
              Eigen::Vector3d(0.5 * (lo.x() + hi.x()), 0.5 * (lo.y() + hi.y()), z)}) {
            plan_mesh.vertices.push_back((T_W_U * c).cast<float>());
            if (!plan_mesh.colors.empty()) plan_mesh.colors.emplace_back(255, 255, 255);
            if (!plan_mesh.normals.empty()) plan_mesh.normals.emplace_back(0.f, 0.f, 1.f);
        }
        // Colinear corners: zero area, so the triangle fixes the extent and is never drawn.
        plan_mesh.triangles.emplace_back(base, base + 2, base + 1);
    }
    if (plan_mesh.triangles.empty()) return "<p class=na>empty mesh</p>";
    MeshRenderConfig c;
    c.width_px = size_px;
    c.height_px = size_px;
    c.elevation_deg = 90.0;
    c.azimuth_deg = -90.0;  // +x right, +y up
    c.margin = 0.05;
    c.cull_back_faces = true;
    c.light_direction_U = Eigen::Vector3d(0.3, -0.4, 1.0);
    if (layout && layout->ceiling_height_m > 0.5) {
        c.cut_above_z_m = layout->ceiling_height_m - 0.25;
    } else {
        c.cut_top_fraction = 0.12;
    }
    const MeshRender plan = renderMesh(plan_mesh, T_U_W, c);
    auto px = [&](const Eigen::Vector3d& p_U) {
        const Eigen::Vector3d q = plan.project(p_U).value_or(Eigen::Vector3d::Zero());
        return Eigen::Vector2d(q.x(), q.y());
    };
    std::ostringstream out;
    out << fmt::format("<svg class=topview width={0} height={0} viewBox='0 0 {0} {0}'>", size_px);
    out << fmt::format("<image width='{0}' height='{0}' href='{1}'/>", size_px,
                       pngDataUri(plan.image));
    out << fmt::format("<rect width={0} height={0} fill='none' stroke='#ccc'/>", size_px);
    if (layout) {
        for (const LayoutPlane* w : layout->walls()) {
            const Eigen::Vector2d a = px({w->start_L.x(), w->start_L.y(), 0.0});
            const Eigen::Vector2d b = px({w->end_L.x(), w->end_L.y(), 0.0});
            out << fmt::format(
                "<line class=wall x1='{:.1f}' y1='{:.1f}' x2='{:.1f}' y2='{:.1f}' stroke='{}' "
                "stroke-width='2.5'/>",
                a.x(), a.y(), b.x(), b.y(), w->manhattan_snapped ? "#d73a49" : "#e36209");
        }
    }
    // The camera path, in at most max_segments pieces; with errors, each piece coloured by the
    // mean error of the poses it stands for.
    const auto& pos = trajectory.positions_W;
    const bool with_errors = trajectory.errors_m.size() == pos.size() && !pos.empty();
    double max_error = 0.0;
    if (with_errors)
        for (double e : trajectory.errors_m)
            if (std::isfinite(e)) max_error = std::max(max_error, e);
    if (pos.size() >= 2) {
        const size_t pieces = std::max<size_t>(1, std::min(max_segments, pos.size() - 1));
        const double step = double(pos.size() - 1) / pieces;
        out << "<g class=trajectory stroke-width='2.5' stroke-linecap='round' fill='none'>";
        if (!with_errors) out << "<polyline stroke='#1f6feb' points='";
        for (size_t k = 0; k < pieces; ++k) {
            const size_t i0 = static_cast<size_t>(std::round(k * step));
            const size_t i1 =
                std::min(pos.size() - 1, static_cast<size_t>(std::round((k + 1) * step)));
            const Eigen::Vector2d a = px(T_U_W * pos[i0]);
            const Eigen::Vector2d b = px(T_U_W * pos[i1]);
            if (!with_errors) {
                if (k == 0) out << fmt::format("{:.1f},{:.1f} ", a.x(), a.y());
                out << fmt::format("{:.1f},{:.1f} ", b.x(), b.y());
                continue;
            }
            double sum = 0.0;
            int n = 0;
            for (size_t i = i0; i <= i1; ++i)
                if (std::isfinite(trajectory.errors_m[i])) {
                    sum += trajectory.errors_m[i];
                    ++n;
                }
            const std::string colour =
                n == 0 ? std::string("#888888")
                       : errorColour(max_error > 0.0 ? sum / n / max_error : 0.0);
            out << fmt::format(
                "<line x1='{:.1f}' y1='{:.1f}' x2='{:.1f}' y2='{:.1f}' stroke='{}'/>", a.x(), a.y(),
                b.x(), b.y(), colour);
        }
        if (!with_errors) out << "'/>";
        out << "</g>";
        const Eigen::Vector2d start = px(T_U_W * pos.front());
        const Eigen::Vector2d end = px(T_U_W * pos.back());
        out << fmt::format(
            "<circle cx='{:.1f}' cy='{:.1f}' r='5' fill='#fff' stroke='#000' "
            "stroke-width='2'><title>first frame</title></circle>",
            start.x(), start.y());
        out << fmt::format(
            "<circle cx='{:.1f}' cy='{:.1f}' r='4' fill='#000'><title>last frame</title></circle>",
            end.x(), end.y());
    }
    // Scale bar: 1 m in plan pixels.
    const double metre_px = plan.focal_px;
    out << fmt::format(
        "<line x1='12' y1='{0:.1f}' x2='{1:.1f}' y2='{0:.1f}' stroke='#000' stroke-width='3'/>",
        size_px - 8.0, 12.0 + metre_px);
    out << fmt::format("<text x='{:.1f}' y='{}' font-size='11'>1 m</text>", 16.0 + metre_px,
                       size_px - 4);
    if (with_errors) {
        const int bar_x = size_px - 130, bar_y = 8;
        out << "<defs><linearGradient id='errgrad'>";
        for (int k = 0; k <= 4; ++k)
            out << fmt::format("<stop offset='{}%' stop-color='{}'/>", 25 * k,
                               errorColour(0.25 * k));
        out << "</linearGradient></defs>";
        out << fmt::format(
            "<rect class=colourbar x='{}' y='{}' width='100' height='8' fill='url(#errgrad)'/>",
            bar_x, bar_y);
        out << fmt::format("<text x='{}' y='{}' font-size='10'>0</text>", bar_x, bar_y + 19);
        out << fmt::format(
            "<text x='{}' y='{}' font-size='10' text-anchor='end'>{:.1f} cm ATE</text>",
            bar_x + 100, bar_y + 19, 100.0 * max_error);
    }
    out << "</svg>";
    return out.str();
}

Color3u8 reconErrorColour(double error_m) {
    const double t =
        std::isfinite(error_m) ? std::clamp(error_m / kReconErrorScaleMaxM, 0.0, 1.0) : 0.0;
    return Color3u8(static_cast<uint8_t>(std::round(255.0 * std::min(1.0, 2.0 * t))),
                    static_cast<uint8_t>(std::round(200.0 * std::min(1.0, 2.0 * (1.0 - t)))), 48);
}

ReconErrorMap reconErrorMap(const std::vector<Eigen::Vector3f>& points_W,
                            const std::vector<double>& errors_m,
                            const std::optional<Layout>& layout, int size_px) {
    PLUMB_CHECK(points_W.size() == errors_m.size())
        << points_W.size() << " points, " << errors_m.size() << " errors";
    PLUMB_CHECK(size_px > 0) << "size " << size_px;
    ReconErrorMap map;
    map.T_U_W = reportUpFrame(layout);
    map.image.width = size_px;
    map.image.height = size_px;
    map.image.rgb.assign(3 * size_t(size_px) * size_px, 255);
    // The points in U, and the cut: like the other top views, the ceiling (and what hangs below
    // it) is taken away so the floor and the walls show.
    std::vector<Eigen::Vector3d> p_U;
    std::vector<double> e;
    p_U.reserve(points_W.size());
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    Eigen::Vector3d hi = -lo;
    for (size_t i = 0; i < points_W.size(); ++i) {
        if (!std::isfinite(errors_m[i]) || !points_W[i].allFinite()) continue;
        p_U.push_back(map.T_U_W * points_W[i].cast<double>());
        e.push_back(errors_m[i]);
        lo = lo.cwiseMin(p_U.back());
        hi = hi.cwiseMax(p_U.back());
    }
    const double cut_z = layout && layout->ceiling_height_m > 0.5
                             ? layout->ceiling_height_m - 0.25
                             : hi.z() - 0.12 * (hi.z() - lo.z());
    constexpr double kMargin = 0.05;
    const double extent = std::max({hi.x() - lo.x(), hi.y() - lo.y(), 1e-3});
    map.px_per_m = p_U.empty() ? 1.0 : size_px * (1.0 - 2.0 * kMargin) / extent;
    if (!p_U.empty())
        map.origin_px = Eigen::Vector2d(0.5 * size_px - map.px_per_m * 0.5 * (lo.x() + hi.x()),
                                        0.5 * size_px + map.px_per_m * 0.5 * (lo.y() + hi.y()));
    // Each point a 3 x 3 pixel square; the highest point wins a pixel (a z-buffer from above).
    std::vector<double> top(size_t(size_px) * size_px, -std::numeric_limits<double>::infinity());
    for (size_t i = 0; i < p_U.size(); ++i) {
        if (p_U[i].z() > cut_z) continue;
        ++map.points_drawn;
        const int cx = static_cast<int>(std::floor(map.origin_px.x() + map.px_per_m * p_U[i].x()));
        const int cy = static_cast<int>(std::floor(map.origin_px.y() - map.px_per_m * p_U[i].y()));
        const Color3u8 colour = reconErrorColour(e[i]);
        for (int y = std::max(0, cy - 1); y <= std::min(size_px - 1, cy + 1); ++y)
            for (int x = std::max(0, cx - 1); x <= std::min(size_px - 1, cx + 1); ++x) {
                double& z = top[size_t(y) * size_px + x];
                if (p_U[i].z() < z) continue;
                z = p_U[i].z();
                map.image.set(x, y, colour);
            }
    }
    std::ostringstream out;
    const int legend_h = 34;
    out << fmt::format(
        "<svg class=reconerror width={0} height={1} viewBox='0 0 {0} {1}'><title>reconstruction "
        "error: distance of each model point to the ground-truth surface</title>",
        size_px, size_px + legend_h);
    out << fmt::format("<image width='{0}' height='{0}' href='{1}'/>", size_px,
                       pngDataUri(map.image));
    out << fmt::format("<rect width={0} height={0} fill='none' stroke='#ccc'/>", size_px);
    out << fmt::format(
        "<line x1='12' y1='{0:.1f}' x2='{1:.1f}' y2='{0:.1f}' stroke='#000' stroke-width='3'/>",
        size_px - 8.0, 12.0 + map.px_per_m);
    out << fmt::format("<text x='{:.1f}' y='{}' font-size='11'>1 m</text>", 16.0 + map.px_per_m,
                       size_px - 4);
    // The colour bar: the fixed scale, 0 to kReconErrorScaleMaxM, with its legend.
    const int bar_x = 12, bar_y = size_px + 6, bar_w = 160;
    out << "<defs><linearGradient id='reconerrgrad'>";
    for (int k = 0; k <= 4; ++k) {
        const Color3u8 c = reconErrorColour(0.25 * k * kReconErrorScaleMaxM);
        out << fmt::format("<stop offset='{}%' stop-color='#{:02x}{:02x}{:02x}'/>", 25 * k, c.x(),
                           c.y(), c.z());
    }
    out << "</linearGradient></defs>";
    out << fmt::format(
        "<rect class=colourbar x='{}' y='{}' width='{}' height='9' fill='url(#reconerrgrad)'/>",
        bar_x, bar_y, bar_w);
    const int text_y = bar_y + 22;
    out << fmt::format("<text x='{}' y='{}' font-size='10'>0</text>", bar_x, text_y);
    out << fmt::format("<text x='{}' y='{}' font-size='10' text-anchor='middle'>{:.1f}</text>",
                       bar_x + bar_w / 2, text_y, 50.0 * kReconErrorScaleMaxM);
    out << fmt::format(
        "<text x='{}' y='{}' font-size='10' text-anchor='end'>&#8805; {:.0f} cm</text>",
        bar_x + bar_w, text_y, 100.0 * kReconErrorScaleMaxM);
    out << fmt::format(
        "<text class=legend x='{}' y='{}' font-size='11'>distance to the ground-truth surface, "
        "cm (clipped at {:.0f} cm)</text>",
        bar_x + bar_w + 12, bar_y + 9, 100.0 * kReconErrorScaleMaxM);
    out << "</svg>";
    map.svg = out.str();
    return map;
}

namespace {

/// Every stride-th vertex, so that at most `max_points` are drawn.
size_t vertexStride(const TriangleMesh& mesh, size_t max_points) {
    const size_t cap = std::max<size_t>(1, max_points);
    return std::max<size_t>(1, (mesh.vertices.size() + cap - 1) / cap);
}

}  // namespace

Result<ReconErrorMap> reconErrorMap(const TriangleMesh& mesh, const Eigen::Isometry3d& T_gt_est,
                                    const std::vector<Eigen::Vector3f>& gt_points_gt,
                                    const std::optional<Layout>& layout, int size_px,
                                    size_t max_points) {
    if (mesh.vertices.empty()) return invalidArgument("reconstruction-error map: empty mesh");
    if (gt_points_gt.empty())
        return invalidArgument("reconstruction-error map: no ground-truth surface points");
    const size_t stride = vertexStride(mesh, max_points);
    std::vector<Eigen::Vector3f> points_W, points_gt;
    const Eigen::Isometry3f T = T_gt_est.cast<float>();
    for (size_t i = 0; i < mesh.vertices.size(); i += stride) {
        points_W.push_back(mesh.vertices[i]);
        points_gt.push_back(T * mesh.vertices[i]);
    }
    Result<std::vector<double>> d = eval::closestPointDistances(points_gt, gt_points_gt);
    if (!d.isOk()) return d.status();
    return reconErrorMap(points_W, *d, layout, size_px);
}

Result<ReconErrorMap> reconErrorMap(const TriangleMesh& mesh,
                                    const std::vector<double>& vertex_errors_m,
                                    const std::optional<Layout>& layout, int size_px,
                                    size_t max_points) {
    if (mesh.vertices.empty()) return invalidArgument("reconstruction-error map: empty mesh");
    if (vertex_errors_m.size() != mesh.vertices.size())
        return invalidArgument(fmt::format("reconstruction-error map: {} errors for {} vertices",
                                           vertex_errors_m.size(), mesh.vertices.size()));
    const size_t stride = vertexStride(mesh, max_points);
    std::vector<Eigen::Vector3f> points_W;
    std::vector<double> errors_m;
    for (size_t i = 0; i < mesh.vertices.size(); i += stride) {
        points_W.push_back(mesh.vertices[i]);
        errors_m.push_back(vertex_errors_m[i]);
    }
    return reconErrorMap(points_W, errors_m, layout, size_px);
}

std::string renderReportHtml(const nlohmann::json& metrics, const ReportFigures& figures) {
    std::ostringstream out;
    out << "<!doctype html><html><head><meta charset='utf-8'><title>plumb report</title><style>"
           "body{font-family:sans-serif;margin:2em;max-width:1100px;color:#222}"
           "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ddd;padding:4px "
           "8px;text-align:right}td:first-child,th:first-child{text-align:left}"
           ".good{color:#1a7f37}.bad{color:#cf222e}.na{color:#999}.row{display:flex;gap:2em;"
           "flex-wrap:wrap}h2{border-bottom:1px solid "
           "#eee}figure{margin:0}img.model{max-width:520px;"
           "width:100%;border:1px solid #eee}figcaption{color:#666;font-size:90%}"
           "</style></head><body>\n";
    out << "<h1>plumb reconstruction report</h1>\n";
    out << "<p>Input: <b>" << escape(metrics.value("input", std::string("?"))) << "</b>; "
        << metrics.value("fragments", 0) << " fragments, " << metrics.value("frames", 0)
        << " frames. Ground truth: " << escape(metrics.value("ground_truth", std::string("none")))
        << ".</p>\n";
    out << runSection(metrics);
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
    out << "<h2 id=warnings>Warnings</h2>\n";
    const std::vector<std::string> warned = warnings(metrics);
    if (warned.empty()) {
        out << "<p class=good>None: every check passed.</p>\n";
    } else {
        out << "<ul class=warnings>\n";
        for (const std::string& w : warned) out << "<li class=bad>" << escape(w) << "</li>\n";
        out << "</ul>\n";
    }
    out << "<h2 id=walls>Walls</h2>\n" << wallTable(metrics);
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
    out << "<h2 id=recon-error>Reconstruction error map</h2>\n";
    if (!figures.recon_error_svg.empty()) {
        out << "<figure>" << figures.recon_error_svg
            << "<figcaption>The model seen from above, each point coloured by its distance to the "
               "ground-truth surface after the trajectory alignment: green 0, yellow "
            << fmt::format("{:.1f} cm, red {:.0f} cm and beyond", 50.0 * kReconErrorScaleMaxM,
                           100.0 * kReconErrorScaleMaxM)
            << ".</figcaption></figure>\n";
    } else {
        out << "<p class=na>Not drawn: " << escape(figures.recon_error_note) << ".</p>\n";
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
        << stageTable(metrics.value("stages", nlohmann::json::array()));
    if (metrics.contains("run") && metrics["run"].contains("tracking_fusion_seconds"))
        out << fmt::format(
            "<p>Before these stages, tracking and fusion took {:.1f} s: {:.1f} s in all.</p>\n",
            metrics["run"].value("tracking_fusion_seconds", 0.0),
            metrics["run"].value("total_seconds", 0.0));
    out << "</body></html>\n";
    return out.str();
}

}  // namespace plumb::backend
