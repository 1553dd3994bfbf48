// SPDX-License-Identifier: Apache-2.0
// Recording a scan while it runs (drivers/recording_source.hpp): the folder reads back through
// the dataset driver as the same frames (depth to the millimetre), stamps and ground truth; a cut
// off recording lists only whole frames; an existing recording is never overwritten.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "drivers/dataset/dataset.hpp"
#include "drivers/recording_source.hpp"
#include "drivers/sim/sim_source.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

std::unique_ptr<FrameSource> simulatedScan(size_t frames) {
    sim::SimConfig c;
    c.scene = "living_room";
    c.camera = *cameraPreset("ci");
    c.trajectory.num_frames = frames;
    c.noise.distortion = sim::DistortionKind::kParametric;  // no shared data needed
    c.seed = 3;
    auto source = sim::SimSource::create(c);
    EXPECT_TRUE(source.isOk()) << source.status().toString();
    return std::move(source).value();
}

/// Paints a colour image onto the frames of another source, as a colour camera would: pixel
/// (u, v) of frame k is {u + k, v, depth in cm}, so every frame and pixel differs. Frames whose
/// index is in `without` keep no colour (a colour frame the camera did not deliver).
class ColourPainter final : public FrameSourceDecorator {
  public:
    ColourPainter(std::unique_ptr<FrameSource> inner, std::vector<int64_t> without)
        : FrameSourceDecorator(std::move(inner)), without_(std::move(without)) {}
    Result<Frame> next() override {
        auto frame = inner().next();
        if (!frame.isOk()) return frame;
        const bool without =
            std::find(without_.begin(), without_.end(), frame->index) != without_.end();
        frame->colour = without ? ColourImage() : paint(*frame);
        return frame;
    }
    static ColourImage paint(const Frame& frame) {
        ColourImage colour(frame.depth.width(), frame.depth.height());
        for (int v = 0; v < colour.height(); ++v) {
            for (int u = 0; u < colour.width(); ++u) {
                colour(u, v) = Rgb8{static_cast<uint8_t>(u + frame.index), static_cast<uint8_t>(v),
                                    static_cast<uint8_t>(std::lround(frame.depth(u, v) * 100.0f))};
            }
        }
        return colour;
    }

  private:
    std::vector<int64_t> without_;
};

size_t countLines(const std::filesystem::path& path) {
    std::ifstream in(path);
    size_t n = 0;
    for (std::string line; std::getline(in, line);) n += !line.empty() && line[0] != '#';
    return n;
}

TEST(RecordingSource, ReadsBackAsTheSameFramesStampsAndGroundTruth) {
    const auto dir = testing::freshTempDir("recording_roundtrip") / "scan";
    auto recording = RecordingSource::create(simulatedScan(8), dir);
    ASSERT_TRUE(recording.isOk()) << recording.status().toString();
    std::vector<Frame> passed;
    for (;;) {
        auto frame = (*recording)->next();
        if (!frame.isOk()) {
            EXPECT_EQ(frame.status().code(), StatusCode::kOutOfRange);
            break;
        }
        passed.push_back(*frame);
    }
    ASSERT_EQ(passed.size(), 8u);
    EXPECT_EQ((*recording)->recorded(), 8u);
    const PinholeCamera camera = (*recording)->camera();
    recording->reset();

    auto replay = dataset::DatasetSource::open(dir);
    ASSERT_TRUE(replay.isOk()) << replay.status().toString();
    EXPECT_EQ((*replay)->info().layout, dataset::Layout::kPlumb);
    ASSERT_EQ((*replay)->size(), std::optional<size_t>(8));
    EXPECT_NEAR((*replay)->camera().fx, camera.fx, 1e-6);
    EXPECT_NEAR((*replay)->camera().cy, camera.cy, 1e-6);
    for (const Frame& original : passed) {
        auto frame = (*replay)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        EXPECT_NEAR(frame->timestamp_s, original.timestamp_s, 1e-6);
        // Depth to the millimetre: each pixel within half a unit of the original.
        ASSERT_EQ(frame->depth.size(), original.depth.size());
        size_t valid = 0, off = 0;
        for (size_t i = 0; i < original.depth.size(); ++i) {
            const float a = original.depth.pixels()[i];
            const float b = frame->depth.pixels()[i];
            valid += a > 0.0f ? 1 : 0;
            off += std::abs(a - b) > 0.0005f + 1e-6f ? 1 : 0;
        }
        EXPECT_GT(valid, original.depth.size() / 3);
        EXPECT_EQ(off, 0u) << "frame " << original.index;
        ASSERT_TRUE(original.T_W_C_gt && frame->T_W_C_gt);
        EXPECT_LT((original.T_W_C_gt->translation() - frame->T_W_C_gt->translation()).norm(), 1e-6);
        EXPECT_TRUE(original.T_W_C_gt->rotation().isApprox(frame->T_W_C_gt->rotation(), 1e-6));
        // Colour comes back exactly as the simulator delivered it.
        EXPECT_EQ(frame->colour, original.colour) << "frame " << original.index;
    }
    EXPECT_EQ(countLines(dir / "capture.txt"), 8u);
    EXPECT_EQ(std::filesystem::exists(dir / "rgb.txt"), !passed.front().colour.empty());
}

TEST(RecordingSource, ColourIsRecordedAndReadsBackExactlyWithItsOwnDepthFrame) {
    // 8 frames at 30 Hz, frames 2 and 5 without colour: each colour image must come back with
    // exactly its own depth frame, and the colourless frames without any.
    const auto dir = testing::freshTempDir("recording_colour") / "scan";
    auto recording = RecordingSource::create(
        std::make_unique<ColourPainter>(simulatedScan(8), std::vector<int64_t>{2, 5}), dir);
    ASSERT_TRUE(recording.isOk()) << recording.status().toString();
    std::vector<Frame> passed;
    for (auto frame = (*recording)->next(); frame.isOk(); frame = (*recording)->next()) {
        passed.push_back(*frame);
    }
    ASSERT_EQ(passed.size(), 8u);
    recording->reset();
    EXPECT_EQ(countLines(dir / "rgb.txt"), 6u);
    EXPECT_EQ(countLines(dir / "associations.txt"), 6u);
    EXPECT_TRUE(std::filesystem::exists(dir / "rgb/000007.png"));
    EXPECT_FALSE(std::filesystem::exists(dir / "rgb/000002.png"));

    auto replay = dataset::DatasetSource::open(dir);
    ASSERT_TRUE(replay.isOk()) << replay.status().toString();
    EXPECT_EQ((*replay)->info().framesWithColour(), 6u);
    EXPECT_EQ((*replay)->info().colour_source, "associations.txt");
    for (const Frame& original : passed) {
        auto frame = (*replay)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        EXPECT_EQ(frame->colour, original.colour) << "frame " << original.index;
        EXPECT_EQ(frame->colour.empty(), original.index == 2 || original.index == 5);
    }

    // rgb.txt alone (associations.txt lost) pairs the same way: the stamps are equal.
    std::filesystem::remove(dir / "associations.txt");
    auto by_stamp = dataset::DatasetSource::open(dir);
    ASSERT_TRUE(by_stamp.isOk()) << by_stamp.status().toString();
    for (const Frame& original : passed) {
        auto frame = (*by_stamp)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        EXPECT_EQ(frame->colour, original.colour) << "frame " << original.index;
    }
}

/// Hands out one frame whose colour is not the depth's size (a broken source).
class MisregisteredSource final : public FrameSourceDecorator {
  public:
    using FrameSourceDecorator::FrameSourceDecorator;
    Result<Frame> next() override {
        auto frame = inner().next();
        if (frame.isOk()) frame->colour = ColourImage(3, 2);
        return frame;
    }
};

TEST(RecordingSource, ColourOfAnotherSizeThanTheDepthIsRefused) {
    const auto dir = testing::freshTempDir("recording_colour_size") / "scan";
    auto recording =
        RecordingSource::create(std::make_unique<MisregisteredSource>(simulatedScan(2)), dir);
    ASSERT_TRUE(recording.isOk()) << recording.status().toString();
    auto frame = (*recording)->next();
    ASSERT_FALSE(frame.isOk());
    EXPECT_EQ(frame.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_NE(frame.status().message().find("3x2 colour for 160x120 depth"), std::string::npos)
        << frame.status().message();
    EXPECT_EQ(countLines(dir / "depth.txt"), 0u);
}

TEST(RecordingSource, ACutOffRecordingListsOnlyWholeFramesAndIsNeverOverwritten) {
    const auto dir = testing::freshTempDir("recording_cut") / "scan";
    {
        auto recording = RecordingSource::create(
            std::make_unique<ColourPainter>(simulatedScan(8), std::vector<int64_t>{}), dir);
        ASSERT_TRUE(recording.isOk()) << recording.status().toString();
        for (int i = 0; i < 3; ++i) ASSERT_TRUE((*recording)->next().isOk());
    }  // the scan stops after 3 of 8 frames
    EXPECT_EQ(countLines(dir / "depth.txt"), 3u);
    EXPECT_EQ(countLines(dir / "groundtruth.txt"), 3u);
    EXPECT_EQ(countLines(dir / "rgb.txt"), 3u);
    EXPECT_EQ(countLines(dir / "associations.txt"), 3u);
    auto replay = dataset::DatasetSource::open(dir);
    ASSERT_TRUE(replay.isOk()) << replay.status().toString();
    EXPECT_EQ((*replay)->size(), std::optional<size_t>(3));
    EXPECT_EQ((*replay)->info().framesWithColour(), 3u);

    EXPECT_EQ(RecordingSource::checkFolder(dir).code(), StatusCode::kFailedPrecondition);
    auto again = RecordingSource::create(simulatedScan(2), dir);
    ASSERT_FALSE(again.isOk());
    EXPECT_EQ(again.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_EQ(countLines(dir / "depth.txt"), 3u);  // untouched

    // A folder that cannot be created (a file is in the way) is a clear I/O error.
    const auto blocked = dir.parent_path() / "file";
    std::ofstream(blocked) << "x";
    auto cannot = RecordingSource::create(simulatedScan(2), blocked / "scan");
    ASSERT_FALSE(cannot.isOk());
    EXPECT_EQ(cannot.status().code(), StatusCode::kIoError) << cannot.status().toString();
}

}  // namespace
}  // namespace plumb
