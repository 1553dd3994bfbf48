// SPDX-License-Identifier: Apache-2.0
// report.html (issue 31): sections present, pictures embedded as PNG, size bounded.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <regex>
#include <string>

#include "backend/report/png_encode.hpp"
#include "backend/report/report_html.hpp"
#include "common/eval/recon_metrics.hpp"
#include "drivers/dataset/depth_png.hpp"

namespace plumb::backend {
namespace {

/// A gridded quad p0 + s u + t v (s, t in [0, 1]), `n` cells a side, wound so its normal is
/// u x v, one colour.
void addQuad(TriangleMesh& mesh, const Eigen::Vector3f& p0, const Eigen::Vector3f& u,
             const Eigen::Vector3f& v, int n, const Color3u8& colour) {
    const int base = static_cast<int>(mesh.vertices.size());
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            mesh.vertices.push_back(p0 + u * (float(i) / n) + v * (float(j) / n));
            mesh.colors.push_back(colour);
        }
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const int a = base + j * (n + 1) + i;
            mesh.triangles.emplace_back(a, a + 1, a + n + 2);
            mesh.triangles.emplace_back(a, a + n + 2, a + n + 1);
        }
}

/// A 4 m x 3 m x 2.5 m room in a z-up world, surfaces facing inwards (the free space).
TriangleMesh room(int n) {
    TriangleMesh mesh;
    const float X = 4.f, Y = 3.f, Z = 2.5f;
    addQuad(mesh, {0, 0, 0}, {X, 0, 0}, {0, Y, 0}, n, Color3u8(150, 100, 60));   // floor, up
    addQuad(mesh, {0, 0, 0}, {0, 0, Z}, {X, 0, 0}, n, Color3u8(200, 200, 190));  // y = 0, +y
    addQuad(mesh, {0, Y, 0}, {X, 0, 0}, {0, 0, Z}, n, Color3u8(190, 200, 200));  // y = Y, -y
    addQuad(mesh, {0, 0, 0}, {0, Y, 0}, {0, 0, Z}, n, Color3u8(200, 190, 200));  // x = 0, +x
    addQuad(mesh, {X, 0, 0}, {0, 0, Z}, {0, Y, 0}, n, Color3u8(200, 200, 200));  // x = X, -x
    return mesh;
}

Layout roomLayout() {
    Layout layout;  // L = W: z up, floor at z = 0
    layout.ceiling_height_m = 2.5;
    layout.room_polygon_L = {{0, 0}, {4, 0}, {4, 3}, {0, 3}};
    for (int k = 0; k < 4; ++k) {
        LayoutPlane wall;
        wall.kind = LayoutPlaneKind::kWall;
        wall.start_L = layout.room_polygon_L[k];
        wall.end_L = layout.room_polygon_L[(k + 1) % 4];
        const Eigen::Vector2d dir = (wall.end_L - wall.start_L).normalized();
        wall.id = k;
        wall.normal_L = Eigen::Vector3d(-dir.y(), dir.x(), 0.0);  // inwards (polygon is CCW)
        wall.d_L = -wall.normal_L.head<2>().dot(wall.start_L);
        layout.planes.push_back(wall);
    }
    return layout;
}

/// A loop of `n` camera positions around the room at 1.4 m with errors growing to 3 cm.
TopViewTrajectory loop(size_t n) {
    TopViewTrajectory t;
    for (size_t i = 0; i < n; ++i) {
        const double a = 2.0 * M_PI * double(i) / n;
        t.positions_W.emplace_back(2.0 + 1.2 * std::cos(a), 1.5 + 0.9 * std::sin(a), 1.4);
        t.errors_m.push_back(0.03 * double(i) / n);
    }
    return t;
}

/// The image of a `data:image/png;base64,` URI, decoded with the drivers' libpng reader.
ColourImage decodeDataUri(const std::string& uri) {
    const std::string prefix = "data:image/png;base64,";
    EXPECT_EQ(uri.rfind(prefix, 0), 0u);
    std::vector<uint8_t> bytes;
    uint32_t acc = 0;
    int bits = 0;
    for (size_t i = prefix.size(); i < uri.size() && uri[i] != '='; ++i) {
        const char c = uri[i];
        const int v = c >= 'A' && c <= 'Z'   ? c - 'A'
                      : c >= 'a' && c <= 'z' ? c - 'a' + 26
                      : c >= '0' && c <= '9' ? c - '0' + 52
                      : c == '+'             ? 62
                                             : 63;
        acc = (acc << 6) | uint32_t(v);
        bits += 6;
        if (bits >= 8) {
            bits -= 8;
            bytes.push_back(uint8_t((acc >> bits) & 0xff));
        }
    }
    Result<ColourImage> image = dataset::decodeColourImage(bytes, "report picture");
    EXPECT_TRUE(image.isOk()) << image.status().toString();
    return image.isOk() ? std::move(*image) : ColourImage();
}

/// Share of the pixels that are not the white background.
double nonBackgroundShare(const ColourImage& image) {
    size_t n = 0;
    for (int v = 0; v < image.height(); ++v)
        for (int u = 0; u < image.width(); ++u) n += !(image(u, v) == Rgb8{255, 255, 255});
    return image.width() * image.height() > 0 ? double(n) / (image.width() * image.height()) : 0.0;
}

size_t count(const std::string& text, const std::string& what) {
    size_t n = 0;
    for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
}

TEST(TopView, IsAnEmbeddedPngWithTheWallsAndABoundedPath) {
    const Layout layout = roomLayout();
    const std::string svg = topViewSvg(room(60), layout, loop(1000));
    EXPECT_EQ(count(svg, "href='data:image/png;base64,"), 1u);
    EXPECT_EQ(count(svg, "class=wall"), 4u);
    EXPECT_EQ(count(svg, "<rect x="), 0u);  // no per-point elements any more
    // 1000 poses, at most 300 path pieces, plus the colour bar.
    const size_t lines = count(svg, "<line ");
    EXPECT_LE(lines, 300u + 4u + 1u);
    EXPECT_GE(lines, 300u);
    EXPECT_NE(svg.find("class=colourbar"), std::string::npos);
    EXPECT_NE(svg.find("3.0 cm ATE"), std::string::npos);
    // Without errors the path is one polyline and there is no colour bar.
    TopViewTrajectory plain = loop(1000);
    plain.errors_m.clear();
    const std::string svg2 = topViewSvg(room(60), layout, plain);
    EXPECT_EQ(count(svg2, "<polyline"), 1u);
    EXPECT_EQ(svg2.find("class=colourbar"), std::string::npos);
}

TEST(ModelViews, RenderTheRoomAsNonBlankPngs) {
    const std::vector<ModelView> views = renderModelViews(room(20), roomLayout(), 200);
    ASSERT_EQ(views.size(), 2u);
    for (const ModelView& v : views) {
        const ColourImage image = decodeDataUri(v.png_data_uri);
        EXPECT_EQ(image.width(), 200);
        EXPECT_EQ(image.height(), 150);
        // The room fills a good part of the picture, and the margin stays background.
        EXPECT_GT(nonBackgroundShare(image), 0.2) << v.caption;
        EXPECT_EQ(image(0, 0), (Rgb8{255, 255, 255})) << v.caption;
        EXPECT_FALSE(v.caption.empty());
    }
}

/// A metrics.json as the pipeline writes it for a 1000-frame run with ground truth.
nlohmann::json metrics() {
    nlohmann::json m;
    m["format"] = "plumb-metrics-1";
    m["status"] = "complete";
    m["input"] = "sim:test_room";
    m["fragments"] = 20;
    m["frames"] = 1000;
    m["ground_truth"] = "simulator";
    m["variants"]["full"] = {{"ate", {{"rmse_m", 0.01}, {"median_m", 0.008}}},
                             {"walls", {{{"wall", 10}, {"vertices", 900}, {"rms_m", 0.002}}}},
                             {"layout",
                              {{"gt_walls", 4},
                               {"walls",
                                {{{"gt_wall", 10},
                                  {"estimated_wall", 0},
                                  {"angle_error_deg", 0.5},
                                  {"offset_error_m", 0.012}}}},
                               {"unmatched_gt_walls", {13}}}}};
    m["layout_walls"] = nlohmann::json::array();
    for (int k = 0; k < 3; ++k)
        m["layout_walls"].push_back({{"id", k},
                                     {"normal_L", {1.0, 0.0, 0.0}},
                                     {"offset_m", -0.5 * k},
                                     {"length_m", 3.0},
                                     {"manhattan_snapped", k > 0}});
    m["planarity_reference"] = "ground-truth layout";
    m["outline_on_walls"] = 0.6;
    m["tracking"] = {{"frames_tracking_failed", 3},
                     {"fragments_closed_by_tracking_loss", {4}},
                     {"fragments_with_unobserved_directions", {7, 8}},
                     {"frames_in_fragments_with_unobserved_directions", 100},
                     {"unobserved_direction_eigenvalue_ratio", 1e-3}};
    m["alternation"] = {
        {"outer_iterations", 5}, {"converged", false}, {"stop_reason", "iteration limit"}};
    m["energies"] = {{{"energy", 3.0}}, {{"energy", 2.0}}, {{"energy", 1.5}}};
    m["stages"] = {{{"name", "initial registration"}, {"seconds", 2.0}}};
    m["total_seconds"] = 2.0;
    m["run"] = {{"version", "0.1.0"},
                {"date_utc", "2026-12-03T08:00:00Z"},
                {"command_line", "plumb reconstruct sim:test_room --out <r>"},
                {"backend_seconds", 2.0},
                {"tracking_fusion_seconds", 61.0},
                {"total_seconds", 63.0}};
    return m;
}

ReportFigures figures() {
    ReportFigures f;
    const Layout layout = roomLayout();
    const TriangleMesh mesh = room(150);  // 270 k triangles
    f.top_views["full"] = topViewSvg(mesh, layout, loop(1000));
    f.top_views["baseline"] = topViewSvg(mesh, layout, loop(1000));
    f.model_views = renderModelViews(mesh, layout);
    Result<ReconErrorMap> map = reconErrorMap(mesh, Eigen::Isometry3d::Identity(),
                                              room(200).vertices, layout);  // 2 cm samples
    EXPECT_TRUE(map.isOk()) << map.status().toString();
    if (map.isOk()) f.recon_error_svg = map->svg;
    return f;
}

/// The text of the <h2> headings, in order.
std::vector<std::string> headings(const std::string& html) {
    std::vector<std::string> out;
    const std::regex h2("<h2[^>]*>([^<]*)</h2>");
    for (auto it = std::sregex_iterator(html.begin(), html.end(), h2); it != std::sregex_iterator();
         ++it)
        out.push_back((*it)[1]);
    return out;
}

TEST(ReportHtml, HasEverySectionAndOnlyEmbeddedPngPictures) {
    const std::string html = renderReportHtml(metrics(), figures());
    const std::vector<std::string> h = headings(html);
    for (const char* section :
         {"Accuracy", "Model", "Warnings", "Walls", "Top views", "Reconstruction error map",
          "Energy per alternation iteration", "Time per stage"})
        EXPECT_NE(std::find(h.begin(), h.end(), section), h.end()) << section;
    // Every picture is an embedded PNG: nothing is fetched.
    const std::regex src("(?:src|href)='([^']{0,40})");
    size_t pictures = 0;
    for (auto it = std::sregex_iterator(html.begin(), html.end(), src);
         it != std::sregex_iterator(); ++it, ++pictures)
        EXPECT_EQ((*it)[1].str().rfind("data:image/png;base64,", 0), 0u) << (*it)[1];
    EXPECT_EQ(pictures, 5u);  // two model views, two top views, the reconstruction-error map
    EXPECT_EQ(html.find("http://"), std::string::npos);
    EXPECT_EQ(html.find("https://"), std::string::npos);
}

TEST(ReportHtml, A1000FrameReportStaysUnder2MB) {
    const std::string html = renderReportHtml(metrics(), figures());
    EXPECT_LT(html.size(), 2u * 1024u * 1024u);
}

TEST(ReconErrorMap, FixedScaleGreenYellowRedClipped) {
    EXPECT_EQ(reconErrorColour(0.0), Color3u8(0, 200, 48));
    EXPECT_EQ(reconErrorColour(0.5 * kReconErrorScaleMaxM), Color3u8(255, 200, 48));
    EXPECT_EQ(reconErrorColour(kReconErrorScaleMaxM), Color3u8(255, 0, 48));
    EXPECT_EQ(reconErrorColour(0.10), Color3u8(255, 0, 48));  // beyond the scale: clipped
    EXPECT_EQ(reconErrorColour(0.03), Color3u8(255, 160, 48));
    EXPECT_EQ(reconErrorColour(std::nan("")), reconErrorColour(0.0));
}

/// Pixel of `image` as our colour type.
Color3u8 at(const ColourImage& image, const Eigen::Vector2d& px) {
    const Rgb8 c =
        image(static_cast<int>(std::floor(px.x())), static_cast<int>(std::floor(px.y())));
    return Color3u8(c.r, c.g, c.b);
}

TEST(ReconErrorMap, ColoursFollowTheErrorOfADisplacedPart) {
    // The model: the room with the floor's half x < 2 m raised by 3 cm; the ground truth: the
    // true room, sampled every 1 cm (on the model's vertex grid, so the rest is exact).
    const Layout layout = roomLayout();
    TriangleMesh model = room(100);
    const std::vector<Eigen::Vector3f> gt = room(400).vertices;
    const size_t floor_vertices = 101 * 101;  // room() adds the floor first
    for (size_t i = 0; i < floor_vertices; ++i)
        if (model.vertices[i].x() < 2.f - 1e-4f) model.vertices[i].z() += 0.03f;
    Result<ReconErrorMap> map = reconErrorMap(model, Eigen::Isometry3d::Identity(), gt, layout);
    ASSERT_TRUE(map.isOk()) << map.status().toString();
    // Everything but the top of the walls (above the cut 25 cm under the ceiling) is drawn.
    EXPECT_GT(map->points_drawn, model.vertices.size() * 8 / 10);
    EXPECT_LT(map->points_drawn, model.vertices.size());
    // The picture is embedded as a PNG, decodes, and is not blank.
    const std::string prefix = "href='";
    const size_t at_uri = map->svg.find(prefix + "data:image/png;base64,");
    ASSERT_NE(at_uri, std::string::npos);
    const size_t begin = at_uri + prefix.size();
    const ColourImage image =
        decodeDataUri(map->svg.substr(begin, map->svg.find('\'', begin) - begin));
    ASSERT_EQ(image.width(), 460);
    EXPECT_GT(nonBackgroundShare(image), 0.3);
    // Away from the walls and the step, the raised half is at 3 cm's colour, the rest green.
    size_t raised = 0, raised_ok = 0, flat = 0, flat_ok = 0;
    for (size_t i = 0; i < floor_vertices; ++i) {
        const Eigen::Vector3d p = model.vertices[i].cast<double>();
        if (p.y() < 0.3 || p.y() > 2.7) continue;
        if (p.x() > 0.3 && p.x() < 1.7) {
            ++raised;
            raised_ok += at(image, map->pixel(p)) == reconErrorColour(0.03);
        } else if (p.x() > 2.3 && p.x() < 3.7) {
            ++flat;
            flat_ok += at(image, map->pixel(p)) == Color3u8(0, 200, 48);
        }
    }
    ASSERT_GT(raised, 1000u);
    ASSERT_GT(flat, 1000u);
    EXPECT_EQ(raised_ok, raised);
    EXPECT_EQ(flat_ok, flat);
    // The colour bar and its legend.
    EXPECT_EQ(count(map->svg, "class=colourbar"), 1u);
    EXPECT_NE(map->svg.find("distance to the ground-truth surface, cm (clipped at 5 cm)"),
              std::string::npos);
    EXPECT_NE(map->svg.find(">0</text>"), std::string::npos);
    EXPECT_NE(map->svg.find(">2.5</text>"), std::string::npos);
    EXPECT_NE(map->svg.find("&#8805; 5 cm</text>"), std::string::npos);
    EXPECT_NE(map->svg.find(">1 m</text>"), std::string::npos);
    // A shifted alignment moves every error: T_gt_est raising the whole model by 6 cm makes the
    // flat half clipped red (6 cm) too.
    Eigen::Isometry3d up = Eigen::Isometry3d::Identity();
    up.translation().z() = 0.06;
    Result<ReconErrorMap> shifted = reconErrorMap(model, up, gt, layout);
    ASSERT_TRUE(shifted.isOk());
    EXPECT_EQ(shifted->image.at(static_cast<int>(shifted->pixel({3.0, 1.5, 0.0}).x()),
                                static_cast<int>(shifted->pixel({3.0, 1.5, 0.0}).y())),
              Color3u8(255, 0, 48));
}

TEST(ReconErrorMap, ErrorsMeasuredByTheEvaluationDrawTheSameMap) {
    const Layout layout = roomLayout();
    TriangleMesh model = room(100);
    for (size_t i = 0; i < 101 * 101; ++i)
        if (model.vertices[i].x() < 2.f) model.vertices[i].z() += 0.02f;
    const std::vector<Eigen::Vector3f> gt = room(300).vertices;
    const std::vector<double> errors = eval::closestPointDistances(model.vertices, gt).value();
    // Few points allowed: both pick the same strided vertices.
    for (size_t max_points : {size_t{400'000}, size_t{5'000}}) {
        const Result<ReconErrorMap> searched =
            reconErrorMap(model, Eigen::Isometry3d::Identity(), gt, layout, 460, max_points);
        const Result<ReconErrorMap> given = reconErrorMap(model, errors, layout, 460, max_points);
        ASSERT_TRUE(searched.isOk() && given.isOk());
        EXPECT_EQ(given->points_drawn, searched->points_drawn);
        EXPECT_EQ(given->svg, searched->svg);
    }
    EXPECT_FALSE(reconErrorMap(model, std::vector<double>(3, 0.0), layout).isOk());
    EXPECT_FALSE(reconErrorMap(TriangleMesh{}, std::vector<double>{}, layout).isOk());
}

TEST(ReconErrorMap, NeedsGroundTruthAndTheReportSaysWhy) {
    EXPECT_FALSE(reconErrorMap(room(10), Eigen::Isometry3d::Identity(), {}, roomLayout()).isOk());
    EXPECT_FALSE(reconErrorMap(TriangleMesh{}, Eigen::Isometry3d::Identity(), room(10).vertices,
                               roomLayout())
                     .isOk());
    const std::string html = renderReportHtml(metrics(), ReportFigures{});
    const std::vector<std::string> h = headings(html);
    EXPECT_NE(std::find(h.begin(), h.end(), "Reconstruction error map"), h.end());
    EXPECT_EQ(html.find("<svg class=reconerror"), std::string::npos);
    EXPECT_NE(html.find("Not drawn: no ground-truth surface came with the input."),
              std::string::npos);
    // With the map, the page embeds it with its caption.
    const std::string with = renderReportHtml(metrics(), figures());
    EXPECT_EQ(count(with, "<svg class=reconerror"), 1u);
    EXPECT_EQ(with.find("Not drawn:"), std::string::npos);
    EXPECT_NE(with.find("red 5 cm and beyond"), std::string::npos);
}

TEST(ReportHtml, WarningsNameWhatToDoubt) {
    const std::string html = renderReportHtml(metrics(), ReportFigures{});
    const size_t at = html.find("<h2 id=warnings>");
    ASSERT_NE(at, std::string::npos);
    const std::string w = html.substr(at, html.find("</ul>", at) - at);
    EXPECT_NE(w.find("tracking failed on 3 frames"), std::string::npos);
    EXPECT_NE(w.find("tracking loss: 4"), std::string::npos);
    EXPECT_NE(w.find("100 frames (fragments 7, 8)"), std::string::npos);
    EXPECT_NE(w.find("did not converge: iteration limit after 5"), std::string::npos);
    EXPECT_NE(w.find("1 of 4 ground-truth walls were not found (walls 13)"), std::string::npos);
    EXPECT_NE(w.find("partial coverage: 60 %"), std::string::npos);
    // A clean run says so.
    nlohmann::json clean = metrics();
    clean.erase("tracking");
    clean["alternation"]["converged"] = true;
    clean["variants"]["full"]["layout"]["unmatched_gt_walls"] = nlohmann::json::array();
    clean["outline_on_walls"] = 0.95;
    EXPECT_NE(renderReportHtml(clean, ReportFigures{}).find("None: every check passed"),
              std::string::npos);
    // Algorithm 1 ending because the next layout would raise the energy is its normal end.
    clean["alternation"] = {{"outer_iterations", 2},
                            {"converged", false},
                            {"stop_reason", "layout step raised the energy"}};
    EXPECT_NE(renderReportHtml(clean, ReportFigures{}).find("None: every check passed"),
              std::string::npos);
    // No layout at all is a warning too.
    clean.erase("layout_walls");
    EXPECT_NE(renderReportHtml(clean, ReportFigures{}).find("no room layout was found"),
              std::string::npos);
}

TEST(ReportHtml, RunSectionGivesVersionDateCommandAndTotalTime) {
    const std::string html = renderReportHtml(metrics(), ReportFigures{});
    EXPECT_NE(html.find("<td>plumb version</td><td>0.1.0</td>"), std::string::npos);
    EXPECT_NE(html.find("2026-12-03T08:00:00Z"), std::string::npos);
    EXPECT_NE(html.find("<code>plumb reconstruct sim:test_room --out &lt;r&gt;</code>"),
              std::string::npos);  // escaped
    EXPECT_NE(html.find("<b>63.0 s</b> (tracking and fusion 61.0 s, backend 2.0 s)"),
              std::string::npos);
    nlohmann::json m = metrics();
    m["run"].erase("tracking_fusion_seconds");
    m["run"].erase("total_seconds");
    EXPECT_NE(renderReportHtml(m, ReportFigures{}).find("backend 2.0 s (tracking and fusion not"),
              std::string::npos);
}

TEST(ReportHtml, EnergyPlotHasAxesTicksAndLabels) {
    const std::string html = renderReportHtml(metrics(), ReportFigures{});
    const size_t at = html.find("<svg class=energy");
    ASSERT_NE(at, std::string::npos);
    const std::string svg = html.substr(at, html.find("</svg>", at) - at);
    EXPECT_NE(svg.find("<g class=axes"), std::string::npos);
    EXPECT_NE(svg.find(">alternation step</text>"), std::string::npos);
    EXPECT_NE(svg.find(">energy E</text>"), std::string::npos);
    EXPECT_NE(svg.find(">1.5</text>"), std::string::npos);  // lowest tick
    EXPECT_NE(svg.find(">3</text>"), std::string::npos);    // highest tick
    EXPECT_EQ(count(svg, "<circle"), 3u);                   // one marker per step
}

TEST(ReportHtml, WallTableJoinsPlanarityAndGroundTruthErrors) {
    const std::string html = renderReportHtml(metrics(), ReportFigures{});
    const size_t at = html.find("<table class=walls>");
    ASSERT_NE(at, std::string::npos);
    const std::string t = html.substr(at, html.find("</table>", at) - at);
    EXPECT_EQ(count(t, "<tr>"), 4u);  // header + 3 walls
    // Wall 0 matched GT wall 10: planarity 2 mm, angle 0.5 deg, offset +1.2 cm.
    EXPECT_NE(t.find("<td>2.00</td><td>10</td><td>0.50</td><td>+1.20</td>"), std::string::npos);
    EXPECT_EQ(count(t, "matches no ground-truth wall"), 2u);
    EXPECT_NE(t.find("1 (snapped)"), std::string::npos);
}

}  // namespace
}  // namespace plumb::backend
