// SPDX-License-Identifier: Apache-2.0
// drivers/dataset: layout detection, frame listing, ground truth, intrinsics priorities and the
// specific errors for damaged folders. Real folders from ../shared/data, tiny synthetic folders
// written here with OpenCV.

#include <gtest/gtest.h>

#include <fmt/format.h>
#include <cmath>
#include <filesystem>

#include <fstream>
#include <iterator>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <string>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/image/image.hpp"
#include "drivers/dataset/dataset.hpp"
#include "drivers/dataset/depth_png.hpp"
#include "drivers/dataset/intrinsics_file.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::dataset {
namespace {

namespace fs = std::filesystem;

void writeText(const fs::path& path, const std::string& text) {
    fs::create_directories(path.parent_path());
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << text;
    ASSERT_TRUE(out.good()) << path;
}

/// A 16-bit depth image whose raw value at (u, v) is base + u + 7 v, with column 0 invalid.
cv::Mat rampDepth(int width, int height, int base) {
    cv::Mat m(height, width, CV_16UC1);
    for (int v = 0; v < height; ++v) {
        for (int u = 0; u < width; ++u) {
            m.at<uint16_t>(v, u) = u == 0 ? 0 : static_cast<uint16_t>(base + u + 7 * v);
        }
    }
    return m;
}

void writePng(const fs::path& path, const cv::Mat& image) {
    fs::create_directories(path.parent_path());
    ASSERT_TRUE(cv::imwrite(path.string(), image)) << path;
}

/// An 8-bit colour image (OpenCV's BGR order in memory) whose pixel (u, v) is R = red,
/// G = u mod 256, B = v mod 256: loaded in RGB order it must read back as {red, u, v}.
cv::Mat taggedColour(int width, int height, int red) {
    cv::Mat m(height, width, CV_8UC3);
    for (int v = 0; v < height; ++v) {
        for (int u = 0; u < width; ++u) {
            m.at<cv::Vec3b>(v, u) = cv::Vec3b(static_cast<uint8_t>(v), static_cast<uint8_t>(u),
                                              static_cast<uint8_t>(red));
        }
    }
    return m;
}

/// The red tag of a colour image written by taggedColour, after checking its G/B ramps.
int colourTag(const ColourImage& colour) {
    EXPECT_EQ(colour(7, 3), (Rgb8{colour(0, 0).r, 7, 3}));
    EXPECT_EQ(colour(colour.width() - 1, colour.height() - 1).g, (colour.width() - 1) % 256);
    EXPECT_EQ(colour(colour.width() - 1, colour.height() - 1).b, (colour.height() - 1) % 256);
    return colour(0, 0).r;
}

/// A tiny plumb-layout folder (depth.txt + intrinsics.json, 160x120, scale 1000).
fs::path writePlumbFolder(const std::string& name, const std::vector<std::string>& files) {
    const fs::path dir = plumb::testing::freshTempDir(name);
    writeText(dir / "intrinsics.json",
              R"({"width": 160, "height": 120, "fx": 131.25, "fy": 131.25, "cx": 79.5,)"
              R"( "cy": 59.5, "depth_scale": 1000})");
    std::string list = "# timestamp filename\n";
    for (size_t k = 0; k < files.size(); ++k) {
        list += std::to_string(10.0 + 0.1 * static_cast<double>(k)) + " " + files[k] + "\n";
    }
    writeText(dir / "depth.txt", list);
    return dir;
}

// ---------------------------------------------------------------------------------------------
// Real data.

TEST(DatasetReal, TumLoadsAllFramesWithInterpolatedGroundTruth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "tum-fr3-structure-notexture-far");
    const std::filesystem::path dir = path;
    auto source = DatasetSource::open(dir);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const DatasetInfo& info = (*source)->info();
    EXPECT_EQ(info.layout, Layout::kTumRgbd);
    EXPECT_EQ(info.frames.size(), 252u);
    EXPECT_EQ((*source)->size(), std::optional<size_t>(252));
    // "freiburg3" in depth.txt's comments selects the fr3 intrinsics.
    EXPECT_DOUBLE_EQ(info.camera.fx, 535.4);
    EXPECT_DOUBLE_EQ(info.camera.fy, 539.2);
    EXPECT_DOUBLE_EQ(info.depth_scale, 5000.0);

    // The motion capture starts at 1341836537.8070: the first four depth frames precede it by
    // more than the 0.02 s association tolerance and have no GT; every later frame has one.
    const double first_gt_s = 1341836537.8070;
    size_t expected_with_gt = 0;
    for (const auto& f : info.frames) {
        const bool covered = f.timestamp_s > first_gt_s - 0.02;
        expected_with_gt += covered ? 1 : 0;
        EXPECT_EQ(f.T_W_C_gt.has_value(), covered) << f.name;
    }
    EXPECT_EQ(expected_with_gt, 248u);
    EXPECT_EQ(info.framesWithGroundTruth(), 248u);
    EXPECT_EQ(info.framesWithColour(), 0u);  // this excerpt ships depth only
    std::printf("[ summary  ] %s\n", info.summary().c_str());

    // Frame 5 (537.823406) lies between GT samples 537.8183 and 537.8269: its position is their
    // linear blend to well under a millimetre (the two samples are 8.6 ms apart).
    const Eigen::Vector3d p_a(-1.2424, 1.9218, 1.0546), p_b(-1.2416, 1.9215, 1.0546);
    const double alpha =
        (1341836537.823406 - 1341836537.8183) / (1341836537.8269 - 1341836537.8183);
    ASSERT_TRUE(info.frames[5].T_W_C_gt.has_value());
    EXPECT_LT((info.frames[5].T_W_C_gt->translation() - (p_a + alpha * (p_b - p_a))).norm(), 1e-5);

    size_t min_valid = 640 * 480, max_valid = 0;
    for (size_t k = 0; k < 252; ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << k << ": " << frame.status().toString();
        EXPECT_EQ(frame->index, static_cast<int64_t>(k));
        EXPECT_EQ(frame->depth.width(), 640);
        EXPECT_EQ(frame->depth.height(), 480);
        EXPECT_EQ(frame->name, info.frames[k].name);
        EXPECT_DOUBLE_EQ(frame->timestamp_s, info.frames[k].timestamp_s);
        EXPECT_TRUE(frame->colour.empty());
        const size_t valid = countValid(frame->depth);
        min_valid = std::min(min_valid, valid);
        max_valid = std::max(max_valid, valid);
        // Kinect v1 range: every valid depth in (0.4, 10) m.
        for (float d : frame->depth.pixels()) {
            if (d > 0.0f) {
                ASSERT_TRUE(d > 0.4f && d < 10.0f) << frame->name << " " << d;
            }
        }
    }
    std::printf("[ valid px ] TUM min %zu max %zu of 307200\n", min_valid, max_valid);
    EXPECT_GT(min_valid, 640u * 480u / 2);  // textureless planes: the sensor sees most of them
    auto end = (*source)->next();
    ASSERT_FALSE(end.isOk());
    EXPECT_EQ(end.status().code(), StatusCode::kOutOfRange);
}

TEST(DatasetReal, IclNuimLoadsListedFramesWithIndexGroundTruth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "icl-nuim-office-kt0");
    const std::filesystem::path dir = path;
    auto source = openFrameSource("dataset:" + dir.string());
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    auto scanned = scanDataset(dir);
    ASSERT_TRUE(scanned.isOk()) << scanned.status().toString();
    const DatasetInfo& info = *scanned;
    EXPECT_EQ(info.layout, Layout::kIclNuim);
    EXPECT_DOUBLE_EQ(info.camera.fx, 481.20);
    EXPECT_DOUBLE_EQ(info.camera.fy, -480.00);
    EXPECT_DOUBLE_EQ(info.depth_scale, 5000.0);
    // depth.txt lists frames 2..101 (depth/1.png is present but unlisted and has no GT line).
    ASSERT_EQ(info.frames.size(), 100u);
    EXPECT_EQ((*source)->size(), std::optional<size_t>(100));
    EXPECT_EQ(info.framesWithGroundTruth(), 100u);
    EXPECT_EQ(info.framesWithColour(), 0u);
    std::printf("[ summary  ] %s\n", info.summary().c_str());
    for (size_t k = 0; k < info.frames.size(); ++k) {
        EXPECT_DOUBLE_EQ(info.frames[k].timestamp_s, static_cast<double>(k + 2));
    }
    // groundtruth.txt line "2 0.000472546 0.00897074 -2.5 ..." belongs to the first frame.
    EXPECT_LT(
        (info.frames[0].T_W_C_gt->translation() - Eigen::Vector3d(0.000472546, 0.00897074, -2.5))
            .norm(),
        1e-9);

    size_t min_valid = 640 * 480, max_valid = 0, min_in_room = 640 * 480;
    for (size_t k = 0; k < 100; ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << k << ": " << frame.status().toString();
        EXPECT_EQ(frame->depth.width(), 640);
        EXPECT_EQ(frame->depth.height(), 480);
        ASSERT_TRUE(frame->T_W_C_gt.has_value()) << frame->name;
        EXPECT_TRUE(frame->colour.empty());
        const size_t valid = countValid(frame->depth);
        min_valid = std::min(min_valid, valid);
        max_valid = std::max(max_valid, valid);
        // The noisy release has a few speckles near the camera; the room itself is 0.3-10 m away.
        size_t in_room = 0;
        for (float d : frame->depth.pixels()) in_room += (d > 0.3f && d < 10.0f) ? 1 : 0;
        EXPECT_GT(in_room, valid * 99 / 100) << frame->name;
        min_in_room = std::min(min_in_room, in_room);
    }
    std::printf("[ valid px ] ICL min %zu max %zu of 307200; min in 0.3-10 m %zu\n", min_valid,
                max_valid, min_in_room);
    EXPECT_GT(min_valid, 640u * 480u * 8 / 10);  // a closed synthetic room: nearly all valid
    EXPECT_EQ((*source)->next().status().code(), StatusCode::kOutOfRange);
}

// ---------------------------------------------------------------------------------------------
// Synthetic layouts.

TEST(DatasetSynthetic, RedwoodOrdersNumericallyAndReadsLogTrajectory) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-redwood");
    const std::vector<int> ids = {0, 1, 2, 10};  // numeric order, not "0 1 10 2"
    for (int id : ids)
        writePng(dir / "depth" / (std::to_string(id) + ".png"),
                 rampDepth(640, 480, 1000 * (id + 1)));
    // Camera->world poses for frames 0, 1, 2; frame 10 has no entry.
    std::string log;
    for (int id = 0; id < 3; ++id) {
        log += std::to_string(id) + " " + std::to_string(id) + " " + std::to_string(id + 1) + "\n";
        log += "1 0 0 " + std::to_string(0.5 * id) + "\n0 0 -1 0.25\n0 1 0 -1\n0 0 0 1\n";
    }
    writeText(dir / "trajectory.log", log);

    auto source = DatasetSource::open(dir);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const DatasetInfo& info = (*source)->info();
    EXPECT_EQ(info.layout, Layout::kRedwood);
    EXPECT_DOUBLE_EQ(info.camera.fx, 525.0);  // primesense default
    EXPECT_DOUBLE_EQ(info.depth_scale, 1000.0);
    ASSERT_EQ(info.frames.size(), 4u);
    EXPECT_EQ(info.framesWithGroundTruth(), 3u);
    for (size_t k = 0; k < ids.size(); ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        EXPECT_EQ(frame->name, "depth/" + std::to_string(ids[k]) + ".png");
        EXPECT_DOUBLE_EQ(frame->timestamp_s, ids[k]);
        // raw = 1000 (id + 1) + u + 7 v millimetres; column 0 invalid.
        EXPECT_FLOAT_EQ(frame->depth(3, 2), (1000.0f * (ids[k] + 1) + 3 + 14) / 1000.0f);
        EXPECT_EQ(frame->depth(0, 5), 0.0f);
        if (ids[k] < 3) {
            ASSERT_TRUE(frame->T_W_C_gt.has_value());
            Eigen::Matrix4d m;
            m << 1, 0, 0, 0.5 * ids[k], 0, 0, -1, 0.25, 0, 1, 0, -1, 0, 0, 0, 1;
            EXPECT_LT((frame->T_W_C_gt->matrix() - m).cwiseAbs().maxCoeff(), 1e-12);
        } else {
            EXPECT_FALSE(frame->T_W_C_gt.has_value());
        }
    }
}

TEST(DatasetSynthetic, SkipMovesPastAFrameWithoutReadingIt) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-skip");
    for (int id = 0; id < 4; ++id)
        writePng(dir / "depth" / (std::to_string(id) + ".png"),
                 rampDepth(640, 480, 1000 * (id + 1)));
    // Frame 1 is unreadable: skipping it is no error, reading it would be.
    writeText(dir / "depth" / "1.png", "not a png");
    auto source = DatasetSource::open(dir);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    ASSERT_TRUE((*source)->next().isOk());
    EXPECT_TRUE((*source)->skip().isOk());
    auto frame = (*source)->next();
    ASSERT_TRUE(frame.isOk()) << frame.status().toString();
    EXPECT_EQ(frame->name, "depth/2.png");
    EXPECT_FLOAT_EQ(frame->depth(3, 2), (3000.0f + 3 + 14) / 1000.0f);
    EXPECT_TRUE((*source)->skip().isOk());
    EXPECT_EQ((*source)->skip().code(), StatusCode::kOutOfRange);
}

TEST(DatasetSynthetic, SevenScenesMapsInvalidAndReadsPoseFiles) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-7scenes");
    for (int id = 0; id < 3; ++id) {
        cv::Mat depth = rampDepth(640, 480, 2000);
        depth.at<uint16_t>(10, 20) = 65535;  // 7-Scenes' invalid marker
        char stem[32];
        std::snprintf(stem, sizeof(stem), "frame-%06d", id);
        writePng(dir / (std::string(stem) + ".depth.png"), depth);
        writePng(dir / (std::string(stem) + ".color.png"),
                 cv::Mat(480, 640, CV_8UC3, cv::Scalar(1, 2, 3)));
        if (id == 1) {
            writeText(dir / (std::string(stem) + ".pose.txt"), "1 0 0\n0 nan 0\n");
        } else {
            writeText(dir / (std::string(stem) + ".pose.txt"),
                      "0 -1 0 " + std::to_string(id) + "\n1 0 0 2\n0 0 1 3\n0 0 0 1\n");
        }
    }
    auto source = DatasetSource::open(dir);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const DatasetInfo& info = (*source)->info();
    EXPECT_EQ(info.layout, Layout::kSevenScenes);
    EXPECT_DOUBLE_EQ(info.camera.fx, 585.0);
    EXPECT_DOUBLE_EQ(info.camera.cx, 320.0);
    EXPECT_DOUBLE_EQ(info.depth_scale, 1000.0);
    ASSERT_EQ(info.frames.size(), 3u);

    auto f0 = (*source)->next();
    ASSERT_TRUE(f0.isOk()) << f0.status().toString();
    EXPECT_EQ(f0->name, "frame-000000.depth.png");
    EXPECT_EQ(f0->depth(20, 10), 0.0f);  // 65535 -> invalid
    EXPECT_FLOAT_EQ(f0->depth(21, 10), (2000.0f + 21 + 70) / 1000.0f);
    ASSERT_TRUE(f0->T_W_C_gt.has_value());
    EXPECT_TRUE(f0->T_W_C_gt->translation().isApprox(Eigen::Vector3d(0, 2, 3)));
    EXPECT_TRUE(f0->T_W_C_gt->linear().isApprox(
        Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix()));

    auto f1 = (*source)->next();  // malformed pose file: an error for that frame only
    ASSERT_FALSE(f1.isOk());
    EXPECT_EQ(f1.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(f1.status().message().find("frame-000001.pose.txt"), std::string::npos)
        << f1.status().message();
    EXPECT_TRUE((*source)->canSkipErrors());

    auto f2 = (*source)->next();
    ASSERT_TRUE(f2.isOk()) << f2.status().toString();
    EXPECT_EQ(f2->index, 2);
    EXPECT_DOUBLE_EQ(f2->T_W_C_gt->translation().x(), 2.0);
}

TEST(DatasetSynthetic, PlumbLayoutTakesIntrinsicsFromFileAndOptionsOverride) {
    const fs::path dir = writePlumbFolder("dataset-plumb", {"depth/0.png"});
    writePng(dir / "depth/0.png", rampDepth(160, 120, 1500));
    writeText(dir / "groundtruth.txt", "10.0 1 2 3 0 0 0 1\n10.05 1 2 3 0 0 0 1\n");

    auto info = scanDataset(dir);
    ASSERT_TRUE(info.isOk()) << info.status().toString();
    EXPECT_EQ(info->layout, Layout::kPlumb);
    EXPECT_EQ(info->camera.width, 160);
    EXPECT_DOUBLE_EQ(info->camera.fx, 131.25);
    EXPECT_DOUBLE_EQ(info->depth_scale, 1000.0);
    EXPECT_EQ(info->framesWithGroundTruth(), 1u);
    auto frame = loadFrame(*info, 0);
    ASSERT_TRUE(frame.isOk()) << frame.status().toString();
    EXPECT_FLOAT_EQ(frame->depth(1, 1), 1.508f);

    // SourceOptions-style overrides: the depth scale option beats the file.
    DatasetConfig scale2000;
    scale2000.depth_scale = 2000.0;
    auto halved = scanDataset(dir, scale2000);
    ASSERT_TRUE(halved.isOk());
    EXPECT_DOUBLE_EQ(halved->depth_scale, 2000.0);
    EXPECT_FLOAT_EQ(loadFrame(*halved, 0)->depth(1, 1), 0.754f);

    // An intrinsics text file named by the option beats intrinsics.json.
    const fs::path text = dir / "cam.txt";
    writeText(text, "# width height fx fy cx cy\n160 120 100 -101 80 60\n");
    DatasetConfig from_text;
    from_text.intrinsics = text.string();
    auto overridden = scanDataset(dir, from_text);
    ASSERT_TRUE(overridden.isOk()) << overridden.status().toString();
    EXPECT_DOUBLE_EQ(overridden->camera.fy, -101.0);
    EXPECT_DOUBLE_EQ(overridden->depth_scale, 1000.0);  // still from intrinsics.json

    // A preset name works the same way; the wrong size then fails on the image.
    DatasetConfig preset;
    preset.intrinsics = "primesense";
    auto primesense = scanDataset(dir, preset);
    ASSERT_TRUE(primesense.isOk());
    EXPECT_EQ(primesense->camera.width, 640);
    auto wrong = loadFrame(*primesense, 0);
    ASSERT_FALSE(wrong.isOk());
    EXPECT_EQ(wrong.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(wrong.status().message().find("expected 640x480, got 160x120"), std::string::npos);

    DatasetConfig bogus;
    bogus.intrinsics = "no-such-camera";
    auto bad = scanDataset(dir, bogus);
    ASSERT_FALSE(bad.isOk());
    EXPECT_EQ(bad.status().code(), StatusCode::kNotFound);
    EXPECT_NE(bad.status().message().find("no-such-camera"), std::string::npos);

    // openFrameSource maps SourceOptions onto the same priorities (and bare folders work).
    SourceOptions options;
    options.intrinsics = "ci";
    options.depth_scale = 4000.0;
    auto src = openFrameSource(dir.string(), options);
    ASSERT_TRUE(src.isOk()) << src.status().toString();
    EXPECT_DOUBLE_EQ((*src)->camera().fx, 131.25);
    auto f = (*src)->next();
    ASSERT_TRUE(f.isOk()) << f.status().toString();
    EXPECT_FLOAT_EQ(f->depth(1, 1), 1508.0f / 4000.0f);
}

TEST(DatasetSynthetic, DetectionRuleSeparatesIclFromTum) {
    // Integer first columns in depth.txt and groundtruth.txt: ICL-NUIM.
    const fs::path icl = plumb::testing::freshTempDir("dataset-detect-icl");
    writeText(icl / "depth.txt", "0 depth/0.png\n1 depth/1.png\n");
    writeText(icl / "groundtruth.txt", "0 0 0 0 0 0 0 1\n1 0 0 0.1 0 0 0 1\n");
    auto a = scanDataset(icl);
    ASSERT_TRUE(a.isOk()) << a.status().toString();
    EXPECT_EQ(a->layout, Layout::kIclNuim);
    EXPECT_DOUBLE_EQ(a->camera.fy, -480.0);
    ASSERT_EQ(a->framesWithGroundTruth(), 2u);
    EXPECT_DOUBLE_EQ(a->frames[1].T_W_C_gt->translation().z(), 0.1);

    // Fractional stamps: TUM; "freiburg2" in a comment picks the fr2 intrinsics.
    const fs::path tum = plumb::testing::freshTempDir("dataset-detect-tum");
    writeText(tum / "depth.txt",
              "# file: 'rgbd_dataset_freiburg2_desk.bag'\n100.000 depth/a.png\n100.033 "
              "depth/b.png\n");
    writeText(tum / "groundtruth.txt", "99.99 0 0 0 0 0 0 1\n100.01 0 0 0.2 0 0 0 1\n");
    auto b = scanDataset(tum);
    ASSERT_TRUE(b.isOk()) << b.status().toString();
    EXPECT_EQ(b->layout, Layout::kTumRgbd);
    EXPECT_DOUBLE_EQ(b->camera.fx, 520.9);
    // Frame 100.000 is interpolated half way; 100.033 is 0.023 s past the last sample: no GT.
    ASSERT_TRUE(b->frames[0].T_W_C_gt.has_value());
    EXPECT_NEAR(b->frames[0].T_W_C_gt->translation().z(), 0.1, 1e-9);
    EXPECT_FALSE(b->frames[1].T_W_C_gt.has_value());

    // Integer depth indices but fractional GT stamps: not ICL (TUM rule), default primesense.
    const fs::path mixed = plumb::testing::freshTempDir("dataset-detect-mixed");
    writeText(mixed / "depth.txt", "1 depth/1.png\n");
    writeText(mixed / "groundtruth.txt", "1.0 0 0 0 0 0 0 1\n");
    auto c = scanDataset(mixed);
    ASSERT_TRUE(c.isOk()) << c.status().toString();
    EXPECT_EQ(c->layout, Layout::kTumRgbd);
    EXPECT_DOUBLE_EQ(c->camera.fx, 525.0);
    EXPECT_EQ(c->framesWithGroundTruth(), 1u);  // exact stamp via the association fallback
}

// ---------------------------------------------------------------------------------------------
// Colour.

TEST(DatasetReal, IclNuimKt3HasRegisteredColourForEveryFrame) {
    PLUMB_REQUIRE_SHARED_DATA(path, "icl-nuim-office-kt3-rgbd");
    const std::filesystem::path dir = path;
    auto source = openFrameSource("dataset:" + dir.string());
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    auto scanned = scanDataset(dir);
    ASSERT_TRUE(scanned.isOk()) << scanned.status().toString();
    const DatasetInfo& info = *scanned;
    EXPECT_EQ(info.layout, Layout::kIclNuim);
    ASSERT_EQ(info.frames.size(), 99u);
    EXPECT_EQ(info.framesWithColour(), 99u);
    EXPECT_EQ(info.framesWithGroundTruth(), 99u);
    EXPECT_TRUE(info.colour_registered);
    EXPECT_EQ(info.colour_source, "associations.txt");
    EXPECT_NE(info.summary().find("colour for 99 frames"), std::string::npos) << info.summary();
    std::printf("[ summary  ] %s\n", info.summary().c_str());
    EXPECT_EQ(info.frames[4].colour_path, dir / "rgb/5.png");

    double min_std = 1.0, max_std = 0.0;
    for (size_t k = 0; k < info.frames.size(); ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << k << ": " << frame.status().toString();
        ASSERT_EQ(frame->colour.width(), frame->depth.width()) << frame->name;
        ASSERT_EQ(frame->colour.height(), frame->depth.height()) << frame->name;
        // A textured office: intensity spread over the image, neither black nor saturated.
        const Image<float> gray = toIntensity(frame->colour);
        double sum = 0.0, sum2 = 0.0;
        for (float i : gray.pixels()) {
            sum += i;
            sum2 += double{i} * i;
        }
        const double n = static_cast<double>(gray.size());
        const double mean = sum / n;
        const double std = std::sqrt(std::max(0.0, sum2 / n - mean * mean));
        EXPECT_GT(mean, 0.1) << frame->name;
        EXPECT_LT(mean, 0.9) << frame->name;
        EXPECT_GT(std, 0.05) << frame->name;
        min_std = std::min(min_std, std);
        max_std = std::max(max_std, std);
        // Not a grey image stored as colour: the channels differ somewhere.
        size_t chromatic = 0;
        for (const Rgb8& c : frame->colour.pixels()) chromatic += (c.r != c.g || c.g != c.b);
        EXPECT_GT(chromatic, frame->colour.size() / 10) << frame->name;
    }
    std::printf("[ colour   ] kt3 intensity std min %.3f max %.3f\n", min_std, max_std);
    EXPECT_EQ((*source)->next().status().code(), StatusCode::kOutOfRange);

    // The same folder read with colour off: depth only, like a dataset without colour.
    DatasetConfig no_colour;
    no_colour.load_colour = false;
    auto depth_only = scanDataset(dir, no_colour);
    ASSERT_TRUE(depth_only.isOk());
    EXPECT_EQ(depth_only->framesWithColour(), 0u);
    EXPECT_NE(depth_only->summary().find("colour ignored"), std::string::npos);
    auto f0 = loadFrame(*depth_only, 0);
    ASSERT_TRUE(f0.isOk());
    EXPECT_TRUE(f0->colour.empty());
    SourceOptions options;
    options.colour = false;
    auto src = openFrameSource(dir.string(), options);
    ASSERT_TRUE(src.isOk());
    auto first = (*src)->next();
    ASSERT_TRUE(first.isOk());
    EXPECT_TRUE(first->colour.empty());
}

TEST(DatasetColour, TumAssociatesRgbByTimestampLikeAssociatePy) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-colour-tum");
    const std::vector<double> depth_stamps = {1.000, 1.033, 1.066, 1.100};
    std::string depth_txt = "# depth maps\n";
    for (size_t k = 0; k < depth_stamps.size(); ++k) {
        const std::string name = "depth/" + std::to_string(k) + ".png";
        writePng(dir / name, rampDepth(640, 480, 1000));
        depth_txt += fmt::format("{:.6f} {}\n", depth_stamps[k], name);
    }
    writeText(dir / "depth.txt", depth_txt);
    // Colour i is tagged 10 (i + 1). 1.005 is closest to 1.000 (0.005) and takes it, so 0.990
    // stays unused; 1.050 is closer to 1.066 (0.016) than to 1.033 (0.017): 1.033 gets nothing;
    // 1.085 pairs with 1.100 (0.015); 1.1205 is more than 0.02 s from everything.
    const std::vector<double> colour_stamps = {0.990, 1.005, 1.050, 1.085, 1.1205};
    std::string rgb_txt = "# colour images\n";
    for (size_t i = 0; i < colour_stamps.size(); ++i) {
        const std::string name = "rgb/" + std::to_string(i) + ".png";
        writePng(dir / name, taggedColour(640, 480, 10 * static_cast<int>(i + 1)));
        rgb_txt += fmt::format("{:.6f} {}\n", colour_stamps[i], name);
    }
    writeText(dir / "rgb.txt", rgb_txt);

    auto source = DatasetSource::open(dir);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const DatasetInfo& info = (*source)->info();
    EXPECT_EQ(info.layout, Layout::kTumRgbd);
    EXPECT_EQ(info.framesWithColour(), 3u);
    EXPECT_NE(info.summary().find("rgb.txt by timestamp within 0.02 s"), std::string::npos)
        << info.summary();
    const std::vector<int> expected_tag = {20, 0, 30, 40};  // 0 = no colour
    for (size_t k = 0; k < depth_stamps.size(); ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        if (expected_tag[k] == 0) {
            EXPECT_TRUE(frame->colour.empty()) << k;
            continue;
        }
        ASSERT_EQ(frame->colour.width(), 640) << k;
        ASSERT_EQ(frame->colour.height(), 480) << k;
        EXPECT_EQ(colourTag(frame->colour), expected_tag[k]) << k;
    }

    // A wider tolerance lets 0.990 pair too, but each colour image is still used once.
    DatasetConfig wide;
    wide.colour_max_difference_s = 0.05;
    auto wider = scanDataset(dir, wide);
    ASSERT_TRUE(wider.isOk()) << wider.status().toString();
    EXPECT_EQ(wider->framesWithColour(), 4u);
    std::set<fs::path> used;
    for (const auto& f : wider->frames) used.insert(f.colour_path);
    EXPECT_EQ(used.size(), 4u);
    DatasetConfig zero;
    zero.colour_max_difference_s = 0.0;
    EXPECT_EQ(scanDataset(dir, zero).status().code(), StatusCode::kInvalidArgument);
}

TEST(DatasetColour, IclUsesAssociationsThenRgbListThenRgbFolder) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-colour-icl");
    writeText(dir / "depth.txt", "0 depth/0.png\n1 depth/1.png\n2 depth/2.png\n");
    for (int k = 0; k < 3; ++k) {
        writePng(dir / ("depth/" + std::to_string(k) + ".png"), rampDepth(640, 480, 1000));
        writePng(dir / ("rgb/" + std::to_string(k) + ".png"), taggedColour(640, 480, 100 + k));
    }
    const auto tags = [&](const DatasetConfig& config = {}) {
        auto info = scanDataset(dir, config);
        EXPECT_TRUE(info.isOk()) << info.status().toString();
        std::vector<int> out;
        if (!info.isOk()) return out;
        EXPECT_EQ(info->layout, Layout::kIclNuim);
        for (size_t k = 0; k < info->frames.size(); ++k) {
            auto frame = loadFrame(*info, k);
            EXPECT_TRUE(frame.isOk()) << frame.status().toString();
            out.push_back(frame.isOk() && !frame->colour.empty() ? colourTag(frame->colour) : 0);
        }
        return out;
    };
    // associations.txt in the ICL-NUIM order (depth first) and deliberately crossed: it wins.
    writeText(dir / "associations.txt",
              "0 depth/0.png 2 rgb/2.png\n1 depth/1.png 1 rgb/1.png\n2 depth/2.png 0 rgb/0.png\n");
    writeText(dir / "rgb.txt", "0 rgb/0.png\n1 rgb/1.png\n2 rgb/2.png\n");
    EXPECT_EQ(tags(), (std::vector<int>{102, 101, 100}));
    // associate.py's order (colour first), frame 2 not paired: it has no colour.
    writeText(dir / "associations.txt",
              "# rgb depth\n1 rgb/0.png 0 depth/0.png\n"
              "1 rgb/1.png 1 depth/1.png\n5 rgb/2.png 5 depth/9.png\n");
    EXPECT_EQ(tags(), (std::vector<int>{100, 101, 0}));
    // Without associations.txt: rgb.txt, equal indices pair.
    fs::remove(dir / "associations.txt");
    writeText(dir / "rgb.txt", "2 rgb/2.png\n0 rgb/0.png\n1 rgb/1.png\n");
    EXPECT_EQ(tags(), (std::vector<int>{100, 101, 102}));
    // Without either list: rgb/N.png by frame index; a missing one is that frame's error.
    fs::remove(dir / "rgb.txt");
    EXPECT_EQ(tags(), (std::vector<int>{100, 101, 102}));
    fs::remove(dir / "rgb/1.png");
    auto source = DatasetSource::open(dir);
    ASSERT_TRUE(source.isOk());
    EXPECT_TRUE((*source)->next().isOk());
    auto missing = (*source)->next();
    ASSERT_FALSE(missing.isOk());
    EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
    EXPECT_NE(missing.status().message().find("rgb/1.png"), std::string::npos)
        << missing.status().message();
    auto after = (*source)->next();
    ASSERT_TRUE(after.isOk()) << after.status().toString();
    EXPECT_EQ(colourTag(after->colour), 102);
}

TEST(DatasetColour, PlumbSimOutputKeepsRgbOrderInTheFile) {
    // plumb sim writes rgb.txt + rgb/NNNNN.png with the same stamps as depth.txt.
    const fs::path dir =
        writePlumbFolder("dataset-colour-plumb", {"depth/00000.png", "depth/00001.png"});
    std::string rgb_txt = "# timestamp filename\n";
    for (int k = 0; k < 2; ++k) {
        writePng(dir / fmt::format("depth/{:05d}.png", k), rampDepth(160, 120, 1000));
        ColourImage colour(160, 120);
        for (int v = 0; v < 120; ++v) {
            for (int u = 0; u < 160; ++u) {
                colour(u, v) = Rgb8{static_cast<uint8_t>(200 + k), static_cast<uint8_t>(u),
                                    static_cast<uint8_t>(v)};
            }
        }
        const std::string name = fmt::format("rgb/{:05d}.png", k);
        fs::create_directories(dir / "rgb");
        ASSERT_TRUE(writeColourPng(dir / name, colour).isOk());
        rgb_txt += std::to_string(10.0 + 0.1 * k) + " " + name + "\n";
        // The file holds real RGB: OpenCV, which reads BGR, finds red in its third channel.
        const cv::Mat bgr = cv::imread((dir / name).string(), cv::IMREAD_UNCHANGED);
        ASSERT_EQ(bgr.type(), CV_8UC3);
        EXPECT_EQ(bgr.at<cv::Vec3b>(3, 7), cv::Vec3b(3, 7, static_cast<uint8_t>(200 + k)));
    }
    writeText(dir / "rgb.txt", rgb_txt);
    auto source = DatasetSource::open(dir);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_EQ((*source)->info().layout, Layout::kPlumb);
    EXPECT_EQ((*source)->info().framesWithColour(), 2u);
    for (int k = 0; k < 2; ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        EXPECT_EQ(colourTag(frame->colour), 200 + k);
    }
}

TEST(DatasetColour, SevenScenesColourIsUnregisteredAndResizedToTheDepth) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-colour-7scenes");
    for (int id = 0; id < 3; ++id) {
        const std::string stem = fmt::format("frame-{:06d}", id);
        writePng(dir / (stem + ".depth.png"), rampDepth(640, 480, 2000));
        if (id == 2) continue;  // frame 2 has no colour image
        // Half the depth's size: left half red, right half blue.
        cv::Mat colour(240, 320, CV_8UC3, cv::Scalar(0, 0, 255));
        colour(cv::Rect(160, 0, 160, 240)).setTo(cv::Scalar(255, 0, 0));
        writePng(dir / (stem + ".color.png"), colour);
    }
    auto source = DatasetSource::open(dir);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const DatasetInfo& info = (*source)->info();
    EXPECT_FALSE(info.colour_registered);
    EXPECT_EQ(info.framesWithColour(), 3u);
    EXPECT_NE(info.summary().find("not registered to depth"), std::string::npos) << info.summary();
    auto frame = (*source)->next();
    ASSERT_TRUE(frame.isOk()) << frame.status().toString();
    ASSERT_EQ(frame->colour.width(), 640);
    ASSERT_EQ(frame->colour.height(), 480);
    EXPECT_EQ(frame->colour(10, 10), (Rgb8{255, 0, 0}));
    EXPECT_EQ(frame->colour(630, 470), (Rgb8{0, 0, 255}));
    // The boundary blends over the two pixels that straddle it.
    EXPECT_EQ(frame->colour(318, 100), (Rgb8{255, 0, 0}));
    EXPECT_EQ(frame->colour(321, 100), (Rgb8{0, 0, 255}));
    ASSERT_TRUE((*source)->next().isOk());
    auto missing = (*source)->next();
    ASSERT_FALSE(missing.isOk());
    EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
    EXPECT_NE(missing.status().message().find("frame-000002.color.png"), std::string::npos)
        << missing.status().message();
}

TEST(DatasetColour, RedwoodPairsColourFoldersByNumber) {
    for (const std::string folder : {"color", "rgb", "image"}) {
        const fs::path dir = plumb::testing::freshTempDir("dataset-colour-redwood-" + folder);
        for (int id : {0, 1, 2, 10}) {
            writePng(dir / fmt::format("depth/{:06d}.png", id), rampDepth(640, 480, 1000));
        }
        writePng(dir / folder / "000000.png", taggedColour(640, 480, 50));
        writePng(dir / folder / "000001.png", taggedColour(640, 480, 51));
        // Redwood ships JPEG: lossy, so a uniform colour is compared with a tolerance.
        writePng(dir / folder / "000002.jpg", cv::Mat(480, 640, CV_8UC3, cv::Scalar(30, 90, 200)));
        auto source = DatasetSource::open(dir);
        ASSERT_TRUE(source.isOk()) << source.status().toString();
        EXPECT_EQ((*source)->info().layout, Layout::kRedwood);
        EXPECT_EQ((*source)->info().framesWithColour(), 3u);
        EXPECT_NE((*source)->info().summary().find(folder + "/ by number"), std::string::npos);
        auto f0 = (*source)->next();
        auto f1 = (*source)->next();
        auto f2 = (*source)->next();
        ASSERT_TRUE(f0.isOk() && f1.isOk() && f2.isOk()) << f2.status().toString();
        EXPECT_EQ(colourTag(f0->colour), 50);
        EXPECT_EQ(colourTag(f1->colour), 51);
        const Rgb8 c = f2->colour(320, 240);
        EXPECT_NEAR(c.r, 200, 3);
        EXPECT_NEAR(c.g, 90, 3);
        EXPECT_NEAR(c.b, 30, 3);
        auto f10 = (*source)->next();  // depth/000010.png has no colour image
        ASSERT_FALSE(f10.isOk());
        EXPECT_EQ(f10.status().code(), StatusCode::kNotFound);
        EXPECT_NE(f10.status().message().find("no colour image numbered 10"), std::string::npos)
            << f10.status().message();
    }
}

TEST(DatasetColourErrors, EachBadColourImageGetsItsSpecificErrorAndTheStreamGoesOn) {
    const std::vector<std::string> colour = {"rgb/good.png", "rgb/truncated.png", "rgb/gray.png",
                                             "rgb/deep.png", "rgb/small.png",     "rgb/missing.png",
                                             "rgb/text.png", "rgb/rgba.png"};
    std::vector<std::string> depth;
    for (size_t k = 0; k < colour.size(); ++k) depth.push_back(fmt::format("depth/{}.png", k));
    const fs::path dir = writePlumbFolder("dataset-colour-errors", depth);
    std::string rgb_txt;
    for (size_t k = 0; k < colour.size(); ++k) {
        writePng(dir / depth[k], rampDepth(160, 120, 800));
        rgb_txt += std::to_string(10.0 + 0.1 * static_cast<double>(k)) + " " + colour[k] + "\n";
    }
    writeText(dir / "rgb.txt", rgb_txt);
    writePng(dir / "rgb/good.png", taggedColour(160, 120, 1));
    writePng(dir / "rgb/truncated.png", taggedColour(160, 120, 2));
    fs::resize_file(dir / "rgb/truncated.png", fs::file_size(dir / "rgb/truncated.png") / 2);
    writePng(dir / "rgb/gray.png", cv::Mat(120, 160, CV_8UC1, cv::Scalar(7)));
    writePng(dir / "rgb/deep.png", cv::Mat(120, 160, CV_16UC3, cv::Scalar(1, 2, 3)));
    writePng(dir / "rgb/small.png", taggedColour(80, 60, 3));
    writeText(dir / "rgb/text.png", "this is not an image\n");
    cv::Mat rgba(120, 160, CV_8UC4, cv::Scalar(5, 6, 7, 128));
    writePng(dir / "rgb/rgba.png", rgba);

    auto source = openFrameSource("dataset:" + dir.string());
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    struct Expected {
        StatusCode code;
        std::vector<std::string> fragments;
    };
    const std::vector<Expected> expected = {
        {StatusCode::kOk, {}},
        {StatusCode::kCorrupt, {"truncated.png", "cannot decode"}},
        {StatusCode::kCorrupt, {"gray.png", "expected 3 channels (RGB), got 1"}},
        {StatusCode::kCorrupt, {"deep.png", "expected 8-bit colour, got 16-bit"}},
        {StatusCode::kCorrupt, {"small.png", "expected 160x120, got 80x60"}},
        {StatusCode::kNotFound, {"missing.png", "does not exist"}},
        {StatusCode::kCorrupt, {"text.png", "not a PNG or JPEG"}},
        {StatusCode::kOk, {}},
    };
    for (size_t k = 0; k < expected.size(); ++k) {
        auto frame = (*source)->next();
        EXPECT_EQ(frame.status().code(), expected[k].code)
            << "frame " << k << ": " << frame.status().toString();
        for (const auto& fragment : expected[k].fragments) {
            EXPECT_NE(frame.status().message().find(fragment), std::string::npos)
                << "frame " << k << ": '" << frame.status().message() << "' lacks '" << fragment
                << "'";
        }
        if (k == 7 && frame.isOk()) {
            // RGBA: the alpha is dropped, the colour kept in RGB order.
            EXPECT_EQ(frame->colour(5, 5), (Rgb8{7, 6, 5}));
        }
    }
    EXPECT_EQ((*source)->next().status().code(), StatusCode::kOutOfRange);
}

TEST(DatasetColourErrors, MalformedColourListsNameFileAndLine) {
    const fs::path dir = writePlumbFolder("dataset-colour-lists", {"depth/0.png", "depth/1.png"});
    writeText(dir / "rgb.txt", "10.0 rgb/0.png\nnot a line at all\n");
    auto garbage = scanDataset(dir);
    ASSERT_FALSE(garbage.isOk());
    EXPECT_EQ(garbage.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(garbage.status().message().find("rgb.txt:2: expected 'timestamp path'"),
              std::string::npos)
        << garbage.status().message();
    writeText(dir / "rgb.txt", "# nothing\n");
    auto empty = scanDataset(dir);
    EXPECT_EQ(empty.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(empty.status().message().find("rgb.txt: lists no colour images"), std::string::npos)
        << empty.status().message();

    writeText(dir / "associations.txt", "10.0 depth/0.png 10.0\n");
    auto short_line = scanDataset(dir);
    EXPECT_EQ(short_line.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(short_line.status().message().find("associations.txt:1:"), std::string::npos)
        << short_line.status().message();
    writeText(dir / "associations.txt", "10.0 depth/7.png 10.0 rgb/7.png\n");
    auto unrelated = scanDataset(dir);
    EXPECT_EQ(unrelated.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(unrelated.status().message().find("pairs none of the depth images"),
              std::string::npos)
        << unrelated.status().message();
    writeText(dir / "associations.txt",
              "10.0 depth/0.png 10.0 rgb/0.png\n10.1 depth/0.png 10.1 rgb/1.png\n");
    auto twice = scanDataset(dir);
    EXPECT_EQ(twice.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(twice.status().message().find("associations.txt:2: pairs depth/0.png a second time"),
              std::string::npos)
        << twice.status().message();
    // With colour off, none of the colour files is read.
    DatasetConfig no_colour;
    no_colour.load_colour = false;
    EXPECT_TRUE(scanDataset(dir, no_colour).isOk());
}

TEST(DatasetColour, NoColourOptionAlsoAppliesToTheSimulator) {
    // The simulator cannot leave colour out itself: openFrameSource drops it, and the wrapped
    // source is still the simulator underneath (for its ground truth).
    SourceOptions options;
    options.intrinsics = "ci";
    options.max_frames = 2;
    options.sim_noise = "off";
    options.colour = false;
    auto source = openFrameSource("sim:living_room", options);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_NE((*source)->description().find("simulated scan"), std::string::npos);
    EXPECT_NE(dynamic_cast<const sim::SimSource*>(&(*source)->underlying()), nullptr);
    for (int k = 0; k < 2; ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        EXPECT_TRUE(frame->colour.empty());
        EXPECT_GT(countValid(frame->depth), frame->depth.size() / 3);
    }
    EXPECT_EQ((*source)->next().status().code(), StatusCode::kOutOfRange);
}

TEST(ColourPng, WriteReadRoundTripIsExactAndResizeInterpolates) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-colour-png");
    ColourImage colour(33, 17);
    for (int v = 0; v < 17; ++v) {
        for (int u = 0; u < 33; ++u) {
            colour(u, v) = Rgb8{static_cast<uint8_t>(u * 7), static_cast<uint8_t>(v * 13),
                                static_cast<uint8_t>(u + v)};
        }
    }
    ASSERT_TRUE(writeColourPng(dir / "c.png", colour).isOk());
    auto back = readColourImage(dir / "c.png");
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(*back, colour);
    auto exact = readColourImage(dir / "c.png", 33, 17, ColourSize::kExact);
    EXPECT_TRUE(exact.isOk());
    auto wrong = readColourImage(dir / "c.png", 32, 17, ColourSize::kExact);
    EXPECT_EQ(wrong.status().code(), StatusCode::kCorrupt);

    // 2x1 -> 4x1 with pixel centres aligned: the outer pixels clamp, the inner ones blend 3:1.
    ColourImage two(2, 1);
    two(0, 0) = Rgb8{0, 100, 200};
    two(1, 0) = Rgb8{200, 100, 0};
    const ColourImage four = resizeColour(two, 4, 1);
    EXPECT_EQ(four(0, 0), (Rgb8{0, 100, 200}));
    EXPECT_EQ(four(1, 0), (Rgb8{50, 100, 150}));
    EXPECT_EQ(four(2, 0), (Rgb8{150, 100, 50}));
    EXPECT_EQ(four(3, 0), (Rgb8{200, 100, 0}));
    EXPECT_EQ(resizeColour(colour, 33, 17), colour);
    auto resized = readColourImage(dir / "c.png", 66, 34, ColourSize::kResize);
    ASSERT_TRUE(resized.isOk());
    EXPECT_EQ(resized->width(), 66);
    EXPECT_EQ(resized->height(), 34);
}

// ---------------------------------------------------------------------------------------------
// Damaged folders.

/// Flips one byte inside the data of the first IDAT chunk of the PNG at `path`.
void damageIdat(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    in.close();
    const size_t idat = bytes.find("IDAT");
    ASSERT_NE(idat, std::string::npos) << path;
    ASSERT_LT(idat + 14, bytes.size());
    bytes[idat + 14] = static_cast<char>(bytes[idat + 14] ^ 0x5a);
    writeText(path, bytes);
}

TEST(DatasetErrors, LibpngMessagesGoIntoTheStatusNotToStderr) {
    const fs::path dir = testing::freshTempDir("dataset-libpng-messages");
    writePng(dir / "truncated.png", rampDepth(160, 120, 800));
    fs::resize_file(dir / "truncated.png", fs::file_size(dir / "truncated.png") / 2);
    writePng(dir / "damaged.png", rampDepth(160, 120, 800));
    damageIdat(dir / "damaged.png");
    writePng(dir / "colour.png", taggedColour(160, 120, 2));
    damageIdat(dir / "colour.png");

    ::testing::internal::CaptureStderr();
    const Result<Depth16Image> truncated = readDepthPng(dir / "truncated.png", 160, 120);
    const Result<Depth16Image> damaged = readDepthPng(dir / "damaged.png", 160, 120);
    const Result<ColourImage> colour = readColourImage(dir / "colour.png");
    const std::string err = ::testing::internal::GetCapturedStderr();

    EXPECT_EQ(err, "") << "libpng must not print";
    EXPECT_EQ(truncated.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(truncated.status().message().find("truncated.png: cannot decode PNG"),
              std::string::npos)
        << truncated.status().message();
    EXPECT_NE(truncated.status().message().find("the data ends early"), std::string::npos)
        << truncated.status().message();
    // libpng's own words (it names the chunk) are in the message.
    for (const Status& s : {damaged.status(), colour.status()}) {
        EXPECT_EQ(s.code(), StatusCode::kCorrupt) << s.toString();
        EXPECT_NE(s.message().find(".png: cannot decode PNG"), std::string::npos) << s.message();
        EXPECT_NE(s.message().find("IDAT: "), std::string::npos) << s.message();
    }
}

TEST(DatasetErrors, EachBadFrameGetsItsSpecificErrorAndTheStreamGoesOn) {
    const fs::path dir = writePlumbFolder(
        "dataset-errors",
        {"depth/good.png", "depth/truncated.png", "depth/eight.png", "depth/small.png",
         "depth/missing.png", "depth/rgb16.png", "depth/text.png", "depth/good2.png"});
    writePng(dir / "depth/good.png", rampDepth(160, 120, 800));
    writePng(dir / "depth/truncated.png", rampDepth(160, 120, 800));
    fs::resize_file(dir / "depth/truncated.png", fs::file_size(dir / "depth/truncated.png") / 2);
    writePng(dir / "depth/eight.png", cv::Mat(120, 160, CV_8UC1, cv::Scalar(7)));
    writePng(dir / "depth/small.png", rampDepth(80, 60, 800));
    writePng(dir / "depth/rgb16.png", cv::Mat(120, 160, CV_16UC3, cv::Scalar(1, 2, 3)));
    writeText(dir / "depth/text.png", "this is not an image\n");
    writePng(dir / "depth/good2.png", rampDepth(160, 120, 900));

    auto source = openFrameSource("dataset:" + dir.string());
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_TRUE((*source)->canSkipErrors());
    struct Expected {
        StatusCode code;
        std::vector<std::string> fragments;  // all must appear in the message
    };
    const std::vector<Expected> expected = {
        {StatusCode::kOk, {}},
        {StatusCode::kCorrupt, {"truncated.png", "cannot decode"}},
        {StatusCode::kCorrupt, {"eight.png", "expected 16-bit depth, got 8-bit"}},
        {StatusCode::kCorrupt, {"small.png", "expected 160x120, got 80x60"}},
        {StatusCode::kNotFound, {"missing.png", "does not exist"}},
        {StatusCode::kCorrupt, {"rgb16.png", "expected 1 channel, got 3"}},
        {StatusCode::kCorrupt, {"text.png", "not a PNG"}},
        {StatusCode::kOk, {}},
    };
    for (size_t k = 0; k < expected.size(); ++k) {
        auto frame = (*source)->next();
        EXPECT_EQ(frame.status().code(), expected[k].code)
            << "frame " << k << ": " << frame.status().toString();
        for (const auto& fragment : expected[k].fragments) {
            EXPECT_NE(frame.status().message().find(fragment), std::string::npos)
                << "frame " << k << ": '" << frame.status().message() << "' lacks '" << fragment
                << "'";
        }
        if (frame.isOk()) {
            EXPECT_EQ(frame->index, static_cast<int64_t>(k));
        }
    }
    auto good2 = loadFrame(dynamic_cast<DatasetSource&>(**source).info(), 7);
    ASSERT_TRUE(good2.isOk());
    EXPECT_FLOAT_EQ(good2->depth(1, 0), 0.901f);
    EXPECT_EQ((*source)->next().status().code(), StatusCode::kOutOfRange);
}

TEST(DatasetErrors, EmptyDepthList) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-empty-list");
    writeText(dir / "depth.txt", "# depth maps\n# timestamp filename\n\n");
    auto info = scanDataset(dir);
    ASSERT_FALSE(info.isOk());
    EXPECT_EQ(info.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(info.status().message().find("depth.txt: lists no depth frames"), std::string::npos)
        << info.status().message();
}

TEST(DatasetErrors, GarbageLineInDepthList) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-garbage");
    writeText(dir / "depth.txt", "# header\n1.0 depth/1.png\nhello world again\n2.0 depth/2.png\n");
    auto info = scanDataset(dir);
    ASSERT_FALSE(info.isOk());
    EXPECT_EQ(info.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(info.status().message().find(
                  "depth.txt:3: expected 'timestamp path', got 'hello world again'"),
              std::string::npos)
        << info.status().message();

    writeText(dir / "depth.txt", "1.0 depth/1.png\nnot-a-number depth/2.png\n");
    auto stamp = scanDataset(dir);
    EXPECT_EQ(stamp.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(stamp.status().message().find("depth.txt:2:"), std::string::npos);
}

TEST(DatasetErrors, UnsupportedAndMissingFolders) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-unsupported");
    writeText(dir / "README.txt", "nothing here\n");
    fs::create_directories(dir / "seq-01");
    auto info = scanDataset(dir);
    ASSERT_FALSE(info.isOk());
    EXPECT_EQ(info.status().code(), StatusCode::kUnsupported);
    for (const char* looked_for :
         {"depth.txt", "frame-XXXXXX.depth.png", "depth/*.png", ".log", "open one of them"}) {
        EXPECT_NE(info.status().message().find(looked_for), std::string::npos)
            << info.status().message();
    }
    auto missing = openFrameSource("dataset:" + (dir / "nope").string());
    ASSERT_FALSE(missing.isOk());
    EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
}

TEST(DatasetErrors, MalformedIntrinsicsAndGroundTruth) {
    const fs::path dir = writePlumbFolder("dataset-bad-intrinsics", {"depth/0.png"});
    writeText(dir / "intrinsics.json", R"({"width": 160, "height": 120, "fx": 131.25})");
    auto info = scanDataset(dir);
    ASSERT_FALSE(info.isOk());
    EXPECT_EQ(info.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(info.status().message().find("intrinsics.json: missing field 'fy'"),
              std::string::npos)
        << info.status().message();

    writeText(dir / "intrinsics.json", "{ not json");
    EXPECT_EQ(scanDataset(dir).status().code(), StatusCode::kCorrupt);

    writeText(dir / "intrinsics.json",
              R"({"width": 160, "height": 120, "fx": 1, "fy": 1, "cx": 1, "cy": 1,)"
              R"( "depth_scale": -5})");
    EXPECT_EQ(scanDataset(dir).status().code(), StatusCode::kInvalidArgument);

    DatasetConfig negative_scale;
    negative_scale.depth_scale = -1.0;
    negative_scale.intrinsics = "ci";
    EXPECT_EQ(scanDataset(dir, negative_scale).status().code(), StatusCode::kInvalidArgument);

    // A NaN in the ground truth fails the scan with the reader's error (file named).
    writeText(dir / "intrinsics.json",
              R"({"width": 160, "height": 120, "fx": 1, "fy": 1, "cx": 1, "cy": 1})");
    writeText(dir / "groundtruth.txt", "10.0 nan 0 0 0 0 0 1\n");
    auto gt = scanDataset(dir);
    ASSERT_FALSE(gt.isOk());
    EXPECT_NE(gt.status().message().find("groundtruth.txt"), std::string::npos)
        << gt.status().message();
}

TEST(DepthPng, WriteReadRoundTripIsExact) {
    const fs::path dir = plumb::testing::freshTempDir("dataset-png");
    Depth16Image raw(33, 17);
    for (int v = 0; v < 17; ++v) {
        for (int u = 0; u < 33; ++u) raw(u, v) = static_cast<uint16_t>(u * 1931 + v * 7);
    }
    ASSERT_TRUE(writeDepthPng(dir / "x.png", raw).isOk());
    auto back = readDepthPng(dir / "x.png", 33, 17);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(*back, raw);

    ASSERT_TRUE(
        writeIntrinsicsJson(dir / "k.json", PinholeCamera{33, 17, 20.5, -21.25, 16, 8}, 5000.0)
            .isOk());
    auto k = readIntrinsicsFile(dir / "k.json", PinholeCamera{});
    ASSERT_TRUE(k.isOk()) << k.status().toString();
    EXPECT_EQ(k->camera.width, 33);
    EXPECT_DOUBLE_EQ(k->camera.fy, -21.25);
    EXPECT_EQ(k->depth_scale, std::optional<double>(5000.0));
}

}  // namespace
}  // namespace plumb::dataset
