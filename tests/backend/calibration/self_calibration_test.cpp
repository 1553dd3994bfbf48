// SPDX-License-Identifier: Apache-2.0
// Self-calibration of the depth distortion table (backend/calibration, reference §7c): on the
// simulated scanner with the measured Redwood table applied and no calibration, the table learnt
// against a TSDF fused at the ground-truth poses matches the true one up to one global scale; on
// undistorted depth it stays neutral; bad input gets specific errors. The table writer reads back.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "backend/calibration/self_calibration.hpp"
#include "common/camera/pinhole.hpp"
#include "common/config/config.hpp"
#include "tests/backend/calibration/simulated_depth.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::calibration {
namespace {

using Table = DistortionTable;

/// A simulated scan at the "ci" camera (160x120): raw depth and ground-truth poses.
using Scan = testing::SimulatedScan;

Scan simulate(const std::string& noise_mode, const std::string& table_path, size_t frames) {
    return testing::simulateLivingRoomScan("ci", noise_mode, table_path, frames);
}

void printIteration(const CalibrationIteration& it) {
    const DistortionEstimate& e = it.estimate;
    std::printf(
        "  iteration %d: %zu samples (%zu outliers), cells covered per bin %d %d %d %d %d, "
        "change median %.5f max %.5f, gauge scale %.5f\n",
        it.iteration, e.samples, e.outliers, e.covered_cells[0], e.covered_cells[1],
        e.covered_cells[2], e.covered_cells[3], e.covered_cells[4], e.median_change, e.max_change,
        e.gauge_scale);
}

double median(std::vector<double> v) {
    if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

constexpr size_t kFrames = 300;

TEST(SelfCalibration, LearnsTheRedwoodTableFromARawScanWithGroundTruthPoses) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const auto start = std::chrono::steady_clock::now();
    const Scan scan = simulate("redwood", path.string(), kFrames);
    ASSERT_EQ(scan.depth.size(), kFrames);
    auto truth = Table::load(path);
    ASSERT_TRUE(truth.isOk()) << truth.status().toString();

    SelfCalibrationConfig config;
    auto result =
        selfCalibrate(scan.depth, scan.camera, scan.T_W_C, config, nullptr, printIteration);
    ASSERT_TRUE(result.isOk()) << result.status().toString();
    ASSERT_FALSE(result->iterations.empty());
    const DistortionEstimate& last = result->iterations.back().estimate;

    // One global scale between learnt and true factors (the gauge), over the compared bins.
    auto cmp = compareTables(result->table, last, *truth);
    ASSERT_TRUE(cmp.isOk()) << cmp.status().toString();
    for (int bin : {0, 1}) {
        const TableComparison::Bin& b = cmp->bins[static_cast<size_t>(bin)];
        std::printf(
            "bin %d (%.0f m): %zu cells covered, median |learned - true| %.4f %% (uncalibrated "
            "|1 - true| %.4f %%), global scale %.5f\n",
            bin, Table::binCentreM(bin), b.cells, 100.0 * b.median_error,
            100.0 * b.median_uncalibrated, cmp->scale);
        EXPECT_GT(b.cells, size_t{Table::kCellsPerSide * Table::kCellsPerSide / 4})
            << "bin " << bin;
        EXPECT_LE(b.median_error, 0.003) << "bin " << bin;
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("%zu frames, %zu iterations, converged %d, %.1f s\n", scan.depth.size(),
                result->iterations.size(), result->converged ? 1 : 0, seconds);
}

TEST(SelfCalibration, StaysNeutralOnUndistortedDepth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const Scan scan = simulate("undistorted", path.string(), kFrames);
    ASSERT_EQ(scan.depth.size(), kFrames);
    SelfCalibrationConfig config;
    config.max_iterations = 2;
    auto result =
        selfCalibrate(scan.depth, scan.camera, scan.T_W_C, config, nullptr, printIteration);
    ASSERT_TRUE(result.isOk()) << result.status().toString();
    const DistortionEstimate& last = result->iterations.back().estimate;
    const int side = Table::kCellsPerSide;
    for (int bin : {0, 1}) {
        std::vector<double> deviation;
        for (int y = 0; y < side; ++y) {
            for (int x = 0; x < side; ++x) {
                if (!last.isCovered(x, y, bin)) continue;
                deviation.push_back(std::abs(result->table.cell(x, y)[bin] - 1.0));
            }
        }
        std::printf("bin %d: %zu cells covered, median |learned - 1| %.4f %%\n", bin,
                    deviation.size(), 100.0 * median(deviation));
        EXPECT_GT(deviation.size(), size_t{side * side / 4}) << "bin " << bin;
        EXPECT_LE(median(deviation), 0.003) << "bin " << bin;
    }
}

TEST(SelfCalibration, ResultsDoNotDependOnTheThreadCount) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const Scan scan = simulate("redwood", path.string(), 40);
    ASSERT_EQ(scan.depth.size(), 40U);
    std::vector<Table> tables;
    for (int threads : {1, 2}) {
        SelfCalibrationConfig config;
        config.max_iterations = 2;
        config.num_threads = config.tsdf.num_threads = config.raycast.num_threads = threads;
        auto result = selfCalibrate(scan.depth, scan.camera, scan.T_W_C, config);
        ASSERT_TRUE(result.isOk()) << result.status().toString();
        tables.push_back(result->table);
    }
    EXPECT_EQ(tables[0].format(), tables[1].format());
}

TEST(SelfCalibration, BadInputGetsSpecificErrors) {
    PinholeCamera camera = cameraPreset("ci").value();
    SelfCalibrationConfig config;
    const std::vector<DepthImage> none;
    auto empty = selfCalibrate(none, camera, std::vector<Eigen::Isometry3d>{}, config);
    ASSERT_FALSE(empty.isOk());
    EXPECT_EQ(empty.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(empty.status().message().find("no frames"), std::string::npos);

    std::vector<DepthImage> frames(2, DepthImage(camera.width, camera.height, 2.0F));
    std::vector<Eigen::Isometry3d> poses(2, Eigen::Isometry3d::Identity());
    auto count = selfCalibrate(frames, camera, std::vector<Eigen::Isometry3d>(1), config);
    ASSERT_FALSE(count.isOk());
    EXPECT_NE(count.status().message().find("1 poses for 2 frames"), std::string::npos)
        << count.status().message();

    std::vector<DepthImage> sizes = frames;
    sizes[1] = DepthImage(80, 60, 2.0F);
    auto size = selfCalibrate(sizes, camera, poses, config);
    ASSERT_FALSE(size.isOk());
    EXPECT_NE(size.status().message().find("frame 1 is 80x60, the camera is 160x120"),
              std::string::npos)
        << size.status().message();

    std::vector<Eigen::Isometry3d> nan_poses = poses;
    nan_poses[1].translation().x() = std::numeric_limits<double>::quiet_NaN();
    auto nan = selfCalibrate(frames, camera, nan_poses, config);
    ASSERT_FALSE(nan.isOk());
    EXPECT_NE(nan.status().message().find("pose of frame 1 is not finite"), std::string::npos)
        << nan.status().message();

    SelfCalibrationConfig bad = config;
    bad.max_depth_m = 0.2;
    auto range = selfCalibrate(frames, camera, poses, bad);
    ASSERT_FALSE(range.isOk());
    EXPECT_NE(range.status().message().find("min_depth_m < max_depth_m"), std::string::npos);

    // Depth the model never sees within range: nothing to estimate.
    std::vector<DepthImage> far(2, DepthImage(camera.width, camera.height, 9.0F));
    auto uncovered = selfCalibrate(far, camera, poses, config);
    ASSERT_FALSE(uncovered.isOk());
    EXPECT_EQ(uncovered.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_NE(uncovered.status().message().find("no image cell"), std::string::npos)
        << uncovered.status().message();

    DistortionEstimator estimator(camera.width, camera.height, config);
    const Status mismatch = estimator.addFrame(DepthImage(camera.width, camera.height),
                                               DepthImage(70, 50), Image<float>());
    ASSERT_FALSE(mismatch.isOk());
    EXPECT_NE(mismatch.message().find("the model depth is 70x50"), std::string::npos);
}

TEST(SelfCalibration, ABlockOriginModelGivesTheSamplesOfItsImageSpreadOverTheBlocks) {
    // 161x121: the last column and row of blocks are one pixel wide.
    const int w = 161, h = 121;
    SelfCalibrationConfig config;
    config.min_samples = 4.0;
    DepthImage raw(w, h), model((w + 1) / 2, (h + 1) / 2), spread(w, h);
    Image<float> cos_half((w + 1) / 2, (h + 1) / 2), cos_full(w, h);
    for (int j = 0; j < model.height(); ++j) {
        for (int i = 0; i < model.width(); ++i) {
            model(i, j) =
                (i * 7 + j * 3) % 13 == 0 ? 0.0F : 0.5F + 0.02F * static_cast<float>(i + j);
            cos_half(i, j) = (i + 2 * j) % 9 == 0 ? 0.1F : 0.9F;
        }
    }
    for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
            spread(u, v) = model(u / 2, v / 2);
            cos_full(u, v) = cos_half(u / 2, v / 2);
            raw(u, v) = spread(u, v) * (1.0F + 0.001F * static_cast<float>((u * 5 + v) % 7 - 3));
        }
    }
    DistortionEstimator from_half(w, h, config), from_full(w, h, config);
    ASSERT_TRUE(from_half.addFrame(raw, model, cos_half).isOk());
    ASSERT_TRUE(from_full.addFrame(raw, spread, cos_full).isOk());
    ASSERT_GT(from_half.numSamples(), size_t{1000});
    EXPECT_EQ(from_half.numSamples(), from_full.numSamples());
    auto a = from_half.estimate();
    auto b = from_full.estimate();
    ASSERT_TRUE(a.isOk() && b.isOk());
    EXPECT_EQ(a->covered, b->covered);
    for (int y = 0; y < DistortionTable::kCellsPerSide; ++y) {
        for (int x = 0; x < DistortionTable::kCellsPerSide; ++x) {
            EXPECT_EQ(a->table.cell(x, y), b->table.cell(x, y)) << x << "," << y;
        }
    }
}

TEST(SelfCalibration, AClearedEstimatorFitsOnlyTheFramesAddedAfterwards) {
    // An odd number of samples per cell and segment (the fit sums them two at a time), and an
    // earlier frame 3 % off that clear() must forget.
    const int w = 161, h = 121;
    SelfCalibrationConfig config;
    config.compare_at_block_origin = false;
    config.min_samples = 4.0;
    DepthImage model(w, h), raw(w, h), earlier(w, h);
    for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
            model(u, v) = 0.7F + 0.015F * static_cast<float>((u + 2 * v) % 151);
            raw(u, v) = model(u, v) * (1.0F + 0.002F * static_cast<float>((u * 3 + v) % 5 - 2));
            earlier(u, v) = model(u, v) * 1.03F;
        }
    }
    DistortionEstimator reused(w, h, config), fresh(w, h, config);
    ASSERT_TRUE(reused.addFrame(earlier, model, Image<float>()).isOk());
    reused.clear();
    EXPECT_EQ(reused.numSamples(), size_t{0});
    ASSERT_TRUE(reused.addFrame(raw, model, Image<float>()).isOk());
    ASSERT_TRUE(fresh.addFrame(raw, model, Image<float>()).isOk());
    EXPECT_EQ(reused.numSamples(), fresh.numSamples());
    auto a = reused.estimate();
    auto b = fresh.estimate();
    ASSERT_TRUE(a.isOk() && b.isOk());
    EXPECT_EQ(a->covered, b->covered);
    EXPECT_EQ(a->outliers, b->outliers);
    for (int y = 0; y < DistortionTable::kCellsPerSide; ++y) {
        for (int x = 0; x < DistortionTable::kCellsPerSide; ++x) {
            ASSERT_EQ(a->table.cell(x, y), b->table.cell(x, y)) << x << "," << y;
        }
    }
}

TEST(SelfCalibration, FittedFactorsFollowTheSamplesAndTheGauge) {
    // Exact synthetic samples: a fronto-parallel sweep from 0.6 to 3.8 m seen through a table
    // whose factor rises linearly with depth; the fit recovers it up to the gauge (bin 0 mean 1).
    SelfCalibrationConfig config;
    config.compare_at_block_origin = false;
    const int w = 160, h = 120;
    DistortionEstimator estimator(w, h, config);
    for (int k = 0; k < 60; ++k) {
        const double z = 0.6 + 3.2 * k / 59.0;
        DepthImage model(w, h, static_cast<float>(z));
        DepthImage raw(w, h);
        for (int v = 0; v < h; ++v) {
            for (int u = 0; u < w; ++u) {
                const double f0 = 1.0 + 0.01 * u / w, f1 = f0 - 0.02;
                const double table[5] = {f0, f1, f1, f1, f1};  // flat beyond the data
                const Table::BinWeights b = Table::binWeights(z);
                const double f = (1 - b.a) * table[b.lo] + b.a * table[b.hi];
                raw(u, v) = static_cast<float>(z / f);
            }
        }
        ASSERT_TRUE(estimator.addFrame(raw, model, Image<float>()).isOk());
    }
    auto e = estimator.estimate();
    ASSERT_TRUE(e.isOk()) << e.status().toString();
    EXPECT_EQ(e->covered_cells[0], 6400);
    EXPECT_EQ(e->covered_cells[1], 6400);
    EXPECT_EQ(e->covered_cells[2], 0);
    const double mean_f0 = 1.0 + 0.01 * (79.5 / 80.0) / 2.0;  // over cells (pixel pairs)
    EXPECT_NEAR(e->gauge_scale, mean_f0, 2e-4);
    for (int x : {0, 40, 79}) {
        const double f0 = (1.0 + 0.01 * (2 * x + 0.5) / w) / e->gauge_scale;
        EXPECT_NEAR(e->table.cell(x, 10)[0], f0, 2e-4) << x;
        EXPECT_NEAR(e->table.cell(x, 10)[1], f0 - 0.02 / e->gauge_scale, 2e-4) << x;
        // Uncovered bins follow the nearest covered one.
        EXPECT_EQ(e->table.cell(x, 10)[2], e->table.cell(x, 10)[1]);
    }
}

TEST(SelfCalibration, ConfigIsDescribedAndChecked) {
    SelfCalibrationConfig c;
    c.max_iterations = 3;
    c.tsdf.voxel_size_m = 0.02F;
    const std::string toml = config::toToml(c);
    EXPECT_NE(toml.find("relaxation"), std::string::npos);
    EXPECT_NE(toml.find("[tsdf]"), std::string::npos);
    SelfCalibrationConfig back;
    ASSERT_TRUE(config::loadString(toml, "test", back).isOk());
    EXPECT_EQ(back.max_iterations, 3);
    EXPECT_EQ(back.tsdf.voxel_size_m, 0.02F);
    const Status unknown = config::loadString("min_sample = 3\n", "test.toml", back);
    ASSERT_FALSE(unknown.isOk());
    EXPECT_NE(unknown.message().find("min_sample"), std::string::npos);
    EXPECT_FALSE(config::applyOverrides({"relaxation=2.5"}, back).isOk());
    c.relaxation = 2.5;
    EXPECT_FALSE(validate(c).isOk());
}

TEST(DistortionTableWriter, ReadsBackTheSameFactors) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto table = Table::load(path);
    ASSERT_TRUE(table.isOk()) << table.status().toString();
    const std::filesystem::path out = plumb::testing::freshTempDir("dist_model_writer") / "t.txt";
    ASSERT_TRUE(table->save(out).isOk());
    auto back = Table::load(out);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    int invalid = 0;
    for (int y = 0; y < Table::kCellsPerSide; ++y) {
        for (int x = 0; x < Table::kCellsPerSide; ++x) {
            EXPECT_EQ(back->cell(x, y), table->cell(x, y)) << x << "," << y;
            invalid += table->cell(x, y)[0] == 0.0F ? 1 : 0;
        }
    }
    std::printf("%d invalid cells kept invalid\n", invalid);
    EXPECT_EQ(Table::neutral().format(), Table::parse(Table::neutral().format(), "t")->format());
    const Status unwritable = table->save("/nonexistent/dir/t.txt");
    ASSERT_FALSE(unwritable.isOk());
    EXPECT_NE(unwritable.message().find("/nonexistent/dir/t.txt"), std::string::npos);
}

}  // namespace
}  // namespace plumb::calibration
