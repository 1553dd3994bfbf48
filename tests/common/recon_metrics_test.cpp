// SPDX-License-Identifier: Apache-2.0
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <random>

#include "common/eval/recon_metrics.hpp"
#include "common/io/ply.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

constexpr double kGridStepM = 0.002;
constexpr int kGridCells = 200;  // 0.4 m x 0.4 m, 201 x 201 samples

/// Samples z = `height` on the grid x = i * 2 mm (i in [i_begin, i_end]), y = j * 2 mm.
std::vector<Eigen::Vector3f> planeSamples(float height, int i_begin = 0, int i_end = kGridCells) {
    std::vector<Eigen::Vector3f> points;
    for (int i = i_begin; i <= i_end; ++i) {
        for (int j = 0; j <= kGridCells; ++j) {
            points.emplace_back(static_cast<float>(i * kGridStepM),
                                static_cast<float>(j * kGridStepM), height);
        }
    }
    return points;
}

TEST(ReconMetrics, PlaneDisplacedByOneCentimetre) {
    const auto gt = planeSamples(0.0f);
    // The reconstruction is offset laterally by half a grid step (so no point lies directly
    // above a GT sample) and lifted by exactly 1 cm.
    std::vector<Eigen::Vector3f> recon;
    for (int i = 0; i < kGridCells; ++i) {
        for (int j = 0; j < kGridCells; ++j) {
            recon.emplace_back(static_cast<float>((i + 0.5) * kGridStepM),
                               static_cast<float>((j + 0.5) * kGridStepM), 0.01f);
        }
    }
    auto m = eval::evaluateReconstruction(recon, gt);
    ASSERT_TRUE(m.isOk()) << m.status().toString();
    // Every recon point sees its closest GT sample at sqrt(1 cm^2 + 2 (1 mm)^2) = 10.0995 mm.
    const double expected = std::sqrt(0.01 * 0.01 + 2 * 0.001 * 0.001);
    EXPECT_NEAR(m->accuracy.mean_m, 0.01, 0.0005);
    EXPECT_NEAR(m->accuracy.mean_m, expected, 1e-6);
    EXPECT_NEAR(m->accuracy.median_m, expected, 1e-6);
    EXPECT_NEAR(m->accuracy.rms_m, expected, 1e-6);
    EXPECT_NEAR(m->accuracy.p90_m, expected, 1e-6);
    EXPECT_NEAR(m->accuracy.max_m, expected, 1e-6);
    EXPECT_EQ(m->accuracy.count, recon.size());
    EXPECT_EQ(m->num_ground_truth, gt.size());
    EXPECT_DOUBLE_EQ(m->accuracy_fraction, 1.0);
    EXPECT_DOUBLE_EQ(m->completeness, 1.0);
    // A threshold below 1 cm matches nothing.
    eval::ReconMetricsConfig tight;
    tight.completeness_threshold_m = 0.0099;
    auto t = eval::evaluateReconstruction(recon, gt, tight);
    ASSERT_TRUE(t.isOk());
    EXPECT_EQ(t->accuracy_fraction, 0.0);
    EXPECT_EQ(t->completeness, 0.0);
}

TEST(ReconMetrics, HalfTheGroundTruthMissing) {
    const auto gt = planeSamples(0.0f);
    // The reconstruction covers only x <= 0.2 m (columns 0..100), 1 cm above the GT.
    const auto recon = planeSamples(0.01f, 0, kGridCells / 2);
    auto m = eval::evaluateReconstruction(recon, gt);
    ASSERT_TRUE(m.isOk());
    // A GT column at lateral distance dx from the last recon column is within 2 cm iff
    // sqrt(1 cm^2 + dx^2) <= 2 cm, i.e. dx <= 17.3 mm: columns 101..108 (8 columns).
    const double expected = (101.0 + 8.0) / 201.0;
    EXPECT_NEAR(m->completeness, expected, 1e-12);
    EXPECT_NEAR(m->completeness, 0.5, 0.05);
    EXPECT_DOUBLE_EQ(m->accuracy_fraction, 1.0);
    EXPECT_NEAR(m->accuracy.mean_m, 0.01, 1e-6);
    // GT -> recon: the farthest GT column is 100 steps (0.2 m) beyond the recon edge.
    EXPECT_NEAR(m->completeness_distances.max_m, std::hypot(0.2, 0.01), 1e-6);
}

TEST(ReconMetrics, MatchesBruteForceAndIgnoresThreadCount) {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    std::vector<Eigen::Vector3f> a(3000), b(800);
    for (auto& p : a) p = {u(rng), u(rng), u(rng)};
    for (auto& p : b) p = {u(rng), u(rng), 0.3f * u(rng)};
    auto d1 = eval::closestPointDistances(a, b, 1);
    auto d2 = eval::closestPointDistances(a, b, 2);
    auto d0 = eval::closestPointDistances(a, b, 0);
    ASSERT_TRUE(d1.isOk() && d2.isOk() && d0.isOk());
    EXPECT_EQ(*d1, *d2);  // bit-identical
    EXPECT_EQ(*d1, *d0);
    for (size_t i = 0; i < a.size(); ++i) {
        double best = 1e9;
        for (const auto& q : b) best = std::min(best, (a[i] - q).cast<double>().norm());
        EXPECT_NEAR((*d1)[i], best, 1e-6) << i;
    }
    eval::ReconMetricsConfig one, two;
    one.num_threads = 1;
    two.num_threads = 2;
    const auto m1 = eval::evaluateReconstruction(a, b, one).value();
    const auto m2 = eval::evaluateReconstruction(a, b, two).value();
    EXPECT_EQ(m1.accuracy.mean_m, m2.accuracy.mean_m);
    EXPECT_EQ(m1.accuracy.median_m, m2.accuracy.median_m);
    EXPECT_EQ(m1.completeness, m2.completeness);
}

TEST(ReconMetrics, AGroundTruthTreeBuiltOnceServesEveryEvaluationAlike) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    std::vector<Eigen::Vector3f> gt(2000), first(1500), second(900);
    for (auto& p : gt) p = {u(rng), u(rng), 0.2f * u(rng)};
    for (auto& p : first) p = {u(rng), u(rng), 0.3f * u(rng)};
    for (auto& p : second) p = {0.5f * u(rng), u(rng), 0.1f * u(rng)};
    const auto shared = eval::ClosestPoints::build(gt);
    ASSERT_TRUE(shared.isOk());
    for (const auto* recon : {&first, &second}) {
        std::vector<double> to_gt;
        const auto m = eval::evaluateReconstruction(*recon, **shared, {}, &to_gt).value();
        const auto alone = eval::evaluateReconstruction(*recon, gt).value();
        EXPECT_EQ(m.accuracy.mean_m, alone.accuracy.mean_m);  // bit-identical
        EXPECT_EQ(m.accuracy.max_m, alone.accuracy.max_m);
        EXPECT_EQ(m.completeness_distances.mean_m, alone.completeness_distances.mean_m);
        EXPECT_EQ(m.completeness, alone.completeness);
        EXPECT_EQ(m.num_ground_truth, gt.size());
        // Each point's own distance comes back, the same the plain search gives.
        EXPECT_EQ(to_gt, eval::closestPointDistances(*recon, gt).value());
        EXPECT_EQ(eval::summarize(to_gt).mean_m, m.accuracy.mean_m);
    }
    EXPECT_EQ(eval::ClosestPoints::build({}).status().code(), StatusCode::kInvalidArgument);
    std::vector<Eigen::Vector3f> nan = gt;
    nan[7].x() = std::numeric_limits<float>::quiet_NaN();
    EXPECT_EQ(eval::ClosestPoints::build(nan).status().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ((*shared)->distances(nan).status().code(), StatusCode::kInvalidArgument);
}

TEST(ReconMetrics, SummaryStatisticsAreExact) {
    std::vector<double> d;
    for (int i = 10; i >= 0; --i) d.push_back(i);  // 0..10, unsorted
    const eval::DistanceStats s = eval::summarize(d);
    EXPECT_EQ(s.count, 11u);
    EXPECT_DOUBLE_EQ(s.mean_m, 5.0);
    EXPECT_DOUBLE_EQ(s.median_m, 5.0);
    EXPECT_DOUBLE_EQ(s.p90_m, 9.0);
    EXPECT_DOUBLE_EQ(s.max_m, 10.0);
    EXPECT_DOUBLE_EQ(s.rms_m, std::sqrt(385.0 / 11.0));
    // Even count: the median interpolates; p90 at position 0.9 * 3 = 2.7.
    const eval::DistanceStats e = eval::summarize({1.0, 2.0, 4.0, 8.0});
    EXPECT_DOUBLE_EQ(e.median_m, 3.0);
    EXPECT_DOUBLE_EQ(e.p90_m, 4.0 + 0.7 * 4.0);
    EXPECT_EQ(eval::summarize({}).count, 0u);
    EXPECT_DOUBLE_EQ(eval::summarize({7.0}).median_m, 7.0);
    EXPECT_DOUBLE_EQ(eval::summarize({7.0}).p90_m, 7.0);
    // Random lists with repeats, of every length up to 60: the percentiles a full sort gives.
    std::mt19937 rng(3);
    std::uniform_int_distribution<int> value(0, 20);
    for (size_t n = 1; n <= 60; ++n) {
        std::vector<double> list;
        for (size_t i = 0; i < n; ++i) list.push_back(0.01 * value(rng));
        std::vector<double> sorted = list;
        std::sort(sorted.begin(), sorted.end());
        const auto at = [&](double q) {
            const double pos = q * static_cast<double>(n - 1);
            const auto lo = static_cast<size_t>(std::floor(pos));
            const size_t hi = std::min(lo + 1, n - 1);
            return sorted[lo] + (pos - static_cast<double>(lo)) * (sorted[hi] - sorted[lo]);
        };
        const eval::DistanceStats r = eval::summarize(list);
        EXPECT_EQ(r.median_m, at(0.5)) << n;
        EXPECT_EQ(r.p90_m, at(0.9)) << n;
        EXPECT_EQ(r.max_m, sorted.back()) << n;
    }
}

TEST(ReconMetrics, MeshSamplingIsDenseAndOnTheSurface) {
    // A 1 x 2 m rectangle in z = 0.5 as two triangles, sampled at 5 mm.
    const std::vector<Eigen::Vector3f> v = {{0, 0, 0.5f}, {1, 0, 0.5f}, {1, 2, 0.5f}, {0, 2, 0.5f}};
    const std::vector<Eigen::Vector3i> t = {{0, 1, 2}, {0, 2, 3}};
    auto s = eval::sampleMeshSurface(v, t, 0.005);
    ASSERT_TRUE(s.isOk()) << s.status().toString();
    // Longest edge (diagonal) sqrt(5) m -> n = 448 steps per triangle.
    const size_t n = 448;
    EXPECT_EQ(s->size(), 2 * (n + 1) * (n + 2) / 2);
    for (const auto& p : *s) {
        ASSERT_EQ(p.z(), 0.5f);
        ASSERT_TRUE(p.x() >= 0.0f && p.x() <= 1.0f && p.y() >= 0.0f && p.y() <= 2.0f);
    }
    // Every point of the rectangle is within half the sample spacing diagonal of a sample: probe
    // a fine grid of query points.
    std::vector<Eigen::Vector3f> probes;
    for (int i = 0; i <= 50; ++i) {
        for (int j = 0; j <= 100; ++j) probes.emplace_back(i * 0.02f, j * 0.02f, 0.5f);
    }
    auto d = eval::closestPointDistances(probes, *s);
    ASSERT_TRUE(d.isOk());
    EXPECT_LT(eval::summarize(*d).max_m, 0.005);
    EXPECT_FALSE(eval::sampleMeshSurface(v, {{0, 1, 4}}, 0.005).isOk());
    EXPECT_FALSE(eval::sampleMeshSurface(v, t, 0.0).isOk());
    EXPECT_FALSE(eval::sampleMeshSurface(v, t, 1e-5, 1000).isOk());
}

TEST(ReconMetrics, RejectsUnusableInput) {
    const std::vector<Eigen::Vector3f> some = {{0, 0, 0}, {1, 0, 0}};
    const std::vector<Eigen::Vector3f> none;
    EXPECT_EQ(eval::evaluateReconstruction(none, some).status().code(),
              StatusCode::kInvalidArgument);
    EXPECT_EQ(eval::evaluateReconstruction(some, none).status().code(),
              StatusCode::kInvalidArgument);
    auto nan = some;
    nan[1].x() = std::nanf("");
    auto r = eval::evaluateReconstruction(nan, some);
    ASSERT_FALSE(r.isOk());
    EXPECT_NE(r.status().message().find("point 1 is not finite"), std::string::npos);
    eval::ReconMetricsConfig bad;
    bad.completeness_threshold_m = 0.0;
    EXPECT_EQ(eval::evaluateReconstruction(some, some, bad).status().code(),
              StatusCode::kInvalidArgument);
}

TEST(ReconMetricsOpen3d, MatchesComputePointCloudDistance) {
    if (std::system("/usr/bin/python3 -c 'import open3d' > /dev/null 2>&1") != 0) {
        if (testing::runningInCi()) FAIL() << "python3-open3d missing";
        GTEST_SKIP() << "python3-open3d not importable";
    }
    const fs::path dir = testing::freshTempDir("recon_metrics_open3d");
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> u(-2.0f, 2.0f);
    PointCloud recon, gt;
    for (int i = 0; i < 2000; ++i) recon.points.emplace_back(u(rng), u(rng), u(rng));
    for (int i = 0; i < 5000; ++i) gt.points.emplace_back(u(rng), u(rng), 0.5f * u(rng));
    ASSERT_TRUE(io::writePointCloud(dir / "recon.ply", recon).isOk());
    ASSERT_TRUE(io::writePointCloud(dir / "gt.ply", gt).isOk());
    std::ofstream(dir / "dist.py") << R"(
import sys, numpy as np, open3d as o3d
d = sys.argv[1]
r = o3d.io.read_point_cloud(d + "/recon.ply")
g = o3d.io.read_point_cloud(d + "/gt.ply")
np.savetxt(d + "/o3d.txt", np.asarray(r.compute_point_cloud_distance(g)), fmt="%.12g")
)";
    const std::string cmd =
        fmt::format("/usr/bin/python3 {} {}", (dir / "dist.py").string(), dir.string());
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    std::ifstream in(dir / "o3d.txt");
    std::vector<double> o3d;
    for (double v; in >> v;) o3d.push_back(v);
    ASSERT_EQ(o3d.size(), recon.size());
    auto ours = eval::closestPointDistances(recon.points, gt.points);
    ASSERT_TRUE(ours.isOk());
    double worst = 0.0;
    for (size_t i = 0; i < o3d.size(); ++i) worst = std::max(worst, std::abs((*ours)[i] - o3d[i]));
    EXPECT_LT(worst, 1e-6);
}

}  // namespace
}  // namespace plumb
