// SPDX-License-Identifier: Apache-2.0
// Depth-noise model of the simulated scanner (reference §1.4, §1.5).
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "common/camera/pinhole.hpp"
#include "drivers/dataset/depth_png.hpp"
#include "drivers/sim/noise.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::sim {
namespace {

constexpr double kBf = 35.130;

NoiseConfig pureConfig() {
    NoiseConfig c;
    c.distortion = DistortionKind::kNone;
    c.missing_data = false;
    c.min_depth_m = 0.0;
    c.max_depth_m = 0.0;
    return c;
}

double mean(const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return s / v.size();
}

double stddev(const std::vector<double>& v) {
    const double m = mean(v);
    double s = 0.0;
    for (double x : v) s += (x - m) * (x - m);
    return std::sqrt(s / (v.size() - 1));
}

TEST(SimNoise, NormalTableHasUnitVariance) {
    double s1 = 0.0, s2 = 0.0;
    const int n = 1 << 20;
    for (int i = 0; i < n; ++i) {
        const double x = standardNormalFromBits(static_cast<uint32_t>(mixSeed(i)));
        s1 += x;
        s2 += x * x;
    }
    EXPECT_NEAR(s1 / n, 0.0, 0.005);
    EXPECT_NEAR(s2 / n, 1.0, 0.01);
}

TEST(SimNoise, DepthLevelsFallOnDisparitySteps) {
    const DepthNoiseModel model(pureConfig(), std::nullopt, 79.5, 59.5);
    for (const double z : {1.0, 1.37, 2.0, 3.0}) {
        const DepthImage clean(160, 120, static_cast<float>(z));
        const DepthImage noisy = model.apply(clean, {}, 7, 0);
        size_t valid = 0;
        double worst = 0.0;
        for (float d : noisy.pixels()) {
            if (d <= 0.0F) continue;
            ++valid;
            const double k = kBf * 8.0 / d;  // the 1/8-pixel disparity level
            worst = std::max(worst, std::abs(k - std::nearbyint(k)));
        }
        EXPECT_EQ(valid, noisy.size());
        EXPECT_LT(worst, 1e-3) << "z = " << z;
    }
}

TEST(SimNoise, SigmaMatchesTheModelAtOneTwoThreeMetres) {
    // Planes spread over one quantisation step around z: the measured spread must match
    // sigma_z = z^2 * 0.027778 / 35.13 combined with the quantisation variance dz^2 / 12.
    const DepthNoiseModel model(pureConfig(), std::nullopt, 79.5, 59.5);
    for (const double z0 : {1.0, 2.0, 3.0}) {
        const double dz = z0 * z0 / (8.0 * kBf);
        const double sigma = z0 * z0 * 0.027778 / kBf;
        const double expected = std::sqrt(sigma * sigma + dz * dz / 12.0);
        std::vector<double> err;
        for (int j = 0; j < 32; ++j) {
            const double z = z0 + (j + 0.5) / 32.0 * dz;
            const DepthImage clean(160, 120, static_cast<float>(z));
            const DepthImage noisy = model.apply(clean, {}, 11, j);
            for (float d : noisy.pixels()) {
                if (d > 0.0F) err.push_back(d - z);
            }
        }
        const double measured = stddev(err);
        EXPECT_NEAR(measured / expected, 1.0, 0.2)
            << "z = " << z0 << " measured " << measured << " model " << expected;
        EXPECT_NEAR(mean(err), 0.0, 0.2 * expected) << "z = " << z0;
        std::printf("[sim noise] z=%.0f m: sigma measured %.4f m, model %.4f m\n", z0, measured,
                    expected);
    }
}

TEST(SimNoise, SameSeedSameFrameIsIdenticalForAnyThreadCount) {
    NoiseConfig config;
    config.distortion = DistortionKind::kParametric;
    const DepthNoiseModel model(config, std::nullopt, 79.5, 59.5);
    DepthImage clean(160, 120);
    Image<float> cosv(160, 120, 0.5F);
    for (int v = 0; v < 120; ++v) {
        for (int u = 0; u < 160; ++u) clean(u, v) = 1.0F + 0.01F * u + (u > 80 ? 0.5F : 0.0F);
    }
    const DepthImage a = model.apply(clean, cosv, 42, 5);
    DepthImage b;
    {
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        b = model.apply(clean, cosv, 42, 5);
    }
    EXPECT_TRUE(a == b);
    const DepthImage other_frame = model.apply(clean, cosv, 42, 6);
    const DepthImage other_seed = model.apply(clean, cosv, 43, 5);
    EXPECT_FALSE(a == other_frame);
    EXPECT_FALSE(a == other_seed);
    // The depth edge at u = 80/81 is dropped (up to pixel jitter from the neighbours), grazing
    // pixels (cos 0.5) are kept.
    size_t edge_valid = 0;
    for (int v = 0; v < 120; ++v) edge_valid += (a(80, v) > 0.0F) + (a(81, v) > 0.0F);
    EXPECT_LT(edge_valid, 0.15 * 240);
    EXPECT_GT(countValid(a), 0.95 * 160 * 120 - 4 * 120);
}

TEST(SimNoise, GrazingAnglesAndRangeLimitsDropPixels) {
    NoiseConfig config = pureConfig();
    config.missing_data = true;
    config.random_dropout = 0.0;
    config.min_depth_m = 0.4;
    config.max_depth_m = 4.0;
    const DepthNoiseModel model(config, std::nullopt, 79.5, 59.5);
    Image<float> cosv(160, 120, 0.05F);
    EXPECT_EQ(countValid(model.apply(DepthImage(160, 120, 2.0F), cosv, 1, 0)), 0U);
    cosv = Image<float>(160, 120, 0.2F);  // half-way up the ramp: about half dropped
    const double kept =
        countValid(model.apply(DepthImage(160, 120, 2.0F), cosv, 1, 0)) / (160.0 * 120.0);
    EXPECT_NEAR(kept, 0.5, 0.05);
    cosv = Image<float>(160, 120, 1.0F);
    EXPECT_EQ(countValid(model.apply(DepthImage(160, 120, 0.3F), cosv, 1, 0)), 0U);
    EXPECT_EQ(countValid(model.apply(DepthImage(160, 120, 4.5F), cosv, 1, 0)), 0U);
    EXPECT_EQ(countValid(model.apply(DepthImage(160, 120, 2.0F), cosv, 1, 0)), 160U * 120U);
}

TEST(SimNoise, ParametricDistortionBendsTowardsTheCorners) {
    // Quantisation and noise made negligible: the corner/centre depth ratio is 1 + k1 * rho.
    NoiseConfig config = pureConfig();
    config.distortion = DistortionKind::kParametric;
    config.k1 = 0.05;
    config.disparity_subpixel_steps = 1e7;
    config.disparity_noise_std = 0.0;
    config.jitter_std_px = 0.0;
    const PinholeCamera cam = *cameraPreset("ci");
    const DepthNoiseModel model(config, std::nullopt, cam.cx, cam.cy);
    const double z = 3.0;
    const DepthImage noisy = model.apply(DepthImage(160, 120, static_cast<float>(z)), {}, 1, 0);
    // Pixel (0, 0): sampled at block (0, 0), rho = 1 exactly; k(3 m) = k1.
    EXPECT_NEAR(noisy(0, 0), z / (1.0 + config.k1), 1e-4);
    // Near the centre rho ~ 0: the depth is unchanged.
    EXPECT_NEAR(noisy(80, 60), z, 1e-3);
    EXPECT_NEAR(z - noisy(0, 0), config.k1 * z / (1.0 + config.k1), 1e-4);
}

TEST(SimNoise, RedwoodTableLoadsAndFailsClearly) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto table = DistortionTable::load(path);
    ASSERT_TRUE(table.isOk()) << table.status().toString();
    int valid = 0;
    for (int y = 0; y < 480; y += 6) {
        for (int x = 0; x < 640; x += 8) {
            const float f = table->factor(x, y, 2.0);
            if (f == 0.0F) continue;
            ++valid;
            EXPECT_GT(f, 0.8F);
            EXPECT_LT(f, 1.2F);
        }
    }
    EXPECT_GT(valid, 80 * 80 / 2);
    auto truncated = DistortionTable::parse("8\n6\n2\n80\n80\n1\n2\n", "short.txt");
    ASSERT_FALSE(truncated.isOk());
    EXPECT_EQ(truncated.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(truncated.status().message().find("short.txt"), std::string::npos);
    auto missing = findNoiseModelFile("/nonexistent/dist-model.txt");
    ASSERT_FALSE(missing.isOk());
    EXPECT_NE(missing.status().message().find("/nonexistent/dist-model.txt"), std::string::npos);
}

// Our Redwood pipeline and Open3D's DepthNoiseSimulator on the same clean planes with the same
// model file: means and spreads per depth must agree.
TEST(SimNoise, MatchesOpen3dDepthNoiseSimulator) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const std::filesystem::path model_path = path;
    const std::string python = "/usr/bin/python3";
    if (std::system((python + " -c 'import open3d' >/dev/null 2>&1").c_str()) != 0) {
        if (testing::runningInCi()) FAIL() << "python3-open3d is required under CI";
        GTEST_SKIP() << "python3 with open3d not available";
    }
    const auto dir = testing::freshTempDir("sim_noise_open3d");
    const std::vector<double> depths = {1.0, 2.0, 3.0};
    for (double z : depths) {
        const Depth16Image raw(640, 480, static_cast<uint16_t>(std::lround(z * 1000)));
        ASSERT_TRUE(
            dataset::writeDepthPng(dir / ("clean_" + std::to_string(int(z)) + ".png"), raw).isOk());
    }
    {
        std::ofstream script(dir / "o3d_noise.py");
        script << "import json, sys\nimport numpy as np\nimport open3d as o3d\n"
                  "sim = o3d.t.io.DepthNoiseSimulator(sys.argv[1])\nout = {}\n"
                  "for z in (1, 2, 3):\n"
                  "    im = o3d.t.io.read_image(sys.argv[2] + '/clean_%d.png' % z)\n"
                  "    vals = []\n"
                  "    for rep in range(3):\n"
                  "        a = np.asarray(sim.simulate(im, depth_scale=1000.0)).astype(np.float64)"
                  " / 1000.0\n"
                  "        vals.append(a[a > 0])\n"
                  "    v = np.concatenate(vals)\n"
                  "    out[str(z)] = {'mean': float(v.mean()), 'std': float(v.std()),\n"
                  "                   'valid': float(v.size) / (3 * a.size)}\n"
                  "json.dump(out, open(sys.argv[2] + '/o3d.json', 'w'))\n";
    }
    const std::string cmd = python + " " + (dir / "o3d_noise.py").string() + " " +
                            model_path.string() + " " + dir.string();
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    std::ifstream in(dir / "o3d.json");
    const nlohmann::json o3d = nlohmann::json::parse(in);

    NoiseConfig config;  // Redwood with the table, no missing-data extras, no range gating
    config.missing_data = false;
    config.min_depth_m = 0.0;
    config.max_depth_m = 0.0;
    const DepthNoiseModel model(config, *DistortionTable::load(model_path), 319.5, 239.5);
    for (double z : depths) {
        std::vector<double> vals;
        size_t total = 0;
        for (int rep = 0; rep < 3; ++rep) {
            const DepthImage noisy =
                model.apply(DepthImage(640, 480, static_cast<float>(z)), {}, 3, rep);
            total += noisy.size();
            for (float d : noisy.pixels()) {
                if (d > 0.0F) vals.push_back(std::round(d * 1000.0) / 1000.0);  // as a mm PNG
            }
        }
        const auto& ref = o3d[std::to_string(int(z))];
        const double ref_mean = ref["mean"], ref_std = ref["std"], ref_valid = ref["valid"];
        std::printf(
            "[sim noise] z=%.0f m: ours mean %.4f std %.4f valid %.3f | open3d mean %.4f "
            "std %.4f valid %.3f\n",
            z, mean(vals), stddev(vals), double(vals.size()) / total, ref_mean, ref_std, ref_valid);
        EXPECT_NEAR(mean(vals), ref_mean, 0.002 * z) << "z = " << z;
        EXPECT_NEAR(stddev(vals) / ref_std, 1.0, 0.2) << "z = " << z;
        EXPECT_NEAR(double(vals.size()) / total, ref_valid, 0.02) << "z = " << z;
    }
}

// The noise model as first written (full-resolution pass 1, std::mt19937_64, a fresh image):
// the slow reference for apply(), which skips the pixels A.2 never reads and reuses buffers.
DepthImage referenceApply(const NoiseConfig& c, double cx, double cy, const DepthImage& clean,
                          const Image<float>& cos_view, uint64_t seed, uint64_t frame) {
    const int w = clean.width(), h = clean.height();
    auto row_seed = [&](int row, int pass) {
        return mixSeed(mixSeed(mixSeed(seed) ^ frame) ^ ((static_cast<uint64_t>(row) << 4) | pass));
    };
    auto uniform = [](uint32_t bits) { return (bits + 0.5) * (1.0 / 4294967296.0); };
    auto in_range = [&](double z) {
        return z >= c.min_depth_m && (c.max_depth_m <= 0.0 || z <= c.max_depth_m);
    };
    DepthImage src = clean;
    for (int v = 0; v < h && c.missing_data; ++v) {
        std::mt19937_64 rng(row_seed(v, 1));
        for (int u = 0; u < w; ++u) {
            const uint64_t bits = rng();
            const float z = clean(u, v);
            if (!(z > 0.0F)) continue;
            bool drop = uniform(static_cast<uint32_t>(bits)) < c.random_dropout;
            const double cs = cos_view(u, v);
            if (cs < c.grazing_cos_drop) {
                drop = true;
            } else if (cs < c.grazing_cos_keep) {
                const double p =
                    (c.grazing_cos_keep - cs) / (c.grazing_cos_keep - c.grazing_cos_drop);
                drop |= uniform(static_cast<uint32_t>(bits >> 32)) < p;
            }
            if (!drop) {
                float lo = z, hi = z;
                for (int vv = std::max(0, v - 1); vv <= std::min(h - 1, v + 1); ++vv) {
                    for (int uu = std::max(0, u - 1); uu <= std::min(w - 1, u + 1); ++uu) {
                        const float zn = clean(uu, vv);
                        if (!(zn > 0.0F)) continue;
                        lo = std::min(lo, zn);
                        hi = std::max(hi, zn);
                    }
                }
                drop = hi - lo > c.edge_relative_range * z;
            }
            if (drop) src(u, v) = 0.0F;
        }
    }
    DepthImage out(w, h, 0.0F);
    for (int v = 0; v < h; ++v) {
        std::mt19937_64 rng(row_seed(v, 2));
        for (int u = 0; u < w; ++u) {
            const uint64_t r1 = rng();
            const uint64_t r2 = rng();
            const double jx = c.jitter_std_px * standardNormalFromBits(static_cast<uint32_t>(r1));
            const double jy =
                c.jitter_std_px * standardNormalFromBits(static_cast<uint32_t>(r1 >> 32));
            const int x = std::clamp(static_cast<int>(std::nearbyint(u + jx)), 0, w - 1);
            const int y = std::clamp(static_cast<int>(std::nearbyint(v + jy)), 0, h - 1);
            double d = src(x - x % 2, y - y % 2);
            if (!(d > 0.0)) continue;
            if (c.distortion == DistortionKind::kParametric) {
                const double rx = (x - cx) / cx;
                const double ry = (y - cy) / cy;
                const double rho = 0.5 * (rx * rx + ry * ry);
                d /= 1.0 + c.k1 * std::clamp(d / 3.0, 0.0, 1.5) * rho + c.k2 * rx;
            }
            const double disparity =
                c.baseline_focal_px_m / d +
                c.disparity_noise_std * standardNormalFromBits(static_cast<uint32_t>(r2));
            const double level = std::nearbyint(disparity * c.disparity_subpixel_steps);
            if (!(level > 0.0)) continue;
            const double z = c.baseline_focal_px_m * c.disparity_subpixel_steps / level;
            if (in_range(z)) out(u, v) = static_cast<float>(z);
        }
    }
    return out;
}

TEST(SimNoise, GeneratorIsStdMt19937_64) {
    for (const uint64_t seed :
         {uint64_t{0}, uint64_t{1}, uint64_t{5489}, mixSeed(7), ~uint64_t{0}}) {
        std::mt19937_64 reference(seed);
        Mt19937_64 ours(seed);
        for (int i = 0; i < 2000; ++i) ASSERT_EQ(ours(), reference()) << seed << " #" << i;
    }
}

TEST(SimNoise, ApplyMatchesTheReferenceBitForBit) {
    // Odd and even sizes, steps, holes, grazing angles; missing data on and off; reused and fresh
    // output buffers; one and two threads.
    for (const auto& [w, h] : {std::pair{160, 120}, std::pair{97, 61}}) {
        DepthImage clean(w, h);
        Image<float> cos_view(w, h);
        for (int v = 0; v < h; ++v) {
            for (int u = 0; u < w; ++u) {
                clean(u, v) = (u + v) % 37 == 0 ? 0.0F : (u < w / 2 ? 1.3F : 2.9F) + 0.004F * v;
                cos_view(u, v) = static_cast<float>(u) / w;
            }
        }
        for (const bool missing : {true, false}) {
            NoiseConfig config;
            config.distortion = DistortionKind::kParametric;
            config.missing_data = missing;
            const DepthNoiseModel model(config, std::nullopt, 0.5 * w, 0.5 * h);
            DepthImage reused;
            for (const int threads : {1, 2}) {
                tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
                for (uint64_t frame = 0; frame < 3; ++frame) {
                    const DepthImage expected =
                        referenceApply(config, 0.5 * w, 0.5 * h, clean, cos_view, 11, frame);
                    model.apply(clean, cos_view, 11, frame, &reused);
                    ASSERT_EQ(reused, expected) << w << "x" << h << " frame " << frame;
                    ASSERT_EQ(model.apply(clean, cos_view, 11, frame), expected);
                }
            }
        }
    }
}

}  // namespace
}  // namespace plumb::sim
