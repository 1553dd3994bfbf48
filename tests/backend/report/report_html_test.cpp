// SPDX-License-Identifier: Apache-2.0
// report.html (issue 31): sections present, pictures embedded as PNG, size bounded.
#include <gtest/gtest.h>

#include <cmath>
#include <regex>
#include <string>

#include "backend/report/png_encode.hpp"
#include "backend/report/report_html.hpp"
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

}  // namespace
}  // namespace plumb::backend
