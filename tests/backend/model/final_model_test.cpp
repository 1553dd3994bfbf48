// SPDX-License-Identifier: Apache-2.0
// The final model's volumes, one per variant, are integrated side by side: each variant's mesh
// must be the one it has alone, whatever the thread count, from raw frames or fragment surfaces.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <vector>

#include "backend/model/final_model.hpp"
#include "common/frame/frame_recorder.hpp"
#include "tests/backend/global/sim_fragments.hpp"

namespace plumb::backend {
namespace {

PinholeCamera smallCamera() {
    PinholeCamera camera;
    camera.width = 160;
    camera.height = 120;
    camera.fx = camera.fy = 131.25;  // 640x480 at fx 525, a quarter
    camera.cx = 79.5;
    camera.cy = 59.5;
    return camera;
}

struct Scan {
    testing::SimFragments sim;
    std::vector<std::vector<Eigen::Isometry3d>> variants;  // ground truth, then perturbed
    std::shared_ptr<std::vector<Frame>> frames;  // every fragment frame, its surface rendered
};

Scan makeScan() {
    testing::SimFragmentsOptions options;
    options.num_fragments = 4;
    options.frames_per_fragment = 6;
    options.views_per_fragment = 3;
    Scan scan{testing::makeSimFragments(options), {}, std::make_shared<std::vector<Frame>>()};
    scan.variants.push_back(scan.sim.T_W_F_gt);
    std::vector<Eigen::Isometry3d> moved = scan.sim.T_W_F_gt;
    for (size_t i = 1; i < moved.size(); ++i)
        moved[i] = testing::randomPerturbation(1.0, 0.03, 100 + i) * moved[i];
    scan.variants.push_back(moved);
    for (const Fragment& fragment : scan.sim.fragments) {
        for (const FragmentFrame& f : fragment.frames) {
            Frame frame;
            frame.index = f.frame_index;
            frame.timestamp_s = f.timestamp_s;
            frame.depth = renderPointsToDepth(fragment.points_F, smallCamera(), f.T_F_C, 1);
            scan.frames->push_back(std::move(frame));
        }
    }
    return scan;
}

const Scan& scan() {
    static const Scan s = makeScan();
    return s;
}

std::vector<FinalModel> fromFrames(const std::vector<std::vector<Eigen::Isometry3d>>& variants,
                                   int threads) {
    FinalModelConfig config;
    config.num_threads = threads;
    ReplaySource source(scan().frames, smallCamera(), "rendered fragment frames");
    Result<std::vector<FinalModel>> models =
        integrateRawFrames(source, scan().sim.fragments, variants, config);
    EXPECT_TRUE(models.isOk()) << models.status().toString();
    return models.isOk() ? std::move(*models) : std::vector<FinalModel>{};
}

std::vector<FinalModel> fromSurfaces(const std::vector<std::vector<Eigen::Isometry3d>>& variants,
                                     int threads) {
    FinalModelConfig config;
    config.num_threads = threads;
    Result<std::vector<FinalModel>> models =
        fuseFragmentSurfaces(scan().sim.fragments, variants, smallCamera(), config);
    EXPECT_TRUE(models.isOk()) << models.status().toString();
    return models.isOk() ? std::move(*models) : std::vector<FinalModel>{};
}

void expectSameMesh(const FinalModel& a, const FinalModel& b) {
    EXPECT_EQ(a.blocks, b.blocks);
    EXPECT_EQ(a.frames_integrated, b.frames_integrated);
    EXPECT_EQ(a.mesh.vertices, b.mesh.vertices);
    EXPECT_EQ(a.mesh.triangles, b.mesh.triangles);
}

using Builder = std::vector<FinalModel> (*)(const std::vector<std::vector<Eigen::Isometry3d>>&,
                                            int);

void checkSideBySide(Builder build) {
    const std::vector<FinalModel> both = build(scan().variants, 0);
    ASSERT_EQ(both.size(), 2u);
    ASSERT_GT(both[0].mesh.vertices.size(), 1000u);
    // The perturbed poses give another model: the check below can tell the variants apart.
    EXPECT_NE(both[0].mesh.vertices, both[1].mesh.vertices);
    for (size_t v = 0; v < 2; ++v) {
        const std::vector<FinalModel> alone = build({scan().variants[v]}, 0);
        ASSERT_EQ(alone.size(), 1u);
        expectSameMesh(both[v], alone[0]);
    }
    for (int threads : {1, 2}) {
        const std::vector<FinalModel> again = build(scan().variants, threads);
        ASSERT_EQ(again.size(), 2u);
        for (size_t v = 0; v < 2; ++v) expectSameMesh(both[v], again[v]);
    }
    {
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        const std::vector<FinalModel> serial = build(scan().variants, 0);
        ASSERT_EQ(serial.size(), 2u);
        for (size_t v = 0; v < 2; ++v) expectSameMesh(both[v], serial[v]);
    }
}

TEST(FinalModel, RawFramesGiveEachVariantItsOwnModelWhateverTheThreads) {
    checkSideBySide(&fromFrames);
    const std::vector<FinalModel> models = fromFrames(scan().variants, 0);
    ASSERT_EQ(models.size(), 2u);
    EXPECT_TRUE(models[0].from_raw_frames);
    EXPECT_EQ(models[0].frames_integrated, scan().frames->size());
}

TEST(FinalModel, FragmentSurfacesGiveEachVariantItsOwnModelWhateverTheThreads) {
    checkSideBySide(&fromSurfaces);
    const std::vector<FinalModel> models = fromSurfaces(scan().variants, 0);
    ASSERT_EQ(models.size(), 2u);
    EXPECT_FALSE(models[0].from_raw_frames);
}

TEST(FinalModel, ARenderedSlantedPlaneLiesOnThePlane) {
    // A wall 2 m ahead turned 60 degrees about the vertical, sampled every 6 mm (the device's
    // voxel) with its normal: every rendered pixel's depth is where that pixel's ray meets the
    // wall, to within a millimetre, though a splat spans 3 pixels (about 9 cm of wall along the
    // slant at that distance, for this quarter-VGA camera; flat splats stand out by centimetres).
    const PinholeCamera camera = smallCamera();
    const double angle = 60.0 * std::numbers::pi / 180.0;
    const Eigen::Vector3d normal(-std::sin(angle), 0.0, -std::cos(angle));  // faces the camera
    const Eigen::Vector3d centre(0.0, 0.0, 2.0);
    const Eigen::Vector3d along(std::cos(angle), 0.0, -std::sin(angle));
    PointCloud wall;
    for (double s = -0.8; s <= 0.8; s += 0.006)
        for (double y = -0.5; y <= 0.5; y += 0.006) {
            wall.points.push_back((centre + s * along + Eigen::Vector3d(0, y, 0)).cast<float>());
            wall.normals.push_back(normal.cast<float>());
        }
    const DepthImage depth = renderPointsToDepth(wall, camera, Eigen::Isometry3d::Identity(), 1);
    size_t rendered = 0;
    double worst = 0.0;
    for (int v = 0; v < camera.height; ++v)
        for (int u = 0; u < camera.width; ++u) {
            if (depth(u, v) == 0.0f) continue;
            const Eigen::Vector3d ray = camera.ray(u, v);
            const double truth = normal.dot(centre) / normal.dot(ray);
            worst = std::max(worst, std::abs(depth(u, v) - truth));
            ++rendered;
        }
    EXPECT_GT(rendered, static_cast<size_t>(camera.width * camera.height / 4));
    EXPECT_LT(worst, 0.001);  // first order over the splat: this camera's pixels are 4x a VGA one's
    // Without normals the splats are flat: the same wall renders over 5 mm off.
    PointCloud bare;
    bare.points = wall.points;
    const DepthImage flat = renderPointsToDepth(bare, camera, Eigen::Isometry3d::Identity(), 1);
    double flat_worst = 0.0;
    for (int v = 0; v < camera.height; ++v)
        for (int u = 0; u < camera.width; ++u)
            if (flat(u, v) > 0.0f)
                flat_worst = std::max(
                    flat_worst,
                    std::abs(flat(u, v) - normal.dot(centre) / normal.dot(camera.ray(u, v))));
    EXPECT_GT(flat_worst, 0.005) << worst;
}

TEST(FinalModel, EveryKthViewOfEachFragmentIsFused) {
    for (int stride : {1, 2, 4}) {
        FinalModelConfig config;
        config.surface_frame_stride = stride;
        size_t expected = 0;
        for (const Fragment& f : scan().sim.fragments)
            expected +=
                (f.frames.size() + static_cast<size_t>(stride) - 1) / static_cast<size_t>(stride);
        Result<std::vector<FinalModel>> models =
            fuseFragmentSurfaces(scan().sim.fragments, {scan().variants[0]}, smallCamera(), config);
        ASSERT_TRUE(models.isOk());
        EXPECT_EQ((*models)[0].frames_integrated, expected) << "stride " << stride;
    }
    FinalModelConfig bad;
    bad.surface_frame_stride = 0;
    EXPECT_EQ(fuseFragmentSurfaces(scan().sim.fragments, {scan().variants[0]}, smallCamera(), bad)
                  .status()
                  .code(),
              StatusCode::kInvalidArgument);
}

/// A smooth colour of the world point p, so that a vertex's expected colour is known wherever it
/// lies: about 3 units of change a centimetre at most.
Color3u8 worldColour(const Eigen::Vector3f& p) {
    auto channel = [](float x) {
        return static_cast<uint8_t>(std::lround(128.0f + 100.0f * std::sin(3.0f * x)));
    };
    return Color3u8(channel(p.x()), channel(p.y()), channel(p.z()));
}

int largestChannelError(const Color3u8& a, const Color3u8& b) {
    int e = 0;
    for (int c = 0; c < 3; ++c) e = std::max(e, std::abs(int{a[c]} - int{b[c]}));
    return e;
}

TEST(FinalModel, RawDepthWithoutColourTakesTheColourOfTheFragmentPoints) {
    // The fragments carry the colour of the world where their points lie (ground-truth poses);
    // the raw frames carry depth only, as a device streaming stream.raw_frame_colour = false.
    std::vector<Fragment> fragments = scan().sim.fragments;
    for (size_t i = 0; i < fragments.size(); ++i) {
        PointCloud& cloud = fragments[i].points_F;
        cloud.colors.clear();
        for (const Eigen::Vector3f& p : cloud.points)
            cloud.colors.push_back(worldColour(scan().sim.T_W_F_gt[i].cast<float>() * p));
    }
    auto build = [&](int threads, double radius) {
        FinalModelConfig config;
        config.num_threads = threads;
        config.fragment_colour_radius_m = radius;
        ReplaySource source(scan().frames, smallCamera(), "depth-only frames");
        Result<std::vector<FinalModel>> models =
            integrateRawFrames(source, fragments, scan().variants, config);
        EXPECT_TRUE(models.isOk()) << models.status().toString();
        return models.isOk() ? std::move(*models) : std::vector<FinalModel>{};
    };
    const std::vector<FinalModel> models = build(0, 0.03);
    ASSERT_EQ(models.size(), 2u);
    for (const FinalModel& m : models) {
        EXPECT_TRUE(m.from_raw_frames);
        EXPECT_TRUE(m.colour_from_fragments);
        ASSERT_EQ(m.mesh.colors.size(), m.mesh.vertices.size());
    }
    // At the true poses every vertex has the colour of the world where it lies, to within the
    // change over the distance to the nearest point.
    const TriangleMesh& mesh = models[0].mesh;
    ASSERT_GT(mesh.vertices.size(), 1000u);
    std::vector<int> errors;
    for (size_t v = 0; v < mesh.vertices.size(); ++v)
        errors.push_back(largestChannelError(mesh.colors[v], worldColour(mesh.vertices[v])));
    std::sort(errors.begin(), errors.end());
    EXPECT_LE(errors[errors.size() / 2], 3);
    EXPECT_LE(errors[errors.size() * 99 / 100], 10);
    // The perturbed poses carry their fragments' points with them: another colouring.
    EXPECT_NE(models[1].mesh.colors,
              std::vector<Color3u8>(models[1].mesh.vertices.size(), Color3u8(128, 128, 128)));
    // Whatever the thread count, the same colours.
    for (int threads : {1, 2}) {
        const std::vector<FinalModel> again = build(threads, 0.03);
        ASSERT_EQ(again.size(), 2u);
        for (size_t v = 0; v < 2; ++v) EXPECT_EQ(again[v].mesh.colors, models[v].mesh.colors);
    }
    // A radius of 0 leaves the mesh uncoloured; so do fragments without colour.
    for (const FinalModel& m : build(0, 0.0)) {
        EXPECT_FALSE(m.colour_from_fragments);
        EXPECT_TRUE(m.mesh.colors.empty());
    }
    for (const FinalModel& m : fromFrames(scan().variants, 0)) {
        EXPECT_FALSE(m.colour_from_fragments);
        EXPECT_TRUE(m.mesh.colors.empty());
    }
}

TEST(FinalModel, AVertexFarFromEveryFragmentPointIsMidGrey) {
    std::vector<Fragment> fragments = scan().sim.fragments;
    for (Fragment& f : fragments)
        f.points_F.colors.assign(f.points_F.points.size(), Color3u8(200, 10, 20));
    TriangleMesh mesh;
    const Eigen::Vector3f on =
        scan().sim.T_W_F_gt[0].cast<float>() * fragments[0].points_F.points[0];
    mesh.vertices = {on, on + Eigen::Vector3f(0.0f, 0.0f, 0.02f),
                     on + Eigen::Vector3f(50.0f, 0.0f, 0.0f)};
    colourFromFragmentPoints(fragments, scan().sim.T_W_F_gt, 0.03, 0, &mesh);
    ASSERT_EQ(mesh.colors.size(), 3u);
    EXPECT_EQ(mesh.colors[0], Color3u8(200, 10, 20));
    EXPECT_EQ(mesh.colors[1], Color3u8(200, 10, 20));
    EXPECT_EQ(mesh.colors[2], Color3u8(128, 128, 128));
    // Fragments without colour leave the mesh as it is.
    TriangleMesh plain;
    plain.vertices = {on};
    colourFromFragmentPoints(scan().sim.fragments, scan().sim.T_W_F_gt, 0.03, 0, &plain);
    EXPECT_TRUE(plain.colors.empty());
}

}  // namespace
}  // namespace plumb::backend
