// SPDX-License-Identifier: Apache-2.0
// Preprocessing on analytic depth: the masked bilateral filter, the pyramid and the normal maps.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

#include "device/preprocess/preprocess.hpp"
#include "tests/device/room_scene.hpp"

namespace plumb::device {
namespace {

PinholeCamera smallCamera() { return cameraPreset("ci").value(); }

double rmsError(const DepthImage& a, const DepthImage& truth, int* count) {
    double s = 0.0;
    *count = 0;
    for (int v = 4; v < a.height() - 4; ++v) {
        for (int u = 4; u < a.width() - 4; ++u) {
            if (a(u, v) <= 0.0f || truth(u, v) <= 0.0f) continue;
            s += std::pow(a(u, v) - truth(u, v), 2);
            ++*count;
        }
    }
    return std::sqrt(s / std::max(1, *count));
}

TEST(Preprocess, BilateralFilterReducesNoiseOnAPlane) {
    const PinholeCamera cam = cameraPreset("primesense").value().scaled(0.5);  // 320x240
    testing::Scene scene;
    scene.planes = {{Eigen::Vector3d(0.2, -0.1, -1.0).normalized(), 2.0}};
    const DepthImage truth = scene.render(cam, Eigen::Isometry3d::Identity());
    const DepthImage noisy = scene.render(cam, Eigen::Isometry3d::Identity(), 7);
    PreprocessConfig config;
    const DepthImage filtered = bilateralFilter(noisy, config);
    int n_noisy = 0, n_filtered = 0;
    const double before = rmsError(noisy, truth, &n_noisy);
    const double after = rmsError(filtered, truth, &n_filtered);
    EXPECT_EQ(n_noisy, n_filtered);
    EXPECT_LT(after, 0.5 * before) << "before " << before << " after " << after;
}

TEST(Preprocess, MaskedFilterNeverMixesInInvalidPixelsOrOtherSurfaces) {
    const PinholeCamera cam = smallCamera();
    DepthImage depth(cam.width, cam.height, 0.0f);
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            if (u < 50) continue;                 // invalid strip
            depth(u, v) = u < 100 ? 1.0f : 2.0f;  // a 1 m step
        }
    }
    const DepthImage f = bilateralFilter(depth, PreprocessConfig{});
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            ASSERT_FLOAT_EQ(f(u, v), depth(u, v)) << u << "," << v;
        }
    }
    const DepthImage half = downsampleDepth(depth, 0.03f);
    EXPECT_EQ(half.width(), cam.width / 2);
    for (float d : half.pixels()) EXPECT_TRUE(d == 0.0f || d == 1.0f || d == 2.0f) << d;
}

TEST(Preprocess, BilateralFilterMatchesItsDefinitionInsideAndAtTheBorder) {
    // Noisy depth with holes and a 4 cm step (within 3 sigma_r, so both sides mix): every pixel,
    // interior or within the radius of the border, against the filter written out with exp().
    const PinholeCamera cam = smallCamera();
    testing::Scene scene;
    scene.planes = {{Eigen::Vector3d(0.1, 0.2, -1.0).normalized(), 1.5}};
    DepthImage depth = scene.render(cam, Eigen::Isometry3d::Identity(), 3);
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            if ((u * 7 + v * 13) % 11 == 0) depth(u, v) = 0.0f;  // holes
            if (u > cam.width / 2 && depth(u, v) > 0.0f) depth(u, v) += 0.04f;
        }
    }
    const PreprocessConfig config;
    const DepthImage f = bilateralFilter(depth, config);
    const int r = config.bilateral_radius_px;
    const double sigma_s = config.bilateral_sigma_space_px * cam.width / 640.0;
    const double sigma_r = config.bilateral_sigma_depth_m;
    double max_err = 0.0;
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            const double dc = depth(u, v);
            if (dc <= 0.0) {
                ASSERT_EQ(f(u, v), 0.0f);
                continue;
            }
            double sum = 0.0, wsum = 0.0;
            for (int y = std::max(0, v - r); y <= std::min(cam.height - 1, v + r); ++y) {
                for (int x = std::max(0, u - r); x <= std::min(cam.width - 1, u + r); ++x) {
                    const double d = depth(x, y), diff = d - dc;
                    if (d <= 0.0 || std::abs(diff) > 3.0 * sigma_r) continue;
                    const double wt = std::exp(-((x - u) * (x - u) + (y - v) * (y - v)) /
                                                   (2 * sigma_s * sigma_s) -
                                               diff * diff / (2 * sigma_r * sigma_r));
                    sum += wt * d;
                    wsum += wt;
                }
            }
            max_err = std::max(max_err, std::abs(f(u, v) - sum / wsum));
        }
    }
    EXPECT_LT(max_err, 2e-4);  // the tabulated range kernel: 256 bins over 3 sigma_r
}

TEST(Preprocess, BilateralFilterKernelsAgreeBitForBit) {
    // The AVX2 kernel does per pixel what the portable loop does, in the same order: the images
    // must be identical, for widths that are and are not multiples of 8 lanes, several radii,
    // holes, whole runs of holes, depth steps within and beyond 3 sigma_r, and neighbours exactly
    // 3 sigma_r away.
    if (simd::best() != simd::Level::kAvx2) GTEST_SKIP() << "this CPU has no AVX2";
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> noise(-0.02f, 0.02f);
    std::uniform_int_distribution<int> pick(0, 99);
    for (const int width : {160, 317, 640}) {
        const int height = width * 3 / 4;
        DepthImage depth(width, height, 0.0f);
        for (int v = 0; v < height; ++v) {
            for (int u = 0; u < width; ++u) {
                float d = 1.2f + 0.002f * static_cast<float>(u) + noise(rng);
                if (u > width / 3) d += 0.05f;                         // a step within 3 sigma_r
                if (v > height / 2) d += 0.5f;                         // a step beyond it
                if ((u / 9 + v / 5) % 7 == 0 && u % 3 == 0) d = 0.0f;  // scattered holes
                if (v % 17 == 3 && u > 20 && u < 60) d = 0.0f;         // runs of holes
                if (pick(rng) == 0) d = 0.0f;
                depth(u, v) = d;
            }
        }
        depth(width / 2, height / 4) = depth(width / 2 + 1, height / 4) + 0.09f;  // 3 sigma_r
        for (const int radius : {1, 3, 5}) {
            PreprocessConfig config;
            config.bilateral_radius_px = radius;
            const DepthImage a = bilateralFilter(depth, config, simd::Level::kPortable);
            const DepthImage b = bilateralFilter(depth, config, simd::Level::kAvx2);
            size_t differing = 0, filtered = 0;
            for (int v = 0; v < height; ++v) {
                for (int u = 0; u < width; ++u) {
                    differing += std::memcmp(&a(u, v), &b(u, v), sizeof(float)) != 0 ? 1 : 0;
                    filtered += a(u, v) != depth(u, v) ? 1 : 0;
                }
            }
            EXPECT_EQ(differing, 0u) << width << " px, radius " << radius;
            EXPECT_GT(filtered, depth.size() / 2) << "the filter must do something";
        }
    }
}

TEST(Preprocess, PyramidNormalsMatchATiltedPlane) {
    const PinholeCamera cam = smallCamera();
    testing::Scene scene;
    const Eigen::Vector3d n(0.3, -0.2, -1.0);
    scene.planes = {{n.normalized(), 1.5}};
    const DepthImage depth = scene.render(cam, Eigen::Isometry3d::Identity());
    PreprocessConfig config;
    config.bilateral = false;  // exact geometry: the filter is tested above
    // By default a 160 px camera stops at 80 px (min_level_width_px); 1 keeps the 40 px level.
    Result<FramePyramid> two = preprocess(depth, cam, config);
    ASSERT_TRUE(two.isOk());
    ASSERT_EQ(two->levels.size(), 2u);
    EXPECT_EQ(two->levels[1].camera.width, 80);
    config.min_level_width_px = 1;
    Result<FramePyramid> pyr = preprocess(depth, cam, config);
    ASSERT_TRUE(pyr.isOk());
    ASSERT_EQ(pyr->levels.size(), 3u);
    EXPECT_EQ(pyr->levels[2].camera.width, 40);
    EXPECT_EQ(pyr->levels[2].depth.height(), 30);
    for (const PyramidLevel& level : pyr->levels) {
        int valid = 0;
        double angle = 0.0, offset = 0.0;
        for (int v = 0; v < level.depth.height(); ++v) {
            for (int u = 0; u < level.depth.width(); ++u) {
                const Eigen::Vector3f& nn = level.normals_C(u, v);
                if (!tsdf::isValid(nn)) continue;
                ++valid;
                angle += std::acos(std::min(1.0, nn.cast<double>().dot(n.normalized())));
                const Eigen::Vector3d p = level.points_C(u, v).cast<double>();
                offset += std::abs(n.normalized().dot(p) + 1.5);
            }
        }
        EXPECT_GT(valid, level.depth.width() * level.depth.height() * 8 / 10);
        // Level 0 is exact; coarser levels average depth (not 1/depth) over 2x2 pixels.
        EXPECT_LT(angle / valid, 0.2 * M_PI / 180.0);
        EXPECT_LT(offset / valid, 2e-4);
    }
    EXPECT_FALSE(preprocess(DepthImage(10, 10), cam, PreprocessConfig{}).isOk());
}

}  // namespace
}  // namespace plumb::device
