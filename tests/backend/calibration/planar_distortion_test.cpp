// SPDX-License-Identifier: Apache-2.0
// The bend of the depth from the planes of each frame (backend/calibration/planar_distortion),
// without any pose: on the simulated scanner with a smooth distortion table (the measured Redwood
// table's degree-4 fit) the learned model matches it to a few hundredths of a per cent beyond the
// part planarity cannot see (an inverse factor affine over the image); with the measured table
// itself it removes most of the bend at 3 m and holds no scale growing with depth over the cells
// where the sensor has depth; on undistorted depth it stays neutral; results do not depend on the
// thread count; bad input gets specific errors.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "backend/calibration/planar_distortion.hpp"
#include "backend/calibration/self_calibration.hpp"
#include "common/camera/pinhole.hpp"
#include "tests/backend/calibration/simulated_depth.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::calibration {
namespace {

using Table = DistortionTable;

/// The table whose inverse factors are, per bin, the least-squares polynomial of degree 4 in
/// the image coordinates through those of `table`: its smooth part.
Table smoothPart(const Table& table) {
    const int n = Table::kCellsPerSide;
    auto at = [&](int x, int y) {
        const double u = (x + 0.5) / (n / 2.0) - 1.0, v = (y + 0.5) / (n / 2.0) - 1.0;
        Eigen::VectorXd row(15);
        int k = 0;
        for (int degree = 0; degree <= 4; ++degree) {
            for (int i = degree; i >= 0; --i) row[k++] = std::pow(u, i) * std::pow(v, degree - i);
        }
        return row;
    };
    std::vector<std::array<float, 5>> cells(static_cast<size_t>(n) * n);
    for (int bin = 0; bin < Table::kBins; ++bin) {
        Eigen::MatrixXd ata = Eigen::MatrixXd::Zero(15, 15);
        Eigen::VectorXd atb = Eigen::VectorXd::Zero(15);
        for (int y = 0; y < n; ++y) {
            for (int x = 0; x < n; ++x) {
                const double f = table.cell(x, y)[bin];
                if (f <= 0.0) continue;
                const Eigen::VectorXd r = at(x, y);
                ata += r * r.transpose();
                atb += r / f;
            }
        }
        const Eigen::VectorXd coefficients = ata.ldlt().solve(atb);
        for (int y = 0; y < n; ++y) {
            for (int x = 0; x < n; ++x) {
                const bool valid = table.cell(x, y)[bin] > 0.0F;
                cells[static_cast<size_t>(y) * n + x][bin] =
                    valid ? static_cast<float>(1.0 / at(x, y).dot(coefficients)) : 0.0F;
            }
        }
    }
    return Table::fromCells(std::move(cells));
}

Result<PlanarEstimate> learn(const std::vector<DepthImage>& depth, const PinholeCamera& camera,
                             const PlanarDistortionConfig& config) {
    PlanarDistortionEstimator estimator(camera, config);
    for (const DepthImage& d : depth) {
        if (Status s = estimator.addFrame(d); !s.isOk()) return s;
    }
    return estimator.estimate([](const PlanarIteration& it) {
        std::printf("  iteration %d: %zu segments, %zu blocks, residual %.2f sigmas, change %.5f\n",
                    it.iteration + 1, it.segments, it.blocks, it.rms_sigmas, it.max_change);
    });
}

/// 60 frames over the whole living-room loop (the two halves of a scan of half the loop
/// disagree) by the simulated sensor with the measured table at `path`; simulated once.
const std::vector<DepthImage>& measuredLoop(const std::filesystem::path& path,
                                            PinholeCamera* camera) {
    static PinholeCamera loop_camera;
    static const std::vector<DepthImage> depth =
        testing::simulateLivingRoom("redwood", path.string(), 600, 10, &loop_camera);
    *camera = loop_camera;
    return depth;
}

/// compareTables over every cell of the 1, 3 and 5 m bins.
TableComparison compare(const Table& learned, const Table& truth) {
    DistortionEstimate all;
    all.covered.assign(Table::kCellsPerSide * Table::kCellsPerSide, 0b111);
    auto c = compareTables(learned, all, truth);
    EXPECT_TRUE(c.isOk()) << c.status().toString();
    return c.isOk() ? *c : TableComparison{};
}

TEST(PlanarDistortion, LearnsASmoothBendExactlyWithoutPoses) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto measured = Table::load(path);
    ASSERT_TRUE(measured.isOk()) << measured.status().toString();
    const Table smooth = smoothPart(*measured);
    const std::filesystem::path smooth_path =
        testing::freshTempDir("planar_distortion_smooth") / "smooth.txt";
    ASSERT_TRUE(smooth.save(smooth_path).isOk());
    PinholeCamera camera;
    const std::vector<DepthImage> depth =
        testing::simulateLivingRoom("redwood", smooth_path.string(), 300, 5, &camera);
    ASSERT_EQ(depth.size(), 60U);
    auto estimate = learn(depth, camera, PlanarDistortionConfig{});
    ASSERT_TRUE(estimate.isOk()) << estimate.status().toString();
    const TableComparison c = compare(estimate->model.toTable(), smooth);
    for (int bin : {0, 1}) {
        const TableComparison::Bin& b = c.bins[static_cast<size_t>(bin)];
        std::printf("%.0f m: beyond the projective part %.4f %% (uncalibrated %.4f %%)\n",
                    Table::binCentreM(bin), 100.0 * b.median_error_beyond_projective,
                    100.0 * b.median_uncalibrated_beyond_projective);
        EXPECT_LT(b.median_error_beyond_projective, 0.0005) << "bin " << bin;
        EXPECT_GT(b.median_uncalibrated_beyond_projective, 0.001) << "bin " << bin;
    }
}

/// `table` with the factor of its 1 m bin tilted by 1 + tilt u (u the normalised image x).
Table tiltedNear(const Table& table, double tilt) {
    const int n = Table::kCellsPerSide;
    std::vector<std::array<float, 5>> cells(static_cast<size_t>(n) * n);
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) {
            std::array<float, 5>& c = cells[static_cast<size_t>(y) * n + x];
            for (int bin = 0; bin < Table::kBins; ++bin) c[bin] = table.cell(x, y)[bin];
            const double u = (x + 0.5) / (n / 2.0) - 1.0;
            if (c[0] > 0.0F) c[0] = static_cast<float>(c[0] * (1.0 + tilt * u));
        }
    }
    return Table::fromCells(std::move(cells));
}

/// The row (1, z, z u, z v) of a + z (b + c u + d v) at cell (x, y) of bin `bin`.
Eigen::Vector4d disparityAffineRow(int x, int y, int bin) {
    const int n = Table::kCellsPerSide;
    const double u = (x + 0.5) / (n / 2.0) - 1.0, v = (y + 0.5) / (n / 2.0) - 1.0;
    const double z = Table::binCentreM(bin);
    return Eigen::Vector4d(1.0, z, z * u, z * v);
}

/// The least-squares (a, b, c, d) of a + z (b + c u + d v) through value(x, y, bin) over the
/// 1 and 3 m bins, at the cells where `mask` has a factor in that bin.
template <class Value>
Eigen::Vector4d fitDisparityAffine(const Table& mask, const Value& value) {
    const int n = Table::kCellsPerSide;
    Eigen::Matrix4d ata = Eigen::Matrix4d::Zero();
    Eigen::Vector4d atb = Eigen::Vector4d::Zero();
    for (int bin : {0, 1}) {
        for (int y = 0; y < n; ++y) {
            for (int x = 0; x < n; ++x) {
                if (mask.cell(x, y)[bin] <= 0.0F) continue;
                const Eigen::Vector4d r = disparityAffineRow(x, y, bin);
                ata += r * r.transpose();
                atb += r * value(x, y, bin);
            }
        }
    }
    return ata.ldlt().solve(atb);
}

/// Per bin (1 and 3 m) the median over the image of |learned / truth - g|, g the least-squares
/// fit of a + z (b + c u + d v) to that ratio over both bins: the error beyond the part that
/// keeps planes planes.
std::array<double, 2> errorBeyondPlanePreserving(const Table& learned, const Table& truth) {
    const int n = Table::kCellsPerSide;
    auto ratio = [&](int x, int y, int bin) {
        return learned.cell(x, y)[bin] / truth.cell(x, y)[bin];
    };
    const Eigen::Vector4d g = fitDisparityAffine(truth, ratio);
    std::array<double, 2> out{};
    for (int bin : {0, 1}) {
        std::vector<double> e;
        for (int y = 0; y < n; ++y) {
            for (int x = 0; x < n; ++x) {
                if (truth.cell(x, y)[bin] <= 0.0F) continue;
                e.push_back(std::abs(ratio(x, y, bin) - disparityAffineRow(x, y, bin).dot(g)));
            }
        }
        std::nth_element(e.begin(), e.begin() + static_cast<long>(e.size() / 2), e.end());
        out[static_cast<size_t>(bin)] = e[e.size() / 2];
    }
    return out;
}

TEST(PlanarDistortion, LearnsATiltThatDoesNotGrowWithDepthWhenAskedTo) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto measured = Table::load(path);
    ASSERT_TRUE(measured.isOk()) << measured.status().toString();
    // The smooth bend plus a 0.6 % tilt across the image in the 1 m bin only: a tilt growing in
    // proportion to the depth would keep planes planes; this one bends every plane that spans
    // depths, and only the affine terms can hold it.
    const Table truth = tiltedNear(smoothPart(*measured), 0.006);
    const std::filesystem::path truth_path =
        testing::freshTempDir("planar_distortion_tilt") / "tilted.txt";
    ASSERT_TRUE(truth.save(truth_path).isOk());
    PinholeCamera camera;
    const std::vector<DepthImage> depth =
        testing::simulateLivingRoom("redwood", truth_path.string(), 600, 10, &camera);
    PlanarDistortionConfig with_affine;
    with_affine.estimate_affine = true;
    auto on = learn(depth, camera, with_affine);
    auto off = learn(depth, camera, PlanarDistortionConfig{});
    ASSERT_TRUE(on.isOk()) << on.status().toString();
    ASSERT_TRUE(off.isOk()) << off.status().toString();
    const std::array<double, 2> e_on = errorBeyondPlanePreserving(on->model.toTable(), truth);
    const std::array<double, 2> e_off = errorBeyondPlanePreserving(off->model.toTable(), truth);
    std::printf(
        "beyond the plane-preserving part, 1 m / 3 m: %.4f / %.4f %% with the affine "
        "terms, %.4f / %.4f %% without\n",
        100.0 * e_on[0], 100.0 * e_on[1], 100.0 * e_off[0], 100.0 * e_off[1]);
    EXPECT_GT(e_off[0], 0.001);  // the tilt is there, and the curved terms cannot hold it
    EXPECT_LT(e_on[0], 0.2 * e_off[0]);
    EXPECT_LT(e_on[0], 0.0003);
    EXPECT_LT(e_on[1], 0.0003);
}

TEST(PlanarDistortion, RemovesMostOfTheMeasuredTablesBendAtThreeMetres) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto measured = Table::load(path);
    ASSERT_TRUE(measured.isOk()) << measured.status().toString();
    PinholeCamera camera;
    const std::vector<DepthImage>& depth = measuredLoop(path, &camera);
    auto estimate = learn(depth, camera, PlanarDistortionConfig{});
    ASSERT_TRUE(estimate.isOk()) << estimate.status().toString();
    // The measured table holds cell-to-cell structure no smooth model has (0.26 % at 3 m around
    // its own degree-4 fit); the bend itself is what the planes show.
    const TableComparison c = compare(estimate->model.toTable(), *measured);
    const TableComparison::Bin& b = c.bins[1];
    std::printf("3 m: beyond the projective part %.4f %% (uncalibrated %.4f %%)\n",
                100.0 * b.median_error_beyond_projective,
                100.0 * b.median_uncalibrated_beyond_projective);
    EXPECT_LT(b.median_error_beyond_projective, 0.45 * b.median_uncalibrated_beyond_projective);
    EXPECT_EQ(estimate->estimated_bins & 0b11U, 0b11U);
}

/// The depth-proportional scale b of the least-squares fit f = a + z (b + c u + d v) of the
/// table's factors at 1 and 3 m over the cells valid in `mask` (per metre).
double depthScaleOver(const Table& table, const Table& mask) {
    return fitDisparityAffine(mask,
                              [&](int x, int y, int bin) { return table.cell(x, y)[bin]; })[1];
}

TEST(PlanarDistortion, SetsTheScaleGrowingWithDepthToZeroOverTheCellsWithDepth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto measured = Table::load(path);
    ASSERT_TRUE(measured.isOk()) << measured.status().toString();
    // The simulated sensor has no depth where the measured table has no factor (a border of
    // the image): planarity fixes nothing there, and the basis' gauge over the whole image
    // leaves the model a scale growing with depth over the cells the sensor does see.
    PinholeCamera camera;
    const std::vector<DepthImage>& depth = measuredLoop(path, &camera);
    PlanarDistortionConfig whole_image;
    whole_image.scale_gauge_over_data = false;
    auto over_data = learn(depth, camera, PlanarDistortionConfig{});
    auto over_image = learn(depth, camera, whole_image);
    ASSERT_TRUE(over_data.isOk()) << over_data.status().toString();
    ASSERT_TRUE(over_image.isOk()) << over_image.status().toString();
    const int n = Table::kCellsPerSide;
    size_t valid = 0;
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) valid += measured->cell(x, y)[0] > 0.0F;
    }
    const Table on = over_data->model.toTable(), off = over_image->model.toTable();
    const double b_on = depthScaleOver(on, *measured), b_off = depthScaleOver(off, *measured);
    const double b_truth = depthScaleOver(*measured, *measured);
    std::printf(
        "%zu cells with depth (%zu valid in the measured table); scale growing with depth over "
        "them: %+.4f %%/m gauged over them, %+.4f %%/m over the image, %+.4f %%/m in the "
        "measured table; removed %+.4f %%/m\n",
        over_data->cells_with_data, valid, 100.0 * b_on, 100.0 * b_off, 100.0 * b_truth,
        100.0 * over_data->removed_depth_scale_per_m);
    EXPECT_NEAR(static_cast<double>(over_data->cells_with_data), static_cast<double>(valid),
                0.01 * valid);
    EXPECT_LT(over_data->cells_with_data, static_cast<size_t>(n * n));
    EXPECT_EQ(over_image->cells_with_data, 0U);
    EXPECT_GT(std::abs(b_off), 3e-4);  // the bias is there without the gauge
    EXPECT_LT(std::abs(b_on), 2e-5);
    EXPECT_NEAR(over_data->removed_depth_scale_per_m, b_off, 2e-5);
    // Only the scale growing with depth changes: the 1 m bin is untouched (and with it the
    // global scale), the 3 m bin moves by the same 2 b in every cell.
    double max_near = 0.0, max_far = 0.0;
    const double two_b = 2.0 * over_data->removed_depth_scale_per_m;
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) {
            const double near = on.cell(x, y)[0] - off.cell(x, y)[0];
            const double far = on.cell(x, y)[1] - off.cell(x, y)[1] + two_b;
            max_near = std::max(max_near, std::abs(near));
            max_far = std::max(max_far, std::abs(far));
        }
    }
    EXPECT_LT(max_near, 1e-6);
    EXPECT_LT(max_far, 1e-6);
    // On this sensor the gauge over the cells with depth is also the nearer to the truth.
    EXPECT_LT(std::abs(b_on - b_truth), std::abs(b_off - b_truth));
}

TEST(PlanarDistortion, StaysNeutralOnUndistortedDepth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    PinholeCamera camera;
    const std::vector<DepthImage> depth =
        testing::simulateLivingRoom("undistorted", path.string(), 300, 10, &camera);
    auto estimate = learn(depth, camera, PlanarDistortionConfig{});
    ASSERT_TRUE(estimate.isOk()) << estimate.status().toString();
    const Table learned = estimate->model.toTable();
    const int n = Table::kCellsPerSide;
    for (int bin : {0, 1}) {
        std::vector<double> deviation;
        for (int y = 0; y < n; ++y) {
            for (int x = 0; x < n; ++x)
                deviation.push_back(std::abs(learned.cell(x, y)[bin] - 1.0));
        }
        std::sort(deviation.begin(), deviation.end());
        std::printf("%.0f m: median |learned - 1| %.4f %%\n", Table::binCentreM(bin),
                    100.0 * deviation[deviation.size() / 2]);
        EXPECT_LT(deviation[deviation.size() / 2], 0.0005) << "bin " << bin;
    }
}

TEST(PlanarDistortion, ResultsDoNotDependOnTheThreadCount) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    PinholeCamera camera;
    const std::vector<DepthImage> depth =
        testing::simulateLivingRoom("redwood", path.string(), 100, 10, &camera);
    std::vector<std::string> tables;
    for (int threads : {1, 2}) {
        PlanarDistortionConfig config;
        config.iterations = 2;
        config.max_split_disagreement = 0.0;  // 10 frames do not determine the bend
        config.num_threads = threads;
        auto estimate = learn(depth, camera, config);
        ASSERT_TRUE(estimate.isOk()) << estimate.status().toString();
        tables.push_back(estimate->model.toTable().format());
    }
    EXPECT_EQ(tables[0], tables[1]);
}

TEST(PlanarDistortion, BadInputGetsSpecificErrors) {
    const PinholeCamera camera = cameraPreset("ci").value();
    PlanarDistortionEstimator estimator(camera, PlanarDistortionConfig{});
    const Status size = estimator.addFrame(DepthImage(80, 60, 2.0F));
    EXPECT_EQ(size.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(size.message().find("a 80x60 frame from a 160x120 camera"), std::string::npos)
        << size.message();

    // No depth in range (and no frame at all): nothing to estimate from.
    ASSERT_TRUE(estimator.addFrame(DepthImage(camera.width, camera.height, 9.0F)).isOk());
    auto none = estimator.estimate();
    ASSERT_FALSE(none.isOk());
    EXPECT_EQ(none.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_NE(none.status().message().find("no frame holds a planar segment"), std::string::npos)
        << none.status().message();

    PlanarDistortionConfig bad;
    bad.normal_stencil = 40;
    EXPECT_NE(validate(bad).message().find("normal_stencil"), std::string::npos);
    bad = PlanarDistortionConfig{};
    bad.max_depth_m = 0.1;
    EXPECT_NE(validate(bad).message().find("min_depth_m < max_depth_m"), std::string::npos);
    EXPECT_TRUE(validate(PlanarDistortionConfig{}).isOk());
}

}  // namespace
}  // namespace plumb::calibration
