// SPDX-License-Identifier: Apache-2.0
// Depth calibration (common/calibration/depth_calibration, drivers/calibrated_source):
// undistorting with the CLAMS / Redwood table inverts the sensor model's step A.3 (reference
// §1.4), and sources get it as documented.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "drivers/calibrated_source.hpp"
#include "drivers/sim/noise.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

/// The Redwood noise pipeline with only the distortion table on: no jitter, no disparity noise,
/// quantisation too fine to matter, no missing data.
sim::NoiseConfig tableOnly() {
    sim::NoiseConfig c;
    c.distortion = sim::DistortionKind::kTable;
    c.jitter_std_px = 0.0;
    c.disparity_noise_std = 0.0;
    c.disparity_subpixel_steps = 1e7;
    c.missing_data = false;
    c.min_depth_m = 0.0;
    c.max_depth_m = 0.0;
    return c;
}

TEST(DepthCalibration, UndistortingTheSimulatedSensorGivesBackTheTrueDepth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto table = DistortionTable::load(path);
    ASSERT_TRUE(table.isOk()) << table.status().toString();
    auto calibration = DepthCalibration::load(path);
    ASSERT_TRUE(calibration.isOk()) << calibration.status().toString();
    const sim::DepthNoiseModel sensor(tableOnly(), *table, 319.5, 239.5);
    for (const float z : {0.8F, 1.7F, 3.0F, 4.5F}) {
        // A slanted plane: depth z at the left edge, z + 0.6 m at the right, constant along
        // 2x2 blocks so that the sensor's block sampling does not move it.
        DepthImage truth(640, 480);
        for (int v = 0; v < 480; ++v) {
            for (int u = 0; u < 640; ++u)
                truth(u, v) = z + 0.6F * static_cast<float>(u - u % 2) / 640;
        }
        const DepthImage measured = sensor.apply(truth, {}, 1, 0);
        const DepthImage undistorted = calibration->undistort(measured);
        double max_bend = 0.0, max_error = 0.0;
        size_t valid = 0;
        for (int v = 0; v < 480; ++v) {
            for (int u = 0; u < 640; ++u) {
                if (measured(u, v) <= 0.0F) {
                    EXPECT_EQ(undistorted(u, v), 0.0F);  // unmeasured cells stay invalid
                    continue;
                }
                ++valid;
                max_bend = std::max(max_bend, std::abs(double{measured(u, v)} - truth(u, v)));
                max_error = std::max(max_error, std::abs(double{undistorted(u, v)} - truth(u, v)));
            }
        }
        std::printf("z %.1f m: sensor bends up to %.1f mm, undistorted within %.4f mm (%zu px)\n",
                    z, max_bend * 1e3, max_error * 1e3, valid);
        EXPECT_GT(valid, 640U * 480U / 2);
        EXPECT_GT(max_bend, 0.005 * z);  // the table does bend the sensor's depth
        EXPECT_LT(max_error, 1e-4 * z);  // and the calibration takes the bend out
    }
}

TEST(DepthCalibration, UndistortionSolvesTheSensorModelExactlyAtEveryDepth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto table = DistortionTable::load(path);
    auto calibration = DepthCalibration::load(path);
    ASSERT_TRUE(table.isOk() && calibration.isOk());
    // Row v holds the true depth 0.2 + 11.8 v / 479 m (every piece of the factor, and beyond
    // both end bins); the last rows the bin centres themselves, where the pieces meet.
    const double centres[] = {1.0, 3.0, 5.0, 7.0, 9.0};
    auto trueDepth = [&](int v) {
        return v >= 470 ? centres[(v - 470) % 5] : 0.2 + 11.8 * v / 469;
    };
    DepthImage measured(640, 480);
    for (int v = 0; v < 480; ++v) {
        for (int u = 0; u < 640; ++u) {
            const float f = table->factor(u - u % 2, v - v % 2, trueDepth(v));
            measured(u, v) = f > 0.0F ? static_cast<float>(trueDepth(v) / f) : 0.0F;
        }
    }
    const DepthImage undistorted = calibration->undistort(measured);
    double worst = 0.0;
    for (int v = 0; v < 480; ++v) {
        for (int u = 0; u < 640; ++u) {
            if (measured(u, v) <= 0.0F) continue;
            const double d = trueDepth(v);
            worst = std::max(worst, std::abs(double{undistorted(u, v)} - d) / d);
        }
    }
    std::printf("0.2-12 m: undistorted depth within %.2g of the true depth (relative)\n", worst);
    EXPECT_LT(worst, 5e-7);  // float rounding of the measured depth and of the factor
}

TEST(DepthCalibration, ScalesAnyImageSizeToTheTableGrid) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto table = DistortionTable::load(path);
    auto calibration = DepthCalibration::load(path);
    ASSERT_TRUE(table.isOk() && calibration.isOk());
    // Measured depth d / f at 160x120 for a true depth of 2.5 m, f at the 2x2 block origin.
    DepthImage measured(160, 120);
    for (int v = 0; v < 120; ++v) {
        for (int u = 0; u < 160; ++u) {
            const float f = table->factor((u - u % 2) * 4, (v - v % 2) * 4, 2.5);  // block origin
            measured(u, v) = f > 0.0F ? 2.5F / f : 0.0F;
        }
    }
    const DepthImage undistorted = calibration->undistort(measured);
    for (int v = 0; v < 120; ++v) {
        for (int u = 0; u < 160; ++u) {
            if (measured(u, v) > 0.0F) {
                EXPECT_NEAR(undistorted(u, v), 2.5F, 2.5e-4) << u << "," << v;
            }
        }
    }
}

TEST(DepthCalibration, UndistortingTheBlockOriginsOnlyGivesTheSameDepthThere) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto calibration = DepthCalibration::load(path);
    ASSERT_TRUE(calibration.isOk());
    // Odd sizes (the last block is one pixel wide and high), depths 0.3-9.5 m, invalid pixels.
    for (const auto& [w, h] : {std::pair{640, 480}, std::pair{321, 241}}) {
        DepthImage measured(w, h);
        for (int v = 0; v < h; ++v) {
            for (int u = 0; u < w; ++u) {
                const bool invalid = (u * 7 + v * 3) % 11 == 0;
                measured(u, v) =
                    invalid ? 0.0F : static_cast<float>(0.3 + 9.2 * (u + v * w) / (w * h));
            }
        }
        const DepthImage full = calibration->undistort(measured);
        const DepthImage origins = calibration->undistortBlockOrigins(measured);
        ASSERT_EQ(origins.width(), (w + 1) / 2);
        ASSERT_EQ(origins.height(), (h + 1) / 2);
        int valid = 0;
        for (int j = 0; j < origins.height(); ++j) {
            for (int i = 0; i < origins.width(); ++i) {
                ASSERT_EQ(origins(i, j), full(2 * i, 2 * j))
                    << w << "x" << h << " " << i << "," << j;
                valid += origins(i, j) > 0.0F;
            }
        }
        EXPECT_GT(valid, origins.width() * origins.height() / 2);
    }
}

TEST(DepthCalibration, ARepeatedReadingIsUndistortedAsItsCellAndDepthSay) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto calibration = DepthCalibration::load(path);
    ASSERT_TRUE(calibration.isOk());
    // Readings quantised to 5 cm: runs of equal readings along rows, across cell boundaries
    // (every 8 px) and across invalid pixels; each pixel must get its own cell's depth.
    DepthImage measured(640, 480);
    for (int v = 0; v < 480; ++v) {
        for (int u = 0; u < 640; ++u) {
            const double z = 0.5 + 0.004 * u + 0.01 * v;
            measured(u, v) = (u + v) % 13 == 0 ? 0.0F : static_cast<float>(std::round(z * 20) / 20);
        }
    }
    const DepthImage undistorted = calibration->undistort(measured);
    int repeats = 0;
    for (int v = 0; v < 480; ++v) {
        for (int u = 0; u < 640; ++u) {
            const float m = measured(u, v);
            if (!(m > 0.0F)) {
                EXPECT_EQ(undistorted(u, v), 0.0F);
                continue;
            }
            repeats += u > 0 && measured(u - 1, v) == m;
            const double alone = calibration->undistortDepth(DistortionTable::cellX(u - u % 2),
                                                             DistortionTable::cellY(v - v % 2), m);
            ASSERT_EQ(undistorted(u, v), static_cast<float>(alone)) << u << "," << v;
        }
    }
    EXPECT_GT(repeats, 640 * 480 / 2);
}

TEST(DepthCalibration, BadFilesAndValuesAreClearErrors) {
    auto missing = DepthCalibration::load("/nonexistent/dist-model.txt");
    ASSERT_FALSE(missing.isOk());
    EXPECT_NE(missing.status().message().find("/nonexistent/dist-model.txt"), std::string::npos);
    EXPECT_TRUE(checkDepthCalibration("").isOk());
    EXPECT_TRUE(checkDepthCalibration("sensor").isOk());
    EXPECT_TRUE(checkDepthCalibration("none").isOk());
    const Status bad = checkDepthCalibration("/nonexistent/table.txt");
    ASSERT_FALSE(bad.isOk());
    EXPECT_NE(bad.message().find("/nonexistent/table.txt"), std::string::npos);
    SourceOptions options;
    options.depth_calibration = "/nonexistent/table.txt";
    EXPECT_FALSE(openFrameSource("sim:living_room", options).isOk());
}

TEST(DepthCalibration, TheSimulatedSensorIsCalibratedWithItsOwnTableUnlessToldOtherwise) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    SourceOptions options;
    options.max_frames = 3;
    options.intrinsics = "ci";
    struct Case {
        std::string noise, calibration;
        bool calibrated;
    };
    for (const Case& c :
         {Case{"", "", true}, Case{"redwood", "sensor", true}, Case{"redwood", "none", false},
          Case{"undistorted", "", false}, Case{"undistorted", path.string(), true}}) {
        options.sim_noise = c.noise;
        options.depth_calibration = c.calibration;
        auto source = openFrameSource("sim:living_room", options);
        ASSERT_TRUE(source.isOk()) << source.status().toString();
        const bool wrapped = dynamic_cast<CalibratedSource*>(source->get()) != nullptr;
        EXPECT_EQ(wrapped, c.calibrated) << c.noise << " / " << c.calibration;
        EXPECT_EQ(((*source)->description().find("depth calibrated") != std::string::npos),
                  c.calibrated);
        // The simulator stays reachable for its ground truth.
        EXPECT_NE(dynamic_cast<const sim::SimSource*>(&(*source)->underlying()), nullptr);
        size_t frames = 0;
        while ((*source)->next().isOk()) ++frames;
        EXPECT_EQ(frames, 3U);
    }
}

}  // namespace
}  // namespace plumb
