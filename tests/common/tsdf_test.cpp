// SPDX-License-Identifier: Apache-2.0
// TSDF volume, raycaster and surface extraction on analytic scenes rendered here: planes and a
// sphere whose depth has a closed form per pixel, so every error is measured against exact truth.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <optional>
#include <random>
#include <utility>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/core/simd.hpp"
#include "common/geometry/lie.hpp"
#include "common/tsdf/raycast.hpp"
#include "common/tsdf/surface.hpp"
#include "common/tsdf/tsdf_volume.hpp"

namespace plumb::tsdf {
namespace {

struct Plane {
    Eigen::Vector3d n;  ///< unit normal (world)
    double d;           ///< n.x + d = 0
};
struct Sphere {
    Eigen::Vector3d c;
    double r;
};

/// Ray parameter (camera z-depth) of the first hit, or nullopt.
std::optional<double> hitPlane(const Plane& pl, const Eigen::Vector3d& o,
                               const Eigen::Vector3d& r) {
    const double den = pl.n.dot(r);
    if (std::abs(den) < 1e-12) return std::nullopt;
    const double t = -(pl.n.dot(o) + pl.d) / den;
    if (t <= 0.0) return std::nullopt;
    return t;
}
std::optional<double> hitSphere(const Sphere& s, const Eigen::Vector3d& o,
                                const Eigen::Vector3d& r) {
    const Eigen::Vector3d oc = o - s.c;
    const double a = r.squaredNorm(), b = 2.0 * oc.dot(r), c = oc.squaredNorm() - s.r * s.r;
    const double disc = b * b - 4 * a * c;
    if (disc < 0.0) return std::nullopt;
    const double t = (-b - std::sqrt(disc)) / (2 * a);
    if (t <= 0.0) return std::nullopt;
    return t;
}

template <typename HitFn>
DepthImage render(const PinholeCamera& cam, const Eigen::Isometry3d& T_W_C, HitFn hit) {
    DepthImage depth(cam.width, cam.height, 0.0f);
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            const Eigen::Vector3d r = T_W_C.linear() * cam.ray(u, v);
            const std::optional<double> t = hit(T_W_C.translation(), r);
            if (t && *t < 4.0) depth(u, v) = static_cast<float>(*t);
        }
    }
    return depth;
}

/// Camera at `eye` looking at `target` (camera z forward, y roughly along world -z... any up).
Eigen::Isometry3d lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
    const Eigen::Vector3d z = (target - eye).normalized();
    Eigen::Vector3d up =
        std::abs(z.y()) < 0.9 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitX();
    const Eigen::Vector3d x = up.cross(z).normalized();
    const Eigen::Vector3d y = z.cross(x);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear().col(0) = x;
    T.linear().col(1) = y;
    T.linear().col(2) = z;
    T.translation() = eye;
    return T;
}

PinholeCamera smallCamera() { return cameraPreset("ci").value(); }  // 160x120

TsdfConfig testConfig(float voxel = 0.01f) {
    TsdfConfig c;
    c.voxel_size_m = voxel;
    c.truncation_m = 0.04f;
    c.allocation_stride_px = 1;
    return c;
}

/// Small hand-held style jitter of the camera, deterministic.
Eigen::Isometry3d jitter(int k) {
    Vector6d xi;
    xi << 0.01 * std::sin(k), 0.01 * std::cos(1.3 * k), 0.005 * std::sin(0.7 * k),
        0.01 * std::cos(k), 0.01 * std::sin(2.1 * k), 0.01 * std::sin(0.5 * k);
    return lie::expSE3(xi);
}

/// Fuses `frames` jittered views of `sphere` into `volume`.
void integrateSphere(const PinholeCamera& cam, const Sphere& sphere, int frames,
                     TsdfVolume* volume) {
    for (int k = 0; k < frames; ++k) {
        const Eigen::Isometry3d T_W_C = jitter(k);
        ASSERT_TRUE(volume
                        ->integrate(render(cam, T_W_C,
                                           [&](auto o, auto r) { return hitSphere(sphere, o, r); }),
                                    cam, T_W_C)
                        .isOk());
    }
}

struct Stats {
    double mean = 0.0;
    double max = 0.0;
};
template <typename Fn>
Stats distanceStats(const PointCloud& cloud, Fn dist) {
    Stats s;
    for (const auto& p : cloud.points) {
        const double d = std::abs(dist(p.cast<double>()));
        s.mean += d;
        s.max = std::max(s.max, d);
    }
    s.mean /= std::max<size_t>(1, cloud.size());
    return s;
}

TEST(TsdfVolume, BlockHashFindsEveryInsertedKey) {
    BlockHashMap map;
    int n = 0;
    for (int z = -20; z < 20; ++z)
        for (int y = -5; y < 5; ++y)
            for (int x = -7; x < 7; ++x) map.insert(BlockKey(x, y, z), n++);
    EXPECT_EQ(map.size(), static_cast<size_t>(n));
    int expected = 0;
    for (int z = -20; z < 20; ++z)
        for (int y = -5; y < 5; ++y)
            for (int x = -7; x < 7; ++x) EXPECT_EQ(map.find(x, y, z), expected++);
    EXPECT_EQ(map.find(100, 0, 0), BlockHashMap::kNotFound);
}

TEST(TsdfVolume, FrontoParallelPlaneSurfaceAndRaycastAreUnbiased) {
    const PinholeCamera cam = smallCamera();
    // Off-grid distances where a grid-snapped raycast is wrong by millimetres.
    for (const double z_plane : {1.5025, 1.505, 1.5137}) {
        const Plane plane{Eigen::Vector3d(0, 0, -1), z_plane};
        TsdfVolume volume(testConfig());
        for (int k = 0; k < 10; ++k) {
            const Eigen::Isometry3d T_W_C = jitter(k);
            const DepthImage depth =
                render(cam, T_W_C, [&](auto o, auto r) { return hitPlane(plane, o, r); });
            ASSERT_TRUE(volume.integrate(depth, cam, T_W_C).isOk());
        }
        const PointCloud surface = extractSurfacePoints(volume);
        ASSERT_GT(surface.size(), 5000u);
        const Stats s =
            distanceStats(surface, [&](const Eigen::Vector3d& p) { return p.z() - z_plane; });
        EXPECT_LT(s.mean, 0.25 * volume.voxelSize()) << "plane at " << z_plane;
        for (const auto& n : surface.normals) ASSERT_GT(-n.z(), 0.99f);

        const Eigen::Isometry3d T_W_C = jitter(3);
        const RaycastResult ray = raycast(volume, cam, T_W_C);
        const DepthImage truth =
            render(cam, T_W_C, [&](auto o, auto r) { return hitPlane(plane, o, r); });
        double bias = 0.0, abs_err = 0.0;
        int valid = 0;
        for (int v = 0; v < cam.height; ++v) {
            for (int u = 0; u < cam.width; ++u) {
                if (ray.depth(u, v) <= 0.0f) continue;
                bias += ray.depth(u, v) - truth(u, v);
                abs_err += std::abs(ray.depth(u, v) - truth(u, v));
                ++valid;
            }
        }
        ASSERT_GT(valid, cam.width * cam.height * 8 / 10);
        bias /= valid;
        abs_err /= valid;
        EXPECT_LT(std::abs(bias), 0.0005) << "plane at " << z_plane;
        EXPECT_LT(abs_err, 0.0005) << "plane at " << z_plane;
    }
}

/// A colour that varies smoothly over the world: 3 levels per centimetre in red and green.
Rgb8 worldColour(const Eigen::Vector3d& p) {
    auto level = [](double x) { return static_cast<uint8_t>(std::clamp(x, 0.0, 255.0)); };
    return {level(128.0 + 300.0 * p.x()), level(128.0 + 300.0 * p.y()), 60};
}

TEST(TsdfVolume, ColourBlendIsTheRoundedRunningAverage) {
    for (uint32_t w = 0; w < 256; ++w) {
        for (uint32_t avg = 0; avg < 256; ++avg) {
            for (uint32_t c = 0; c < 256; ++c) {
                const uint32_t exact = (2 * (w * avg + c) + w + 1) / (2 * (w + 1));
                ASSERT_EQ(blendColourChannel(avg, w, c), exact)
                    << "w " << w << " avg " << avg << " sample " << c;
            }
        }
    }
}

TEST(TsdfVolume, ColourFollowsTheSurfaceAndLeavesTheTsdfUnchanged) {
    const PinholeCamera cam = smallCamera();
    const Plane plane{Eigen::Vector3d(0, 0, -1), 1.5};
    TsdfVolume coloured(testConfig()), plain(testConfig());
    for (int k = 0; k < 10; ++k) {
        const Eigen::Isometry3d T_W_C = jitter(k);
        const DepthImage depth =
            render(cam, T_W_C, [&](auto o, auto r) { return hitPlane(plane, o, r); });
        ColourImage colour(cam.width, cam.height);
        for (int v = 0; v < cam.height; ++v) {
            for (int u = 0; u < cam.width; ++u) {
                const Eigen::Vector3d r = T_W_C.linear() * cam.ray(u, v);
                if (depth(u, v) > 0.0f) {
                    colour(u, v) = worldColour(T_W_C.translation() + depth(u, v) * r);
                }
            }
        }
        ASSERT_TRUE(coloured.integrate(depth, cam, T_W_C, &colour).isOk());
        ASSERT_TRUE(plain.integrate(depth, cam, T_W_C).isOk());
    }
    EXPECT_TRUE(coloured.hasColour());
    EXPECT_FALSE(plain.hasColour());
    // The TSDF is the same bit for bit: colour rides along.
    ASSERT_EQ(coloured.numBlocks(), plain.numBlocks());
    for (size_t b = 0; b < coloured.numBlocks(); ++b) {
        const Voxel* a = coloured.blockVoxels(static_cast<int32_t>(b));
        const Voxel* c = plain.blockVoxels(static_cast<int32_t>(b));
        for (int i = 0; i < kBlockVoxels; ++i) {
            ASSERT_EQ(a[i].tsdf, c[i].tsdf);
            ASSERT_EQ(a[i].weight, c[i].weight);
        }
    }
    // Surface points carry the colour of the place they lie on, to a few levels (a voxel is
    // 1 cm: 3 levels of the gradient).
    const PointCloud surface = extractSurfacePoints(coloured);
    ASSERT_GT(surface.size(), 5000u);
    ASSERT_TRUE(surface.hasColors());
    EXPECT_FALSE(extractSurfacePoints(plain).hasColors());
    double err = 0.0, worst = 0.0;
    for (size_t i = 0; i < surface.size(); ++i) {
        const Rgb8 truth = worldColour(surface.points[i].cast<double>());
        const double e = std::max({std::abs(surface.colors[i].x() - truth.r),
                                   std::abs(surface.colors[i].y() - truth.g),
                                   std::abs(surface.colors[i].z() - truth.b)});
        err += e;
        worst = std::max(worst, e);
    }
    err /= static_cast<double>(surface.size());
    EXPECT_LT(err, 2.0);
    EXPECT_LT(worst, 8.0);
    // Meshes carry the same colours.
    const TriangleMesh mesh = extractMesh(coloured);
    ASSERT_EQ(mesh.colors.size(), mesh.vertices.size());
    // A colour image of the wrong size is refused.
    const ColourImage wrong(cam.width / 2, cam.height);
    EXPECT_FALSE(coloured
                     .integrate(render(cam, jitter(0),
                                       [&](auto o, auto r) { return hitPlane(plane, o, r); }),
                                cam, jitter(0), &wrong)
                     .isOk());
}

// A tilted plane fused from 10 views of `cam`: the surface and the raycast from a further view
// are unbiased, and the raycast's normals of each kind in `kinds` follow the plane.
void checkTiltedPlane(const PinholeCamera& cam, const std::vector<RaycastNormals>& kinds) {
    const Plane plane{Eigen::Vector3d(0.3, -0.25, -1.0).normalized(), 1.4};
    TsdfConfig config = testConfig(3.0f / 512.0f);
    TsdfVolume volume(config);
    for (int k = 0; k < 10; ++k) {
        const Eigen::Isometry3d T_W_C = jitter(k);
        ASSERT_TRUE(volume
                        .integrate(render(cam, T_W_C,
                                          [&](auto o, auto r) { return hitPlane(plane, o, r); }),
                                   cam, T_W_C)
                        .isOk());
    }
    const PointCloud surface = extractSurfacePoints(volume);
    ASSERT_GT(surface.size(), 10000u);
    const Stats s =
        distanceStats(surface, [&](const Eigen::Vector3d& p) { return plane.n.dot(p) + plane.d; });
    EXPECT_LT(s.mean, 0.25 * volume.voxelSize());

    const Eigen::Isometry3d T_W_C = jitter(5);
    for (const RaycastNormals normals : kinds) {
        for (const bool secant : {false, true}) {
            const std::string kind = std::to_string(static_cast<int>(normals)) +
                                     (secant ? " with secant hits" : "") + " at " +
                                     std::to_string(cam.width) + "x" + std::to_string(cam.height);
            RaycastConfig rc;
            rc.normals = normals;
            rc.secant_hits = secant;
            const RaycastResult ray = raycast(volume, cam, T_W_C, rc);
            double bias = 0.0, normal_err = 0.0;
            int valid = 0;
            for (int v = 0; v < cam.height; ++v) {
                for (int u = 0; u < cam.width; ++u) {
                    if (ray.depth(u, v) <= 0.0f) continue;
                    bias += plane.n.dot(ray.points_V(u, v).cast<double>()) + plane.d;
                    normal_err += std::acos(
                        std::clamp(plane.n.dot(ray.normals_V(u, v).cast<double>()), -1.0, 1.0));
                    ++valid;
                }
            }
            ASSERT_GT(valid, cam.width * cam.height * 8 / 10) << kind;
            EXPECT_LT(std::abs(bias / valid), 0.0005) << kind;  // metres: measured below 1 um
            // Radians; the projective TSDF tilts gradients slightly (at 640x480: gradient 0.007,
            // cell 0.010, neighbours 0.011).
            EXPECT_LT(normal_err / valid, 0.03) << kind;
        }
    }
}

TEST(TsdfVolume, TiltedPlaneSurfaceAndRaycastAreUnbiased) {
    // 160x120: a pixel covers 1.8 voxels at 1.4 m, and the projective distance is constant
    // across a pixel's footprint, so one cell's gradient leans towards the ray (0.05 rad); the
    // gradient's central differences and the neighbouring hits span more.
    checkTiltedPlane(smallCamera(), {RaycastNormals::kNeighbours, RaycastNormals::kGradient});
}

TEST(TsdfVolume, CellNormalsFollowATiltedPlaneWhenPixelsAreFinerThanVoxels) {
    // 640x480: a pixel covers half a voxel at 1.4 m (the device's camera and voxel).
    checkTiltedPlane(
        cameraPreset("primesense").value(),
        {RaycastNormals::kNeighbours, RaycastNormals::kGradient, RaycastNormals::kCell});
}

TEST(TsdfVolume, SphereSurfacePointsAndNormals) {
    const PinholeCamera cam = smallCamera();
    const Sphere sphere{Eigen::Vector3d(0.05, -0.02, 1.2), 0.3};
    TsdfVolume volume(testConfig());
    integrateSphere(cam, sphere, 10, &volume);
    const PointCloud surface = extractSurfacePoints(volume);
    ASSERT_GT(surface.size(), 1000u);
    const Stats s = distanceStats(
        surface, [&](const Eigen::Vector3d& p) { return (p - sphere.c).norm() - sphere.r; });
    EXPECT_LT(s.mean, 0.25 * volume.voxelSize());
    double angle = 0.0;
    for (size_t i = 0; i < surface.size(); ++i) {
        const Eigen::Vector3d radial = (surface.points[i].cast<double>() - sphere.c).normalized();
        angle += std::acos(std::min(1.0, radial.dot(surface.normals[i].cast<double>())));
    }
    EXPECT_LT(angle / surface.size(), 0.05);
}

/// Trilinear TSDF at p from the 8 voxels of its cell read one by one, in the order of the
/// formula: the reference for interpolate().
std::optional<float> trilinearByVoxels(const TsdfVolume& volume, const Eigen::Vector3f& p,
                                       float min_weight) {
    const Eigen::Vector3f q = p / volume.voxelSize();
    const Eigen::Vector3f f = q.array().floor();
    const Eigen::Vector3i g = f.cast<int>();
    const Eigen::Vector3f a = q - f;
    float c[8];
    for (int i = 0; i < 8; ++i) {
        const Voxel* v = volume.voxel(g + Eigen::Vector3i(i & 1, (i >> 1) & 1, (i >> 2) & 1));
        if (v == nullptr || !(v->weight >= min_weight)) return std::nullopt;
        c[i] = v->tsdf;
    }
    const float c00 = c[0] + a.x() * (c[1] - c[0]), c10 = c[2] + a.x() * (c[3] - c[2]);
    const float c01 = c[4] + a.x() * (c[5] - c[4]), c11 = c[6] + a.x() * (c[7] - c[6]);
    const float c0 = c00 + a.y() * (c10 - c00), c1 = c01 + a.y() * (c11 - c01);
    return c0 + a.z() * (c1 - c0);
}

TEST(TsdfVolume, InterpolationAndGradientReadTheRightVoxelsAcrossBlockFaces) {
    // Random points around an integrated sphere, many in cells that straddle block faces: the
    // interpolation equals the formula over the cell's 8 voxels bit for bit, with and without a
    // block cache, the gradient is the central difference of that interpolation and the cell
    // gradient its derivative inside the cell.
    const PinholeCamera cam = smallCamera();
    const Sphere sphere{Eigen::Vector3d(0.05, -0.02, 1.2), 0.3};
    TsdfVolume volume(testConfig());
    integrateSphere(cam, sphere, 4, &volume);
    BlockCache cache(volume);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    const float h = volume.voxelSize();
    int observed = 0, straddling = 0, gradients = 0;
    for (int i = 0; i < 20000; ++i) {
        const Eigen::Vector3f dir = Eigen::Vector3f(unit(rng), unit(rng), unit(rng)).normalized();
        const Eigen::Vector3f p = sphere.c.cast<float>() + dir * (0.3f + 0.03f * unit(rng));
        const std::optional<float> expected = trilinearByVoxels(volume, p, 1.0f);
        float plain = 0.0f, cached = 0.0f;
        ASSERT_EQ(volume.interpolate(p, 1.0f, &plain), expected.has_value());
        const Sample sample = volume.sample(p, 1.0f, &cache, &cached);
        ASSERT_EQ(sample == Sample::kObserved, expected.has_value());
        const Eigen::Vector3i g = (p / h).array().floor().cast<int>();
        ASSERT_EQ(sample == Sample::kUnallocated, volume.findBlock(blockOf(g)) < 0);
        if (!expected) continue;
        ++observed;
        straddling += (g.x() & 7) == 7 ? 1 : 0;  // the cell's x pairs span two blocks
        ASSERT_EQ(plain, *expected);
        ASSERT_EQ(cached, *expected);
        // The cell gradient: the same value, and the derivative of the trilinear formula inside
        // p's cell, which along one axis is linear: the difference across the cell is exact.
        float with_grad = 0.0f;
        Eigen::Vector3f cell_grad;
        ASSERT_EQ(volume.sample(p, 1.0f, &cache, &with_grad, &cell_grad), Sample::kObserved);
        ASSERT_EQ(with_grad, *expected);
        for (int axis = 0; axis < 3; ++axis) {
            Eigen::Vector3f lo = p, hi = p;
            lo[axis] = (static_cast<float>(g[axis]) + 0.01f) * h;
            hi[axis] = (static_cast<float>(g[axis]) + 0.99f) * h;
            const std::optional<float> f_lo = trilinearByVoxels(volume, lo, 1.0f);
            const std::optional<float> f_hi = trilinearByVoxels(volume, hi, 1.0f);
            ASSERT_TRUE(f_lo && f_hi);
            const float slope = (*f_hi - *f_lo) / (hi[axis] - lo[axis]);
            ASSERT_NEAR(cell_grad[axis], slope, 1e-3f * std::max(1.0f, std::abs(slope)))
                << "axis " << axis << " p " << p.transpose();
        }
        Eigen::Vector3f grad, grad_cached, central;
        bool all = true;
        for (int axis = 0; axis < 3 && all; ++axis) {
            const Eigen::Vector3f e = Eigen::Vector3f::Unit(axis) * h;
            float fp = 0.0f, fm = 0.0f;
            all = volume.interpolate(p + e, 1.0f, &fp) && volume.interpolate(p - e, 1.0f, &fm);
            central[axis] = (fp - fm) / (2.0f * h);
        }
        ASSERT_EQ(volume.gradient(p, 1.0f, &grad), all);
        ASSERT_EQ(volume.gradient(p, 1.0f, &cache, &grad_cached), all);
        if (!all) continue;
        ++gradients;
        ASSERT_EQ(grad, grad_cached);
        // p +- h e shares p's fractional offset up to rounding of the shifted point.
        ASSERT_LT((grad - central).norm(), 1e-3f * std::max(1.0f, central.norm()))
            << "p " << p.transpose() << " q " << (p / h).transpose() << " grad " << grad.transpose()
            << " central " << central.transpose();
    }
    EXPECT_GT(observed, 3000);
    EXPECT_GT(straddling, 300);
    EXPECT_GT(gradients, 2000);
}

/// Pixels where two raycasts disagree: one hits and the other does not, or their depths differ
/// by more than `tol` metres.
int raycastDifferences(const RaycastResult& a, const RaycastResult& b, float tol) {
    int differ = 0;
    for (int v = 0; v < a.depth.height(); ++v) {
        for (int u = 0; u < a.depth.width(); ++u) {
            const float da = a.depth(u, v), db = b.depth(u, v);
            if ((da > 0.0f) != (db > 0.0f) || std::abs(da - db) > tol) ++differ;
        }
    }
    return differ;
}

TEST(Raycast, MarchingFromTheLastFusedDepthFindsTheSameSurface) {
    // A ball in front of a tilted wall (depth edges all around it), fused from ten views; the
    // raycast from the last view's pose marches from the depth that view measured.
    const PinholeCamera cam = smallCamera();
    const Plane wall{Eigen::Vector3d(0.2, -0.1, -1.0).normalized(), 1.8};
    const Sphere ball{Eigen::Vector3d(0.1, 0.05, 1.1), 0.2};
    const auto scene = [&](const Eigen::Vector3d& o, const Eigen::Vector3d& r) {
        std::optional<double> t = hitPlane(wall, o, r);
        const std::optional<double> ts = hitSphere(ball, o, r);
        if (ts && (!t || *ts < *t)) t = ts;
        return t;
    };
    TsdfVolume volume(testConfig(3.0f / 512.0f));
    DepthImage last;
    Eigen::Isometry3d T_last;
    for (int k = 0; k < 10; ++k) {
        T_last = jitter(k);
        last = render(cam, T_last, scene);
        ASSERT_TRUE(volume.integrate(last, cam, T_last).isOk());
    }
    const RaycastResult full = raycast(volume, cam, T_last);
    int hits = 0;
    for (float d : full.depth.pixels()) hits += d > 0.0f;
    ASSERT_GT(hits, cam.width * cam.height * 9 / 10);

    // The same surface to well under a millimetre (the samples bracketing a crossing differ, so
    // does the secant step on a curved field), except at a few silhouette pixels where the model
    // keeps a rim of the ball that the last view saw as wall.
    const int max_differ = cam.width * cam.height / 1000;
    const RaycastResult hinted = raycast(volume, cam, T_last, {}, &last);
    EXPECT_LE(raycastDifferences(full, hinted, 1e-3f), max_differ);
    int compared = 0, normals_off = 0;
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            if (full.depth(u, v) > 0.0f &&
                std::abs(full.depth(u, v) - hinted.depth(u, v)) < 1e-3f) {
                ++compared;
                normals_off += full.normals_V(u, v).dot(hinted.normals_V(u, v)) < 0.99f;
            }
        }
    }
    EXPECT_GT(compared, hits - max_differ);
    EXPECT_LE(normals_off, max_differ);
    // A half-resolution raycast starts from the nearest of the 2x2 hint pixels under each ray.
    const PinholeCamera half = cam.scaled(0.5);
    EXPECT_LE(raycastDifferences(raycast(volume, half, T_last),
                                 raycast(volume, half, T_last, {}, &last), 1e-3f),
              max_differ / 4);
    // A hint behind every surface: no ray starts in observed free space, every ray marches in
    // full.
    DepthImage behind = last;
    for (float& d : behind.pixels()) d = d > 0.0f ? d + 0.3f : 0.0f;
    EXPECT_EQ(raycastDifferences(full, raycast(volume, cam, T_last, {}, &behind), 0.0f), 0);
    // Small holes in the hint (dropouts, one pixel in five and a 2-pixel-wide seam): those rays
    // start from the nearest hinted depth around them and find the same surface.
    DepthImage holed = last;
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            if ((u + 3 * v) % 5 == 0 || u == cam.width / 3 || u == cam.width / 3 + 1) {
                holed(u, v) = 0.0f;
            }
        }
    }
    EXPECT_LE(raycastDifferences(full, raycast(volume, cam, T_last, {}, &holed), 1e-3f),
              max_differ);
    // Nothing hinted anywhere around a ray: it is not cast, unless hint_hole_radius_px < 0 says
    // to march such rays in full.
    const DepthImage empty(cam.width, cam.height, 0.0f);
    const RaycastResult unhinted = raycast(volume, cam, T_last, {}, &empty);
    EXPECT_EQ(std::count_if(unhinted.depth.pixels().begin(), unhinted.depth.pixels().end(),
                            [](float d) { return d > 0.0f; }),
              0);
    RaycastConfig march_holes;
    march_holes.hint_hole_radius_px = -1;
    EXPECT_EQ(raycastDifferences(full, raycast(volume, cam, T_last, march_holes, &empty), 0.0f), 0);
    // A hint beyond the end of every march: those rays march in full, unless
    // skip_hints_beyond_end says not to cast them; hints within range are not affected by it.
    DepthImage beyond = last;
    for (float& d : beyond.pixels()) d = d > 0.0f ? d + 10.0f : 0.0f;
    EXPECT_EQ(raycastDifferences(full, raycast(volume, cam, T_last, {}, &beyond), 0.0f), 0);
    RaycastConfig skip_beyond;
    skip_beyond.skip_hints_beyond_end = true;
    const RaycastResult skipped = raycast(volume, cam, T_last, skip_beyond, &beyond);
    EXPECT_EQ(std::count_if(skipped.depth.pixels().begin(), skipped.depth.pixels().end(),
                            [](float d) { return d > 0.0f; }),
              0);
    EXPECT_EQ(raycastDifferences(hinted, raycast(volume, cam, T_last, skip_beyond, &last), 0.0f),
              0);
    // Without the near start every hinted ray marches from one truncation in front: the same
    // surface.
    RaycastConfig far_start;
    far_start.hint_near_voxels = 0.0f;
    EXPECT_LE(raycastDifferences(hinted, raycast(volume, cam, T_last, far_start, &last), 1e-3f),
              max_differ);
}

/// Directed-edge bookkeeping of a triangle mesh.
struct MeshTopology {
    size_t duplicated = 0;  ///< directed edges used twice (inconsistent winding or non-manifold)
    size_t open = 0;        ///< directed edges without their reverse (holes)
    long euler = 0;         ///< V - E + F over referenced vertices
};
MeshTopology topology(const TriangleMesh& mesh) {
    std::map<std::pair<int, int>, int> directed;
    for (const auto& t : mesh.triangles) {
        for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
    }
    MeshTopology m;
    for (const auto& [e, count] : directed) {
        if (count != 1) ++m.duplicated;
        if (directed.find({e.second, e.first}) == directed.end()) ++m.open;
    }
    std::vector<bool> used(mesh.vertices.size(), false);
    for (const auto& t : mesh.triangles) used[t[0]] = used[t[1]] = used[t[2]] = true;
    const long num_v = std::count(used.begin(), used.end(), true);
    m.euler =
        num_v - static_cast<long>(directed.size() / 2) + static_cast<long>(mesh.triangles.size());
    return m;
}

size_t countOutward(const TriangleMesh& mesh, const Eigen::Vector3d& centre) {
    size_t outward = 0;
    for (const auto& t : mesh.triangles) {
        const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(),
                              b = mesh.vertices[t[1]].cast<double>(),
                              c = mesh.vertices[t[2]].cast<double>();
        if ((b - a).cross(c - a).dot((a + b + c) / 3.0 - centre) > 0.0) ++outward;
    }
    return outward;
}

TEST(TsdfVolume, MarchingCubesOfAnalyticSphereIsClosedAcrossBlockBorders) {
    // An exact signed distance field written into every voxel of the blocks around a sphere whose
    // centre is off the grid, so the surface crosses many block borders and every cube case occurs.
    TsdfVolume volume(testConfig());
    const Sphere sphere{Eigen::Vector3d(0.0131, -0.0217, 0.0071), 0.17};
    const float vs = volume.voxelSize(), mu = volume.config().truncation_m;
    for (int z = -4; z < 4; ++z) {
        for (int y = -4; y < 4; ++y) {
            for (int x = -4; x < 4; ++x) {
                const BlockKey key(x, y, z);
                const int32_t b = volume.allocateBlock(key);
                ASSERT_GE(b, 0);
                Voxel* voxels = volume.blockVoxels(b);
                for (int i = 0; i < kBlockVoxels; ++i) {
                    const Eigen::Vector3i g =
                        key * kBlockSide + Eigen::Vector3i(i & 7, (i >> 3) & 7, i >> 6);
                    const double sdf = (g.cast<double>() * vs - sphere.c).norm() - sphere.r;
                    voxels[i].tsdf = static_cast<float>(std::clamp(sdf / mu, -1.0, 1.0));
                    voxels[i].weight = 5.0f;
                }
            }
        }
    }
    const TriangleMesh mesh = extractMesh(volume);
    ASSERT_GT(mesh.triangles.size(), 5000u);
    const MeshTopology topo = topology(mesh);
    EXPECT_EQ(topo.duplicated, 0u);
    EXPECT_EQ(topo.open, 0u);
    EXPECT_EQ(topo.euler, 2);
    EXPECT_EQ(countOutward(mesh, sphere.c), mesh.triangles.size());
    double mean = 0.0;
    for (const auto& p : mesh.vertices)
        mean += std::abs((p.cast<double>() - sphere.c).norm() - sphere.r);
    EXPECT_LT(mean / mesh.vertices.size(), 0.05 * vs);
    // The mesh vertices are the surface points.
    EXPECT_EQ(extractSurfacePoints(volume).points, mesh.vertices);
}

TEST(TsdfVolume, MeshOfIntegratedSphereFacesOutward) {
    const PinholeCamera cam = smallCamera();
    const Sphere sphere{Eigen::Vector3d(0.013, -0.021, 0.007), 0.25};
    TsdfVolume volume(testConfig());
    const Eigen::Vector3d dirs[] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                    {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
    for (const auto& d : dirs) {
        const Eigen::Isometry3d T_W_C = lookAt(sphere.c + 1.0 * d.normalized(), sphere.c);
        for (int rep = 0; rep < 2; ++rep) {
            ASSERT_TRUE(
                volume
                    .integrate(
                        render(cam, T_W_C, [&](auto o, auto r) { return hitSphere(sphere, o, r); }),
                        cam, T_W_C)
                    .isOk());
        }
    }
    const TriangleMesh mesh = extractMesh(volume);
    ASSERT_GT(mesh.triangles.size(), 1000u);
    EXPECT_EQ(topology(mesh).duplicated, 0u);
    EXPECT_GT(countOutward(mesh, sphere.c), 99 * mesh.triangles.size() / 100);
    double mean = 0.0;
    for (const auto& p : mesh.vertices)
        mean += std::abs((p.cast<double>() - sphere.c).norm() - sphere.r);
    EXPECT_LT(mean / mesh.vertices.size(), 0.25 * volume.voxelSize());
}

TEST(TsdfVolume, BlockBudgetRefusesFrameAndLeavesVolumeUnchanged) {
    const PinholeCamera cam = smallCamera();
    const Plane plane{Eigen::Vector3d(0, 0, -1), 1.5};
    TsdfConfig config = testConfig();
    const Eigen::Isometry3d T_W_C = Eigen::Isometry3d::Identity();
    const DepthImage depth =
        render(cam, T_W_C, [&](auto o, auto r) { return hitPlane(plane, o, r); });
    TsdfVolume unlimited(config);
    const size_t needed = unlimited.countNewBlocks(depth, cam, T_W_C);
    ASSERT_GT(needed, 10u);
    ASSERT_EQ(unlimited.integrate(depth, cam, T_W_C).value().blocks_allocated, needed);
    config.max_blocks = needed - 1;
    TsdfVolume limited(config);
    const auto refused = limited.integrate(depth, cam, T_W_C);
    ASSERT_FALSE(refused.isOk());
    EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_EQ(limited.numBlocks(), 0u);
    config.max_blocks = needed;
    TsdfVolume exact(config);
    EXPECT_TRUE(exact.integrate(depth, cam, T_W_C).isOk());
    EXPECT_EQ(exact.numBlocks(), needed);
}

TEST(TsdfVolume, EveryVoxelFollowsTheProjectiveUpdate) {
    // One frame into an empty volume: every voxel of every block is either untouched (tsdf 1,
    // weight 0) or holds min(1, (D(u) - z) / mu) with weight 1, computed here voxel by voxel
    // (scalar, double) from its centre's projection. The same frame again doubles the weights
    // and keeps the values; with max_weight 1 the weights stay 1.
    const PinholeCamera cam = smallCamera();
    const Sphere ball{Eigen::Vector3d(0.05, -0.03, 1.0), 0.25};
    const Plane wall{Eigen::Vector3d(0.1, 0.1, -1.0).normalized(), 1.6};
    const Eigen::Isometry3d T_W_C = jitter(4);
    const DepthImage depth = render(cam, T_W_C, [&](auto o, auto r) {
        std::optional<double> t = hitPlane(wall, o, r);
        const std::optional<double> ts = hitSphere(ball, o, r);
        if (ts && (!t || *ts < *t)) t = ts;
        return t;
    });
    for (const float max_weight : {128.0f, 1.0f}) {
        TsdfConfig config = testConfig();
        config.max_weight = max_weight;
        TsdfVolume volume(config);
        for (int pass = 1; pass <= 2; ++pass) {
            ASSERT_TRUE(volume.integrate(depth, cam, T_W_C).isOk());
            const float weight = std::min(static_cast<float>(pass), max_weight);
            const Eigen::Isometry3d T_C_W = T_W_C.inverse();
            const double mu = config.truncation_m;
            int updated = 0, mismatched = 0;
            for (size_t b = 0; b < volume.numBlocks(); ++b) {
                const BlockKey key = volume.blockKeys()[b];
                const Voxel* voxels = volume.blockVoxels(static_cast<int32_t>(b));
                for (int i = 0; i < kBlockVoxels; ++i) {
                    const Eigen::Vector3i g =
                        key * kBlockSide + Eigen::Vector3i(i % 8, (i / 8) % 8, i / 64);
                    const Eigen::Vector3d p = T_C_W * (g.cast<double>() * config.voxel_size_m);
                    bool expect_update = false;
                    double expect_f = 1.0;
                    if (p.z() > 0.0) {
                        const int u =
                            static_cast<int>(std::floor(cam.fx * p.x() / p.z() + cam.cx + 0.5));
                        const int v =
                            static_cast<int>(std::floor(cam.fy * p.y() / p.z() + cam.cy + 0.5));
                        if (u >= 0 && v >= 0 && u < cam.width && v < cam.height) {
                            const double d = depth(u, v);
                            const double sdf = d - p.z();
                            if (d >= config.min_depth_m && d <= config.max_depth_m && sdf >= -mu) {
                                expect_update = true;
                                expect_f = std::min(1.0, sdf / mu);
                            }
                        }
                    }
                    const Voxel& vx = voxels[i];
                    const bool ok = expect_update
                                        ? vx.weight == weight && std::abs(vx.tsdf - expect_f) < 1e-4
                                        : vx.weight == 0.0f && vx.tsdf == 1.0f;
                    updated += expect_update;
                    mismatched += !ok;
                }
            }
            EXPECT_GT(updated, 10000) << "pass " << pass;
            // Projections that land within float rounding of a pixel border may pick the other
            // pixel: a handful at most.
            EXPECT_LE(mismatched, updated / 2000)
                << "pass " << pass << ", max_weight " << max_weight;
        }
    }
}

TEST(TsdfVolume, ResultsDoNotDependOnThreadCount) {
    const PinholeCamera cam = smallCamera();
    const Sphere sphere{Eigen::Vector3d(0.0, 0.0, 1.0), 0.3};
    std::vector<std::vector<float>> voxels;
    std::vector<size_t> surface_sizes;
    for (int threads : {1, 2, 3}) {
        TsdfConfig config = testConfig();
        config.num_threads = threads;
        TsdfVolume volume(config);
        for (int k = 0; k < 3; ++k) {
            const Eigen::Isometry3d T_W_C = jitter(k);
            ASSERT_TRUE(
                volume
                    .integrate(
                        render(cam, T_W_C, [&](auto o, auto r) { return hitSphere(sphere, o, r); }),
                        cam, T_W_C)
                    .isOk());
        }
        std::vector<float> all;
        for (size_t b = 0; b < volume.numBlocks(); ++b) {
            const Voxel* v = volume.blockVoxels(static_cast<int32_t>(b));
            for (int i = 0; i < kBlockVoxels; ++i) {
                all.push_back(v[i].tsdf);
                all.push_back(v[i].weight);
            }
        }
        voxels.push_back(std::move(all));
        SurfaceConfig sc;
        sc.num_threads = threads;
        surface_sizes.push_back(extractSurfacePoints(volume, sc).size());
    }
    EXPECT_EQ(voxels[0], voxels[1]);
    EXPECT_EQ(voxels[0], voxels[2]);
    EXPECT_EQ(surface_sizes[0], surface_sizes[1]);
    EXPECT_EQ(surface_sizes[0], surface_sizes[2]);
}

TEST(TsdfVolume, TheAvx2KernelFusesTheSameVoxelsAndColoursAsThePortableOne) {
    // A noisy sphere in front of a plane, random colours, weights that saturate (max_weight 3
    // over 6 frames): every branch of the update. Where the CPU has no AVX2 both volumes run the
    // portable kernel and the comparison holds trivially.
    const PinholeCamera cam = smallCamera();
    const Sphere sphere{Eigen::Vector3d(0.05, 0.0, 0.9), 0.25};
    const Plane plane{Eigen::Vector3d(0, 0, -1), 1.3};
    TsdfConfig config = testConfig();
    config.max_weight = 3.0f;
    TsdfVolume wide(config), portable(config);
    std::mt19937 rng(7);
    std::normal_distribution<float> noise(0.0f, 0.004f);
    std::uniform_int_distribution<int> level(0, 255);
    for (int k = 0; k < 6; ++k) {
        const Eigen::Isometry3d T_W_C = jitter(k);
        DepthImage depth = render(cam, T_W_C, [&](auto o, auto r) {
            const std::optional<double> s = hitSphere(sphere, o, r);
            return s ? s : hitPlane(plane, o, r);
        });
        ColourImage colour(cam.width, cam.height);
        for (int v = 0; v < cam.height; ++v) {
            for (int u = 0; u < cam.width; ++u) {
                if (depth(u, v) > 0.0f) depth(u, v) += noise(rng);
                colour(u, v) = {static_cast<uint8_t>(level(rng)), static_cast<uint8_t>(level(rng)),
                                static_cast<uint8_t>(level(rng))};
            }
        }
        ASSERT_TRUE(wide.integrate(depth, cam, T_W_C, &colour).isOk());
        const simd::ScopedLevel scalar(simd::Level::kPortable);
        ASSERT_TRUE(portable.integrate(depth, cam, T_W_C, &colour).isOk());
    }
    ASSERT_EQ(wide.numBlocks(), portable.numBlocks());
    size_t observed = 0, saturated = 0, coloured = 0;
    for (size_t b = 0; b < wide.numBlocks(); ++b) {
        const auto index = static_cast<int32_t>(b);
        const Voxel* a = wide.blockVoxels(index);
        const Voxel* p = portable.blockVoxels(index);
        const VoxelColour* ca = wide.blockColours(index);
        const VoxelColour* cp = portable.blockColours(index);
        for (int i = 0; i < kBlockVoxels; ++i) {
            ASSERT_EQ(a[i].tsdf, p[i].tsdf) << "block " << b << " voxel " << i;
            ASSERT_EQ(a[i].weight, p[i].weight) << "block " << b << " voxel " << i;
            ASSERT_EQ(std::memcmp(&ca[i], &cp[i], sizeof(VoxelColour)), 0)
                << "block " << b << " voxel " << i;
            observed += a[i].weight > 0.0f ? 1 : 0;
            saturated += a[i].weight == config.max_weight ? 1 : 0;
            coloured += ca[i].weight > 0 ? 1 : 0;
        }
    }
    EXPECT_GT(observed, 10000u);
    EXPECT_GT(saturated, 1000u);
    EXPECT_GT(coloured, 1000u);
}

TEST(TsdfVolume, RejectsMismatchedImageAndBadPose) {
    TsdfVolume volume(testConfig());
    const PinholeCamera cam = smallCamera();
    EXPECT_EQ(volume.integrate(DepthImage(10, 10, 1.0f), cam, Eigen::Isometry3d::Identity())
                  .status()
                  .code(),
              StatusCode::kInvalidArgument);
    Eigen::Isometry3d bad = Eigen::Isometry3d::Identity();
    bad.translation().x() = std::nan("");
    EXPECT_EQ(volume.integrate(DepthImage(cam.width, cam.height, 1.0f), cam, bad).status().code(),
              StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace plumb::tsdf
