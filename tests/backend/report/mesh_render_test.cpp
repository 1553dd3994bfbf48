// SPDX-License-Identifier: Apache-2.0
// The report's software rasteriser and PNG/base64 encoding.
#include <gtest/gtest.h>

#include <cmath>

#include "backend/report/mesh_render.hpp"
#include "backend/report/png_encode.hpp"

namespace plumb::backend {
namespace {

/// An axis-aligned square at height z, [x0, x1] x [y0, y1], counter-clockwise seen from +z.
void addSquare(TriangleMesh& mesh, double x0, double x1, double y0, double y1, double z,
               const Color3u8& colour) {
    const int base = static_cast<int>(mesh.vertices.size());
    mesh.vertices.emplace_back(x0, y0, z);
    mesh.vertices.emplace_back(x1, y0, z);
    mesh.vertices.emplace_back(x1, y1, z);
    mesh.vertices.emplace_back(x0, y1, z);
    for (int k = 0; k < 4; ++k) mesh.colors.push_back(colour);
    mesh.triangles.emplace_back(base, base + 1, base + 2);
    mesh.triangles.emplace_back(base, base + 2, base + 3);
}

MeshRenderConfig planView(int size) {
    MeshRenderConfig c;
    c.width_px = size;
    c.height_px = size;
    c.elevation_deg = 90.0;
    c.azimuth_deg = -90.0;
    c.margin = 0.0;
    c.light_direction_U = Eigen::Vector3d::UnitZ();
    c.ambient = 0.0;
    return c;
}

size_t countNot(const RgbImage& image, const Color3u8& background) {
    size_t n = 0;
    for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x) n += image.at(x, y) != background;
    return n;
}

TEST(MeshRender, PlanViewOfASquareFillsItAndMapsXRightYUp) {
    TriangleMesh mesh;
    addSquare(mesh, 0.0, 2.0, 0.0, 1.0, 0.0, Color3u8(200, 0, 0));
    // A small marker in the +x, +y corner, slightly higher so it wins the depth test.
    addSquare(mesh, 1.8, 2.0, 0.8, 1.0, 0.01, Color3u8(0, 0, 200));
    const MeshRender r = renderMesh(mesh, Eigen::Isometry3d::Identity(), planView(100));
    // 2 m x 1 m fitted into 100 px: 50 px per metre, rows 25..74 covered.
    EXPECT_NEAR(r.focal_px, 50.0, 1e-6);
    EXPECT_EQ(r.image.at(50, 50), Color3u8(200, 0, 0));
    EXPECT_EQ(r.image.at(50, 10), Color3u8(255, 255, 255));  // above the square: background
    EXPECT_EQ(r.image.at(50, 90), Color3u8(255, 255, 255));
    EXPECT_NEAR(double(countNot(r.image, Color3u8(255, 255, 255))), 100.0 * 50.0, 200.0);
    // +x is right and +y is up: the marker sits top right.
    EXPECT_EQ(r.image.at(97, 27), Color3u8(0, 0, 200));
    EXPECT_EQ(r.image.at(2, 72), Color3u8(200, 0, 0));
    // project() agrees with where things were drawn.
    const auto p = r.project(Eigen::Vector3d(1.9, 0.9, 0.01));
    ASSERT_TRUE(p.has_value());
    EXPECT_NEAR(p->x(), 95.0, 1e-6);
    EXPECT_NEAR(p->y(), 30.0, 1e-6);
    EXPECT_EQ(r.triangles_drawn, 4u);
}

TEST(MeshRender, NearerSurfaceWinsWhicheverOrderItIsDrawnIn) {
    for (bool low_first : {true, false}) {
        TriangleMesh mesh;
        if (low_first) addSquare(mesh, 0, 1, 0, 1, 0.0, Color3u8(0, 200, 0));
        addSquare(mesh, 0.25, 0.75, 0.25, 0.75, 0.5, Color3u8(0, 0, 200));
        if (!low_first) addSquare(mesh, 0, 1, 0, 1, 0.0, Color3u8(0, 200, 0));
        for (RenderProjection projection :
             {RenderProjection::kOrthographic, RenderProjection::kPerspective}) {
            MeshRenderConfig c = planView(64);
            c.projection = projection;
            c.elevation_deg = 89.0;  // nearly straight down either way
            const MeshRender r = renderMesh(mesh, Eigen::Isometry3d::Identity(), c);
            EXPECT_EQ(r.image.at(32, 32), Color3u8(0, 0, 200)) << low_first;
            const float centre = r.depth[32 * 64 + 32];
            EXPECT_TRUE(std::isfinite(centre));
            // Near the image's edge only the low square is there, and it is further away.
            const auto edge = r.project(Eigen::Vector3d(0.1, 0.5, 0.0));
            ASSERT_TRUE(edge.has_value());
            const int ex = static_cast<int>(edge->x()), ey = static_cast<int>(edge->y());
            EXPECT_EQ(r.image.at(ex, ey), Color3u8(0, 200, 0));
            EXPECT_GT(r.depth[ey * 64 + ex], centre);
        }
    }
}

TEST(MeshRender, LambertShadingDarkensFacesTurnedFromTheLight) {
    TriangleMesh mesh;
    addSquare(mesh, 0, 1, 0, 1, 0.0, Color3u8(200, 200, 200));
    MeshRenderConfig c = planView(32);
    c.light_direction_U = Eigen::Vector3d(1.0, 0.0, 1.0);  // 45 deg: cos = 0.707
    c.ambient = 0.2;
    const MeshRender r = renderMesh(mesh, Eigen::Isometry3d::Identity(), c);
    const double expected = 200.0 * (0.2 + 0.8 * std::sqrt(0.5));
    EXPECT_NEAR(r.image.at(16, 16).x(), expected, 1.0);
}

TEST(MeshRender, CutAndBackFaceCullingOpenARoomFromAbove) {
    // A floor (seen from above: front) and a ceiling facing down, 2.5 m up.
    TriangleMesh mesh;
    addSquare(mesh, 0, 4, 0, 3, 0.0, Color3u8(0, 200, 0));
    addSquare(mesh, 0, 4, 0, 3, 2.5, Color3u8(200, 0, 0));
    for (size_t t = mesh.triangles.size() - 2; t < mesh.triangles.size(); ++t)
        std::swap(mesh.triangles[t][1], mesh.triangles[t][2]);  // now faces down
    MeshRenderConfig c = planView(40);
    EXPECT_EQ(renderMesh(mesh, Eigen::Isometry3d::Identity(), c).image.at(20, 20),
              Color3u8(200, 0, 0));  // the ceiling hides the floor
    c.cull_back_faces = true;
    const MeshRender culled = renderMesh(mesh, Eigen::Isometry3d::Identity(), c);
    EXPECT_EQ(culled.image.at(20, 20), Color3u8(0, 200, 0));
    EXPECT_EQ(culled.triangles_culled, 2u);
    c.cull_back_faces = false;
    c.cut_top_fraction = 0.2;
    EXPECT_EQ(renderMesh(mesh, Eigen::Isometry3d::Identity(), c).image.at(20, 20),
              Color3u8(0, 200, 0));
}

TEST(MeshRender, ObliqueViewOfACubeShowsTopAndTwoSidesWithDifferentShades) {
    // Unit cube, outward faces, grey.
    TriangleMesh mesh;
    for (int i = 0; i < 8; ++i) mesh.vertices.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
    mesh.colors.assign(8, Color3u8(200, 200, 200));
    const int faces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                             {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (const auto& f : faces) {
        mesh.triangles.emplace_back(f[0], f[1], f[2]);
        mesh.triangles.emplace_back(f[0], f[2], f[3]);
    }
    MeshRenderConfig c;
    c.width_px = 120;
    c.height_px = 120;
    c.azimuth_deg = -60.0;
    c.elevation_deg = 35.0;
    c.light_direction_U = Eigen::Vector3d(0.2, -0.5, 1.0);
    const MeshRender r = renderMesh(mesh, Eigen::Isometry3d::Identity(), c);
    // Points on the visible faces: top (z = 1), front (y = 0), right (x = 1).
    auto colourAt = [&](const Eigen::Vector3d& p) {
        const auto q = r.project(p);
        EXPECT_TRUE(q.has_value());
        return r.image.at(static_cast<int>(q->x()), static_cast<int>(q->y()));
    };
    const Color3u8 top = colourAt({0.5, 0.5, 1.0});
    const Color3u8 front = colourAt({0.5, 0.0, 0.5});
    const Color3u8 right = colourAt({1.0, 0.5, 0.5});
    EXPECT_NE(top, Color3u8(255, 255, 255));
    EXPECT_NE(front, Color3u8(255, 255, 255));
    EXPECT_NE(right, Color3u8(255, 255, 255));
    EXPECT_GT(top.x(), front.x());
    EXPECT_NE(front.x(), right.x());
    EXPECT_EQ(r.image.at(1, 1), Color3u8(255, 255, 255));
    // Closed surface: culling back faces changes nothing visible.
    c.cull_back_faces = true;
    const MeshRender culled = renderMesh(mesh, Eigen::Isometry3d::Identity(), c);
    EXPECT_EQ(culled.image.rgb, r.image.rgb);
    EXPECT_EQ(culled.triangles_culled, 6u);
}

TEST(MeshRender, EmptyMeshGivesTheBackground) {
    const MeshRender r = renderMesh(TriangleMesh{}, Eigen::Isometry3d::Identity(), planView(8));
    EXPECT_EQ(countNot(r.image, Color3u8(255, 255, 255)), 0u);
    EXPECT_EQ(r.triangles_drawn, 0u);
}

TEST(PngEncode, Base64MatchesRfc4648Vectors) {
    EXPECT_EQ(base64(""), "");
    EXPECT_EQ(base64("f"), "Zg==");
    EXPECT_EQ(base64("fo"), "Zm8=");
    EXPECT_EQ(base64("foo"), "Zm9v");
    EXPECT_EQ(base64("foob"), "Zm9vYg==");
    EXPECT_EQ(base64("fooba"), "Zm9vYmE=");
    EXPECT_EQ(base64("foobar"), "Zm9vYmFy");
}

TEST(PngEncode, ProducesAPngWithTheImageSize) {
    RgbImage image{7, 3, std::vector<uint8_t>(7 * 3 * 3, 128)};
    Result<std::string> png = encodePng(image);
    ASSERT_TRUE(png.isOk()) << png.status().toString();
    ASSERT_GT(png->size(), 24u);
    EXPECT_EQ(png->substr(1, 3), "PNG");
    const auto be32 = [&](size_t at) {
        return (uint32_t(uint8_t((*png)[at])) << 24) | (uint32_t(uint8_t((*png)[at + 1])) << 16) |
               (uint32_t(uint8_t((*png)[at + 2])) << 8) | uint32_t(uint8_t((*png)[at + 3]));
    };
    EXPECT_EQ(be32(16), 7u);  // IHDR width
    EXPECT_EQ(be32(20), 3u);  // IHDR height
    EXPECT_EQ(pngDataUri(image).rfind("data:image/png;base64,iVBORw0KGgo", 0), 0u);
    EXPECT_FALSE(encodePng(RgbImage{}).isOk());
}

}  // namespace
}  // namespace plumb::backend
