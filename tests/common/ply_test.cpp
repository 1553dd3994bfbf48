// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <string>

#include <fmt/format.h>

#include "common/io/ply.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

PointCloud randomCloud(size_t n, bool normals, bool colors, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-5.0f, 5.0f);
    std::uniform_int_distribution<int> c(0, 255);
    PointCloud cloud;
    for (size_t i = 0; i < n; ++i) {
        cloud.points.emplace_back(u(rng), u(rng), u(rng));
        if (normals) cloud.normals.push_back(Eigen::Vector3f(u(rng), u(rng), u(rng)).normalized());
        if (colors) cloud.colors.emplace_back(c(rng), c(rng), c(rng));
    }
    return cloud;
}

void writeFile(const fs::path& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

std::string readFile(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(Ply, PointCloudRoundTripIsExactInBothFormats) {
    const fs::path dir = testing::freshTempDir("ply_cloud_round_trip");
    for (io::PlyFormat format : {io::PlyFormat::kAscii, io::PlyFormat::kBinaryLittleEndian}) {
        for (int attrs = 0; attrs < 4; ++attrs) {
            const bool normals = (attrs & 1) != 0, colors = (attrs & 2) != 0;
            const PointCloud cloud = randomCloud(257, normals, colors, 7u + attrs);
            const fs::path path = dir / fmt::format("c{}_{}.ply", static_cast<int>(format), attrs);
            ASSERT_TRUE(io::writePointCloud(path, cloud, format).isOk());
            auto back = io::readPointCloud(path);
            ASSERT_TRUE(back.isOk()) << back.status().toString();
            EXPECT_EQ(back->points, cloud.points);  // bit-exact, also for ascii
            EXPECT_EQ(back->normals, cloud.normals);
            EXPECT_EQ(back->colors, cloud.colors);
        }
    }
    // An empty cloud is a valid file.
    ASSERT_TRUE(io::writePointCloud(dir / "empty.ply", PointCloud{}).isOk());
    auto empty = io::readPointCloud(dir / "empty.ply");
    ASSERT_TRUE(empty.isOk());
    EXPECT_TRUE(empty->empty());
}

TEST(Ply, MeshRoundTripIsExactInBothFormats) {
    const fs::path dir = testing::freshTempDir("ply_mesh_round_trip");
    const PointCloud cloud = randomCloud(40, true, true, 3);
    TriangleMesh mesh;
    mesh.vertices = cloud.points;
    mesh.normals = cloud.normals;
    mesh.colors = cloud.colors;
    for (int t = 0; t < 38; ++t) mesh.triangles.emplace_back(t, t + 1, (t * 7 + 2) % 40);
    for (io::PlyFormat format : {io::PlyFormat::kAscii, io::PlyFormat::kBinaryLittleEndian}) {
        const fs::path path = dir / fmt::format("m{}.ply", static_cast<int>(format));
        ASSERT_TRUE(io::writeTriangleMesh(path, mesh, format).isOk());
        auto back = io::readTriangleMesh(path);
        ASSERT_TRUE(back.isOk()) << back.status().toString();
        EXPECT_EQ(back->vertices, mesh.vertices);
        EXPECT_EQ(back->normals, mesh.normals);
        EXPECT_EQ(back->colors, mesh.colors);
        EXPECT_EQ(back->triangles, mesh.triangles);
        // The same file read as a cloud gives the vertices.
        auto as_cloud = io::readPointCloud(path);
        ASSERT_TRUE(as_cloud.isOk());
        EXPECT_EQ(as_cloud->points, mesh.vertices);
    }
    TriangleMesh bad = mesh;
    bad.triangles.emplace_back(0, 1, 40);
    EXPECT_EQ(io::writeTriangleMesh(dir / "bad.ply", bad).code(), StatusCode::kInvalidArgument);
    PointCloud nan_cloud = cloud;
    nan_cloud.points[3].y() = std::nanf("");
    EXPECT_EQ(io::writePointCloud(dir / "nan.ply", nan_cloud).code(), StatusCode::kInvalidArgument);
}

TEST(Ply, ReadsPolygonsOtherPropertiesAndTypeAliases) {
    const fs::path dir = testing::freshTempDir("ply_polygons");
    // Every scalar type appears as an extra property; colours are floats; faces use
    // `vertex_index` with a uint count and carry an extra list and scalar; an unknown element
    // with a list sits between vertices and faces.
    const std::string text =
        "ply\r\n"
        "format ascii 1.0\r\n"
        "comment hand written\n"
        "obj_info nothing\n"
        "element vertex 5\n"
        "property char a\nproperty float32 x\nproperty uint8 b\nproperty double y\n"
        "property short c\nproperty float z\nproperty ushort d\nproperty int e\n"
        "property uint f\nproperty list uchar float tags\nproperty int16 g\n"
        "property float red\nproperty float green\nproperty float blue\nproperty uchar alpha\n"
        "element edge 2\n"
        "property list int int ends\n"
        "element face 3\n"
        "property int8 flags\n"
        "property list uint uint32 vertex_index\n"
        "property list ushort double weights\n"
        "end_header\n"
        "-1 0 255 0 -7 0 65535 -9 9 2 0.5 0.25 3 1 0 0.5 200\n"
        "-1 1 255 0 -7 0 65535 -9 9 0 3 0 1 0 200\n"
        "-1 1 255 1 -7 0 65535 -9 9 1 7 3 0 0 0 200\n"
        "-1 0 255 1 -7 0 65535 -9 9 0 3 0.2 0.4 0.6 200\n"
        "-1 0.5 255 0.5 -7 2 65535 -9 9 0 3 1 1 1 200\n"
        "2 0 1\n"
        "3 1 2 3\n"
        "0 3 0 1 2 0\n"            // triangle, no weights
        "1 4 0 1 2 3 2 0.5 0.5\n"  // quad -> 2 triangles
        "0 5 0 1 2 3 4 1 9\n";     // pentagon -> 3 triangles
    writeFile(dir / "poly.ply", text);
    auto mesh = io::readTriangleMesh(dir / "poly.ply");
    ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
    ASSERT_EQ(mesh->vertices.size(), 5u);
    EXPECT_EQ(mesh->vertices[2], Eigen::Vector3f(1, 1, 0));
    EXPECT_EQ(mesh->vertices[4], Eigen::Vector3f(0.5f, 0.5f, 2.0f));
    EXPECT_TRUE(mesh->normals.empty());
    ASSERT_EQ(mesh->colors.size(), 5u);
    EXPECT_EQ(mesh->colors[0], Color3u8(255, 0, 128));
    EXPECT_EQ(mesh->colors[3], Color3u8(51, 102, 153));
    const std::vector<Eigen::Vector3i> expected = {{0, 1, 2}, {0, 1, 2}, {0, 2, 3},
                                                   {0, 1, 2}, {0, 2, 3}, {0, 3, 4}};
    EXPECT_EQ(mesh->triangles, expected);
}

/// Appends the big-endian bytes of v.
template <typename T>
void putBigEndian(std::string* out, T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if constexpr (std::endian::native == std::endian::little) std::reverse(b, b + sizeof(T));
    out->append(b, sizeof(T));
}

TEST(Ply, ReadsBinaryBigEndian) {
    const fs::path dir = testing::freshTempDir("ply_big_endian");
    std::string bytes =
        "ply\nformat binary_big_endian 1.0\nelement vertex 3\n"
        "property double x\nproperty double y\nproperty double z\n"
        "property short skip\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    const double xyz[3][3] = {{1.5, -2.25, 3.0}, {0.1, 0.2, 0.3}, {-7.0, 8.0, 1e-3}};
    for (int i = 0; i < 3; ++i) {
        for (double v : xyz[i]) putBigEndian(&bytes, v);
        putBigEndian(&bytes, int16_t{-1234});
        putBigEndian(&bytes, 0.0f);
        putBigEndian(&bytes, 1.0f);
        putBigEndian(&bytes, 0.0f);
        for (uint8_t c : {uint8_t(10 * i), uint8_t(20), uint8_t(250)}) putBigEndian(&bytes, c);
    }
    putBigEndian(&bytes, uint8_t{3});
    for (int32_t idx : {2, 0, 1}) putBigEndian(&bytes, idx);
    writeFile(dir / "be.ply", bytes);
    auto mesh = io::readTriangleMesh(dir / "be.ply");
    ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
    ASSERT_EQ(mesh->vertices.size(), 3u);
    for (int i = 0; i < 3; ++i) {
        EXPECT_EQ(mesh->vertices[i],
                  Eigen::Vector3d(xyz[i][0], xyz[i][1], xyz[i][2]).cast<float>());
        EXPECT_EQ(mesh->normals[i], Eigen::Vector3f(0, 1, 0));
        EXPECT_EQ(mesh->colors[i], Color3u8(10 * i, 20, 250));
    }
    ASSERT_EQ(mesh->triangles.size(), 1u);
    EXPECT_EQ(mesh->triangles[0], Eigen::Vector3i(2, 0, 1));
}

Status readError(const fs::path& path) {
    auto r = io::readTriangleMesh(path);
    return r.isOk() ? Status::ok() : r.status();
}

void expectError(const Status& s, StatusCode code, const std::string& part) {
    EXPECT_EQ(s.code(), code) << s.toString();
    EXPECT_NE(s.message().find(part), std::string::npos) << s.toString();
}

TEST(Ply, MalformedFilesGiveSpecificErrors) {
    const fs::path dir = testing::freshTempDir("ply_malformed");
    expectError(readError(dir / "missing.ply"), StatusCode::kNotFound, "missing.ply");

    writeFile(dir / "text.ply", "hello\nworld\n");
    expectError(readError(dir / "text.ply"), StatusCode::kCorrupt, "not a PLY file");

    writeFile(dir / "format.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n");
    expectError(readError(dir / "format.ply"), StatusCode::kUnsupported,
                "unknown PLY format 'binary_middle_endian'");

    writeFile(dir / "type.ply",
              "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n");
    expectError(readError(dir / "type.ply"), StatusCode::kUnsupported,
                "type.ply:4: unknown property type 'float128'");

    writeFile(dir / "noheaderend.ply", "ply\nformat ascii 1.0\nelement vertex 1\n");
    expectError(readError(dir / "noheaderend.ply"), StatusCode::kCorrupt, "end_header");

    writeFile(dir / "noxyz.ply",
              "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
              "end_header\n1 2\n");
    expectError(readError(dir / "noxyz.ply"), StatusCode::kUnsupported, "lacks x, y or z");

    // Truncated binary body: 10 vertices announced, 4 and a half present.
    const PointCloud cloud = randomCloud(10, false, false, 1);
    ASSERT_TRUE(io::writePointCloud(dir / "full.ply", cloud).isOk());
    const std::string full = readFile(dir / "full.ply");
    writeFile(dir / "truncated.ply", full.substr(0, full.size() - 5 * 12 - 6));
    expectError(readError(dir / "truncated.ply"), StatusCode::kCorrupt,
                "truncated: expected 10 vertex elements, read 4");
    // The same for ascii.
    ASSERT_TRUE(io::writePointCloud(dir / "full_ascii.ply", cloud, io::PlyFormat::kAscii).isOk());
    std::string ascii = readFile(dir / "full_ascii.ply");
    size_t cut = ascii.find("end_header\n") + 11;
    for (int line = 0; line < 7; ++line) cut = ascii.find('\n', cut) + 1;
    writeFile(dir / "truncated_ascii.ply", ascii.substr(0, cut));
    expectError(readError(dir / "truncated_ascii.ply"), StatusCode::kCorrupt,
                "truncated: expected 10 vertex elements, read 7");

    const std::string tri_header =
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n";
    writeFile(dir / "index.ply", tri_header + "3 0 1 3\n");
    expectError(readError(dir / "index.ply"), StatusCode::kCorrupt,
                "face 0 refers to vertex 3, but there are only 3 vertices");
    writeFile(dir / "negative.ply", tri_header + "3 0 -1 2\n");
    expectError(readError(dir / "negative.ply"), StatusCode::kCorrupt, "refers to vertex -1");
    writeFile(dir / "degenerate.ply", tri_header + "2 0 1\n");
    expectError(readError(dir / "degenerate.ply"), StatusCode::kCorrupt, "face 0 has 2 vertices");
    writeFile(dir / "word.ply", tri_header + "3 0 one 2\n");
    expectError(readError(dir / "word.ply"), StatusCode::kCorrupt,
                "word.ply:13: 'one' is not a number");

    writeFile(dir / "nan.ply",
              "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
              "property float z\nend_header\n0 0 0\n1 nan 0\n");
    expectError(readError(dir / "nan.ply"), StatusCode::kCorrupt,
                "vertex 1 has a non-finite coordinate");

    // A binary element count far beyond the file size fails before allocating.
    writeFile(dir / "huge.ply",
              "ply\nformat binary_little_endian 1.0\nelement vertex 400000000\n"
              "property float x\nproperty float y\nproperty float z\nend_header\n");
    expectError(readError(dir / "huge.ply"), StatusCode::kCorrupt, "truncated");
}

// ---- Open3D interoperability (python3-open3d as the oracle) ----

const char* kPython = "/usr/bin/python3";

bool open3dAvailable() {
    const std::string cmd = std::string(kPython) + " -c 'import open3d' > /dev/null 2>&1";
    return std::system(cmd.c_str()) == 0;
}

#define REQUIRE_OPEN3D()                                                             \
    do {                                                                             \
        if (!open3dAvailable()) {                                                    \
            if (::plumb::testing::runningInCi()) FAIL() << "python3-open3d missing"; \
            GTEST_SKIP() << "python3-open3d not importable";                         \
        }                                                                            \
    } while (false)

TEST(PlyOpen3d, FilesWrittenByOpen3dReadBackEqual) {
    REQUIRE_OPEN3D();
    const fs::path dir = testing::freshTempDir("ply_from_open3d");
    // Open3D writes doubles; values representable in float make the binary comparison exact.
    const std::string script = R"(
import numpy as np, open3d as o3d, sys
d = sys.argv[1]
rng = np.random.default_rng(5)
pts = rng.uniform(-3, 3, (100, 3)).astype(np.float32).astype(np.float64)
nrm = rng.normal(size=(100, 3)); nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
nrm = nrm.astype(np.float32).astype(np.float64)
col = rng.integers(0, 256, (100, 3))
pc = o3d.geometry.PointCloud()
pc.points = o3d.utility.Vector3dVector(pts)
pc.normals = o3d.utility.Vector3dVector(nrm)
pc.colors = o3d.utility.Vector3dVector(col / 255.0)
o3d.io.write_point_cloud(d + "/o3d_bin.ply", pc)
o3d.io.write_point_cloud(d + "/o3d_ascii.ply", pc, write_ascii=True)
np.savetxt(d + "/expected.txt", np.hstack([pts, nrm, col]), fmt="%.9g")
m = o3d.geometry.TriangleMesh.create_box(1.0, 2.0, 0.5)
o3d.io.write_triangle_mesh(d + "/box.ply", m)
np.savetxt(d + "/box_tris.txt", np.asarray(m.triangles), fmt="%d")
)";
    writeFile(dir / "write.py", script);
    const std::string cmd =
        fmt::format("{} {} {}", kPython, (dir / "write.py").string(), dir.string());
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;

    std::ifstream expected_in(dir / "expected.txt");
    std::vector<std::array<double, 9>> expected;
    std::array<double, 9> row;
    while (expected_in >> row[0] >> row[1] >> row[2] >> row[3] >> row[4] >> row[5] >> row[6] >>
           row[7] >> row[8]) {
        expected.push_back(row);
    }
    ASSERT_EQ(expected.size(), 100u);
    for (const char* file : {"o3d_bin.ply", "o3d_ascii.ply"}) {
        const bool binary = std::string(file) == "o3d_bin.ply";
        auto cloud = io::readPointCloud(dir / file);
        ASSERT_TRUE(cloud.isOk()) << cloud.status().toString();
        ASSERT_EQ(cloud->size(), 100u);
        ASSERT_TRUE(cloud->hasNormals() && cloud->hasColors());
        for (size_t i = 0; i < 100; ++i) {
            const auto& e = expected[i];
            const Eigen::Vector3f p(e[0], e[1], e[2]), n(e[3], e[4], e[5]);
            if (binary) {
                EXPECT_EQ(cloud->points[i], p) << i;
                EXPECT_EQ(cloud->normals[i], n) << i;
            } else {
                // Open3D's ascii writer prints fewer digits than a float needs.
                EXPECT_LT((cloud->points[i] - p).norm(), 1e-5f) << i;
                EXPECT_LT((cloud->normals[i] - n).norm(), 1e-5f) << i;
            }
            EXPECT_EQ(cloud->colors[i], Color3u8(e[6], e[7], e[8])) << i;
        }
    }
    auto box = io::readTriangleMesh(dir / "box.ply");
    ASSERT_TRUE(box.isOk()) << box.status().toString();
    EXPECT_EQ(box->vertices.size(), 8u);
    std::ifstream tris_in(dir / "box_tris.txt");
    std::vector<Eigen::Vector3i> tris;
    int a, b, c;
    while (tris_in >> a >> b >> c) tris.emplace_back(a, b, c);
    EXPECT_EQ(tris.size(), 12u);
    EXPECT_EQ(box->triangles, tris);
    Eigen::Vector3f hi = box->vertices[0], lo = box->vertices[0];
    for (const auto& v : box->vertices) {
        hi = hi.cwiseMax(v);
        lo = lo.cwiseMin(v);
    }
    EXPECT_EQ(hi, Eigen::Vector3f(1.0f, 2.0f, 0.5f));
    EXPECT_EQ(lo, Eigen::Vector3f::Zero());
}

TEST(PlyOpen3d, OurFilesReadInOpen3d) {
    REQUIRE_OPEN3D();
    const fs::path dir = testing::freshTempDir("ply_to_open3d");
    const PointCloud cloud = randomCloud(64, true, true, 11);
    ASSERT_TRUE(io::writePointCloud(dir / "ours_bin.ply", cloud).isOk());
    ASSERT_TRUE(io::writePointCloud(dir / "ours_ascii.ply", cloud, io::PlyFormat::kAscii).isOk());
    TriangleMesh mesh;
    mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0.5f}};
    mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
    ASSERT_TRUE(io::writeTriangleMesh(dir / "ours_mesh.ply", mesh).isOk());
    {
        std::ofstream out(dir / "expected.txt");
        out.precision(9);
        for (size_t i = 0; i < cloud.size(); ++i) {
            const auto& p = cloud.points[i];
            const auto& n = cloud.normals[i];
            const auto& c = cloud.colors[i];
            out << p.x() << ' ' << p.y() << ' ' << p.z() << ' ' << n.x() << ' ' << n.y() << ' '
                << n.z() << ' ' << int{c.x()} << ' ' << int{c.y()} << ' ' << int{c.z()} << '\n';
        }
    }
    // The script exits 0 only if Open3D reads everything equal (floats compared exactly after
    // rounding to float32; colours via round(255 c)).
    const std::string script = R"(
import numpy as np, open3d as o3d, sys
d = sys.argv[1]
e = np.loadtxt(d + "/expected.txt")
ok = True
for f in ["ours_bin.ply", "ours_ascii.ply"]:
    pc = o3d.io.read_point_cloud(d + "/" + f)
    p = np.asarray(pc.points).astype(np.float32); n = np.asarray(pc.normals).astype(np.float32)
    c = np.rint(np.asarray(pc.colors) * 255)
    ok &= p.shape == (64, 3) and np.array_equal(p, e[:, 0:3].astype(np.float32))
    ok &= np.array_equal(n, e[:, 3:6].astype(np.float32)) and np.array_equal(c, e[:, 6:9])
m = o3d.io.read_triangle_mesh(d + "/ours_mesh.ply")
ok &= np.array_equal(np.asarray(m.triangles), [[0, 1, 2], [0, 2, 3]])
ok &= abs(m.get_surface_area() - (0.5 + 0.5 * np.sqrt(1.5))) < 1e-6
sys.exit(0 if ok else 3)
)";
    writeFile(dir / "check.py", script);
    const std::string cmd =
        fmt::format("{} {} {}", kPython, (dir / "check.py").string(), dir.string());
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
}

}  // namespace
}  // namespace plumb
