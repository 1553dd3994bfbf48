// SPDX-License-Identifier: Apache-2.0
#include "common/frame/frame_recorder.hpp"

#include <gtest/gtest.h>

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace plumb {
namespace {

/// `count` frames of 8x6 pixels whose depth and colour encode their index; frame `fail_at`
/// (if any) is an I/O error.
class CountingSource : public FrameSource {
  public:
    explicit CountingSource(int count, std::optional<int> fail_at = std::nullopt)
        : count_(count), fail_at_(fail_at) {}

    const PinholeCamera& camera() const override { return camera_; }
    Result<Frame> next() override {
        if (position_ >= count_) return outOfRange("end");
        const int i = position_++;
        ++reads_;
        if (fail_at_ && i == *fail_at_) return ioError("frame " + std::to_string(i) + " is bad");
        Frame f;
        f.index = i;
        f.timestamp_s = 0.1 * i;
        f.depth = DepthImage(camera_.width, camera_.height, 1.0f + 0.01f * static_cast<float>(i));
        f.depth(3, 2) = 0.0f;
        f.colour = ColourImage(camera_.width, camera_.height,
                               Rgb8{static_cast<uint8_t>(i), 7, static_cast<uint8_t>(2 * i)});
        f.name = "frame" + std::to_string(i);
        return f;
    }
    Status skip() override {
        if (position_ >= count_) return outOfRange("end");
        ++position_;
        return Status::ok();
    }
    std::optional<size_t> size() const override { return static_cast<size_t>(count_); }
    std::string description() const override { return "counting source"; }

    int reads() const { return reads_; }

  private:
    PinholeCamera camera_{8, 6, 5.0, 5.0, 3.5, 2.5};
    int count_;
    std::optional<int> fail_at_;
    int position_ = 0;
    int reads_ = 0;
};

void expectSameFrame(const Frame& a, const Frame& b) {
    EXPECT_EQ(a.index, b.index);
    EXPECT_EQ(a.timestamp_s, b.timestamp_s);
    EXPECT_EQ(a.name, b.name);
    ASSERT_EQ(a.depth.size(), b.depth.size());
    ASSERT_EQ(a.colour.size(), b.colour.size());
    for (size_t k = 0; k < a.depth.size(); ++k) EXPECT_EQ(a.depth.data()[k], b.depth.data()[k]);
    for (size_t k = 0; k < a.colour.size(); ++k) {
        EXPECT_EQ(a.colour.data()[k].r, b.colour.data()[k].r);
        EXPECT_EQ(a.colour.data()[k].b, b.colour.data()[k].b);
    }
}

/// Reads `source` to its end.
std::vector<Frame> readAll(FrameSource& source) {
    std::vector<Frame> frames;
    for (;;) {
        Result<Frame> f = source.next();
        if (!f.isOk()) {
            EXPECT_EQ(f.status().code(), StatusCode::kOutOfRange) << f.status().message();
            return frames;
        }
        frames.push_back(std::move(*f));
    }
}

TEST(FrameRecorder, ReplaysEveryFrameOfTheStreamUnchangedAndInOrder) {
    CountingSource source(5);
    FrameRecorder recorder(source, size_t{1} << 20);
    const std::vector<Frame> first = readAll(recorder);
    ASSERT_EQ(first.size(), 5u);
    ASSERT_TRUE(recorder.complete()) << recorder.droppedBecause();
    EXPECT_EQ(recorder.bytes(), 5 * frameBytes(first[0]));
    std::shared_ptr<const std::vector<Frame>> kept = recorder.take();
    ASSERT_NE(kept, nullptr);
    EXPECT_EQ(recorder.bytes(), 0u);
    // Two replays of the same frames, the second skipping every other frame.
    for (int replay = 0; replay < 2; ++replay) {
        ReplaySource again(kept, source.camera(), "kept");
        EXPECT_EQ(again.size(), std::optional<size_t>(5));
        EXPECT_EQ(again.camera().width, 8);
        if (replay == 0) {
            const std::vector<Frame> second = readAll(again);
            ASSERT_EQ(second.size(), first.size());
            for (size_t i = 0; i < first.size(); ++i) expectSameFrame(second[i], first[i]);
        } else {
            for (int i = 0; i < 5; ++i) {
                if (i % 2 == 1) {
                    ASSERT_TRUE(again.skip().isOk());
                    continue;
                }
                Result<Frame> f = again.next();
                ASSERT_TRUE(f.isOk());
                expectSameFrame(*f, first[static_cast<size_t>(i)]);
            }
            EXPECT_EQ(again.next().status().code(), StatusCode::kOutOfRange);
            EXPECT_EQ(again.skip().code(), StatusCode::kOutOfRange);
        }
    }
    EXPECT_EQ(source.reads(), 5) << "the replays read nothing from the source";
}

TEST(FrameRecorder, KeepsNothingWhenTheFramesDoNotFitTheBudget) {
    CountingSource source(5);
    Frame probe = *CountingSource(1).next();
    FrameRecorder recorder(source, 3 * frameBytes(probe));
    EXPECT_EQ(readAll(recorder).size(), 5u) << "every frame still passes through";
    EXPECT_FALSE(recorder.complete());
    EXPECT_EQ(recorder.bytes(), 0u);
    EXPECT_EQ(recorder.take(), nullptr);
    EXPECT_NE(recorder.droppedBecause().find("MB set aside"), std::string::npos)
        << recorder.droppedBecause();

    CountingSource none(2);
    FrameRecorder off(none, 0);
    EXPECT_EQ(readAll(off).size(), 2u);
    EXPECT_EQ(off.take(), nullptr);
}

TEST(FrameRecorder, AStreamWithAGapOrNotReadToItsEndIsNotReplayed) {
    {
        CountingSource source(4);
        FrameRecorder recorder(source, size_t{1} << 20);
        ASSERT_TRUE(recorder.next().isOk());
        ASSERT_TRUE(recorder.skip().isOk());
        readAll(recorder);
        EXPECT_FALSE(recorder.complete());
        EXPECT_EQ(recorder.take(), nullptr);
        EXPECT_EQ(recorder.droppedBecause(), "a frame was skipped");
    }
    {
        CountingSource source(4, 2);
        FrameRecorder recorder(source, size_t{1} << 20);
        ASSERT_TRUE(recorder.next().isOk());
        ASSERT_TRUE(recorder.next().isOk());
        const Result<Frame> bad = recorder.next();
        EXPECT_EQ(bad.status().code(), StatusCode::kIoError);
        EXPECT_TRUE(recorder.next().isOk());
        EXPECT_EQ(recorder.next().status().code(), StatusCode::kOutOfRange);
        EXPECT_FALSE(recorder.complete());
        EXPECT_NE(recorder.droppedBecause().find("frame 2 is bad"), std::string::npos)
            << recorder.droppedBecause();
    }
    {
        CountingSource source(4);
        FrameRecorder recorder(source, size_t{1} << 20);
        ASSERT_TRUE(recorder.next().isOk());  // stopped before the end (Ctrl-C)
        EXPECT_FALSE(recorder.complete());
        EXPECT_EQ(recorder.take(), nullptr);
    }
}

}  // namespace
}  // namespace plumb
