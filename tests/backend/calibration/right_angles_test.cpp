// SPDX-License-Identifier: Apache-2.0
// The part of the depth distortion that keeps planes planes, from the right angles of the room
// (backend/calibration/right_angles): on the simulated scanner whose depth carries a disparity
// offset (1 / z_measured = 1 / z + delta . (x, y, 1)), which planarity cannot see, the angles
// between each frame's planes give delta back; on undistorted depth it stays near zero; the
// table correction removes exactly such an offset; bad input gets specific errors.

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "backend/calibration/planar_distortion.hpp"
#include "backend/calibration/right_angles.hpp"
#include "common/camera/pinhole.hpp"
#include "tests/backend/calibration/simulated_depth.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::calibration {
namespace {

/// The planes of every frame, the depth taken as it is (the neutral model).
std::vector<std::vector<SegmentPlane>> planesOf(const std::vector<DepthImage>& depth,
                                                const PinholeCamera& camera, int num_threads = 0) {
    PlanarDistortionConfig config;
    config.num_threads = num_threads;
    PlanarDistortionEstimator estimator(camera, config);
    for (const DepthImage& d : depth) EXPECT_TRUE(estimator.addFrame(d).isOk());
    return estimator.framePlanes(PlanarDistortion{});
}

/// The sensor table of a pure disparity offset: f = 1 + z delta . (x, y, 1) at each bin centre
/// (exact between bins: f is linear in z), so 1 / z_measured = f / z = 1 / z + delta . (x, y, 1).
DistortionTable offsetTable(const Eigen::Vector3d& delta, const PinholeCamera& camera) {
    const int n = DistortionTable::kCellsPerSide;
    std::vector<std::array<float, 5>> cells(static_cast<size_t>(n) * n);
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) {
            const Eigen::Vector3d ray(((x + 0.5) * 8.0 - camera.cx) / camera.fx,
                                      ((y + 0.5) * 6.0 - camera.cy) / camera.fy, 1.0);
            for (int b = 0; b < DistortionTable::kBins; ++b) {
                cells[static_cast<size_t>(y) * n + x][b] =
                    static_cast<float>(1.0 + DistortionTable::binCentreM(b) * delta.dot(ray));
            }
        }
    }
    return DistortionTable::fromCells(std::move(cells));
}

TEST(RightAngles, RecoverADisparityOffsetThatPlanarityCannotSee) {
    PinholeCamera camera = cameraPreset("primesense").value();
    const Eigen::Vector3d truth(0.001, 0.0025, 0.0015);  // per metre, Redwood's order
    const std::filesystem::path table_path =
        testing::freshTempDir("right_angles_offset") / "offset.txt";
    ASSERT_TRUE(offsetTable(truth, camera).save(table_path).isOk());
    const std::vector<DepthImage> depth =
        testing::simulateLivingRoom("redwood", table_path.string(), 300, 5, &camera);
    ASSERT_EQ(depth.size(), 60U);
    auto estimate = estimateRightAngles(planesOf(depth, camera), RightAngleConfig{});
    ASSERT_TRUE(estimate.isOk()) << estimate.status().toString();
    const DisparityOffset& d = estimate->delta;
    std::printf(
        "delta true (%.5f %.5f %.5f), learned at 1 m (%.5f %.5f %.5f), at 3 m (%.5f %.5f "
        "%.5f) from %zu perpendicular and %zu parallel pairs in %zu frames; RMS %.3f -> "
        "%.3f deg, observation %.3f\n",
        truth.x(), truth.y(), truth.z(), d.near.x(), d.near.y(), d.near.z(), d.far.x(), d.far.y(),
        d.far.z(), estimate->perpendicular, estimate->parallel, estimate->frames,
        estimate->rms_before_deg, estimate->rms_after_deg, estimate->observation);
    EXPECT_EQ(d.near, d.far);  // one offset for all depths, the default
    EXPECT_LT((d.near - truth).norm(), 0.2 * truth.norm());
    // The offsets at 1 m and at 3 m apart: each the sensor's within the same bound.
    RightAngleConfig by_depth;
    by_depth.depth_dependent = true;
    auto two = estimateRightAngles(planesOf(depth, camera), by_depth);
    ASSERT_TRUE(two.isOk()) << two.status().toString();
    std::printf("by depth: at 1 m (%.5f %.5f %.5f), at 3 m (%.5f %.5f %.5f)\n", two->delta.near.x(),
                two->delta.near.y(), two->delta.near.z(), two->delta.far.x(), two->delta.far.y(),
                two->delta.far.z());
    EXPECT_LT((two->delta.near - truth).norm(), 0.2 * truth.norm());
    EXPECT_LT((two->delta.far - truth).norm(), 0.2 * truth.norm());
    // The tilts alone, the uniform part held at 0 (this sensor has one, which the tilts then
    // cannot hold: only that the fit improves the angles is checked).
    RightAngleConfig tilts;
    tilts.estimate_uniform = false;
    auto tilt = estimateRightAngles(planesOf(depth, camera), tilts);
    ASSERT_TRUE(tilt.isOk()) << tilt.status().toString();
    EXPECT_EQ(tilt->delta.near.z(), 0.0);
    EXPECT_LT(tilt->rms_after_deg, tilt->rms_before_deg);
    // The planes, and so the offset, do not depend on the thread count.
    auto serial = estimateRightAngles(planesOf(depth, camera, 1), RightAngleConfig{});
    ASSERT_TRUE(serial.isOk()) << serial.status().toString();
    EXPECT_EQ(serial->delta.near, d.near);
    EXPECT_EQ(serial->delta.far, d.far);
    EXPECT_LT(estimate->rms_after_deg, estimate->rms_before_deg);
    // The sensor's own offset removed from the neutral table undistorts its depth: the table of
    // 1 + z offset, the sensor's.
    const DistortionTable removal =
        removeDisparityOffset(DistortionTable::neutral(), DisparityOffset{truth, truth}, camera);
    const DistortionTable sensor = offsetTable(truth, camera);
    for (int y = 0; y < DistortionTable::kCellsPerSide; y += 7) {
        for (int x = 0; x < DistortionTable::kCellsPerSide; x += 7) {
            for (int b = 0; b < DistortionTable::kBins; ++b) {
                EXPECT_NEAR(removal.cell(x, y)[b], sensor.cell(x, y)[b], 1e-6);
            }
        }
    }
}

TEST(RightAngles, StaysNearZeroOnUndistortedDepth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    PinholeCamera camera;
    const std::vector<DepthImage> depth =
        testing::simulateLivingRoom("undistorted", path.string(), 300, 5, &camera);
    auto estimate = estimateRightAngles(planesOf(depth, camera), RightAngleConfig{});
    ASSERT_TRUE(estimate.isOk()) << estimate.status().toString();
    const DisparityOffset& d = estimate->delta;
    std::printf(
        "undistorted: delta at 1 m (%.5f %.5f %.5f), at 3 m (%.5f %.5f %.5f), RMS %.3f -> "
        "%.3f deg\n",
        d.near.x(), d.near.y(), d.near.z(), d.far.x(), d.far.y(), d.far.z(),
        estimate->rms_before_deg, estimate->rms_after_deg);
    EXPECT_LT(d.near.norm(), 5e-4);
    EXPECT_LT(d.far.norm(), 5e-4);
}

TEST(RightAngles, BadInputGetsSpecificErrors) {
    const auto none = estimateRightAngles({}, RightAngleConfig{});
    ASSERT_FALSE(none.isOk());
    EXPECT_EQ(none.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_NE(none.status().message().find("perpendicular"), std::string::npos);
    // Parallel planes alone (at different distances) do not make an estimate.
    SegmentPlane floor, table;
    floor.normal = table.normal = Eigen::Vector3d(0.0, -1.0, 0.0);
    floor.distance = -1.4;
    table.distance = -0.7;
    floor.blocks = table.blocks = 500;
    const std::vector<std::vector<SegmentPlane>> parallel(100, {floor, table});
    const auto only_parallel = estimateRightAngles(parallel, RightAngleConfig{});
    ASSERT_FALSE(only_parallel.isOk());
    EXPECT_EQ(only_parallel.status().code(), StatusCode::kFailedPrecondition);
    RightAngleConfig bad;
    bad.max_off_deg = 60.0;
    EXPECT_EQ(estimateRightAngles({}, bad).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace plumb::calibration
