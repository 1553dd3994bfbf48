// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include "common/camera/pinhole.hpp"
#include "common/core/check.hpp"
#include "common/core/status.hpp"
#include "common/image/image.hpp"

namespace plumb {
namespace {

TEST(Status, CarriesCodeAndMessage) {
    const Status s = corrupt("depth/3.png: truncated");
    EXPECT_FALSE(s.isOk());
    EXPECT_EQ(s.code(), StatusCode::kCorrupt);
    EXPECT_EQ(s.toString(), "corrupt: depth/3.png: truncated");
    EXPECT_TRUE(Status::ok().isOk());
}

Result<int> parsePositive(int v) {
    if (v <= 0) return invalidArgument("not positive");
    return v;
}

TEST(Result, HoldsValueOrError) {
    auto good = parsePositive(3);
    ASSERT_TRUE(good.isOk());
    EXPECT_EQ(*good, 3);
    auto bad = parsePositive(-1);
    ASSERT_FALSE(bad.isOk());
    EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
}

TEST(CheckDeathTest, AbortsWithFileLineAndMessage) {
    EXPECT_DEATH(PLUMB_CHECK(1 + 1 == 3) << "arithmetic is "
                                         << "broken",
                 "core_test.cpp:[0-9]+: check failed: 1 \\+ 1 == 3arithmetic is broken");
}

TEST(DepthImage, RoundTripsThroughRawUnits) {
    Depth16Image raw(4, 2, 0);
    raw(0, 0) = 5000;   // 1 m at TUM scale
    raw(3, 1) = 12345;  // 2.469 m
    const DepthImage m = toMetres(raw, 5000.0);
    EXPECT_FLOAT_EQ(m(0, 0), 1.0f);
    EXPECT_FLOAT_EQ(m(3, 1), 2.469f);
    EXPECT_EQ(m(1, 0), 0.0f);
    EXPECT_EQ(countValid(m), 2u);
    EXPECT_EQ(toRaw(m, 5000.0), raw);
    // Range gating drops values outside [min, max].
    EXPECT_EQ(countValid(toMetres(raw, 5000.0, 1.5, 0.0)), 1u);
    EXPECT_EQ(countValid(toMetres(raw, 5000.0, 0.0, 1.5)), 1u);
}

TEST(PinholeCamera, ProjectUnprojectRoundTripWithNegativeFy) {
    for (const char* preset : {"primesense", "icl-nuim"}) {
        const PinholeCamera cam = cameraPreset(preset).value();
        const Eigen::Vector3d p = cam.unproject(100.25, 400.75, 2.5);
        EXPECT_DOUBLE_EQ(p.z(), 2.5);
        const Eigen::Vector2d uv = cam.project(p);
        EXPECT_NEAR(uv.x(), 100.25, 1e-9);
        EXPECT_NEAR(uv.y(), 400.75, 1e-9);
    }
    // With negative fy a point above the optical axis (y < 0 in camera frame) lands below cy.
    const PinholeCamera icl = cameraPreset("icl-nuim").value();
    EXPECT_GT(icl.project({0.0, -0.5, 2.0}).y(), icl.cy);
}

TEST(PinholeCamera, ScalingKeepsPixelCentres) {
    const PinholeCamera cam = cameraPreset("primesense").value();
    const PinholeCamera half = cam.scaled(0.5);
    EXPECT_EQ(half.width, 320);
    EXPECT_DOUBLE_EQ(half.cx, 159.5);
    // A 3-D point projects to the same continuous position, scaled about the image corner.
    const Eigen::Vector3d p(0.3, -0.2, 1.7);
    const Eigen::Vector2d full = cam.project(p), low = half.project(p);
    EXPECT_NEAR(low.x(), (full.x() + 0.5) * 0.5 - 0.5, 1e-9);
    EXPECT_FALSE(cameraPreset("nonsense").isOk());
    EXPECT_FALSE((PinholeCamera{0, 480, 525, 525, 1, 1}).validate().isOk());
}

}  // namespace
}  // namespace plumb
