// SPDX-License-Identifier: Apache-2.0
// The raw frame store (backend/ingest/raw_frame_store.hpp): frames written as received and listed
// in capture order, leftovers of an interrupted write removed, frames matched with a session's
// fragments by index and capture time (another session's frames with the same indices never
// mix in), and read back as depth in metres and exact colour, a damaged file left out.

#include "backend/ingest/raw_frame_store.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>

#include "backend/model/final_model.hpp"
#include "messages/conversions.hpp"
#include "messages/files.hpp"
#include "messages/fragment_sender.hpp"
#include "messages/wire.hpp"

namespace plumb::backend {
namespace {

namespace fs = std::filesystem;

fs::path tempDir(const std::string& name) {
    const fs::path dir =
        fs::temp_directory_path() / ("plumb_rawstore_" + name + "_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

PinholeCamera smallCamera() {
    PinholeCamera c;
    c.width = 8;
    c.height = 6;
    c.fx = c.fy = 10.0;
    c.cx = 4.0;
    c.cy = 3.0;
    return c;
}

/// A raw frame message of the small camera's size: depth (1000 + 10 k + u) mm at pixel u,
/// colour {k, u, v} unless `colour` is false.
messages::Bytes rawFrameMessage(int64_t utime, int64_t index, bool colour = true, int width = 8) {
    messages::RawRgbdFrame f;
    f.utime = utime;
    f.frame_index = index;
    f.depth = Depth16Image(width, 6);
    if (colour) f.colour = ColourImage(width, 6);
    for (int v = 0; v < 6; ++v) {
        for (int u = 0; u < width; ++u) {
            f.depth(u, v) = static_cast<uint16_t>(1000 + 10 * index + u);
            if (colour)
                f.colour(u, v) = Rgb8{static_cast<uint8_t>(index), static_cast<uint8_t>(u),
                                      static_cast<uint8_t>(v)};
        }
    }
    auto msg = messages::toMessage(f, messages::DepthEncoding::kDeltaVarint,
                                   messages::ColourEncoding::kDeltaRice, index + 1);
    PLUMB_CHECK(msg.isOk()) << msg.status().toString();
    return messages::encodeMessage(*msg);
}

/// A fragment of frames `first`..`last` captured at 30 Hz from `t0_s`, tracked but for `failed`.
Fragment fragmentOf(uint32_t id, int64_t first, int64_t last, double t0_s, int64_t failed = -1) {
    Fragment f;
    f.id = id;
    for (int64_t k = first; k <= last; ++k) {
        FragmentFrame frame;
        frame.frame_index = k;
        frame.timestamp_s = t0_s + static_cast<double>(k) / 30.0;
        frame.tracking_ok = k != failed;
        f.frames.push_back(frame);
    }
    return f;
}

/// A stored raw frame that names no session.
StoredRawFrame storedAt(int64_t utime, int64_t frame_index, const fs::path& path) {
    StoredRawFrame f;
    f.utime = utime;
    f.frame_index = frame_index;
    f.path = path;
    return f;
}

int64_t utimeOf(int64_t k, double t0_s) {
    return messages::toUtime(t0_s + static_cast<double>(k) / 30.0);
}

TEST(RawFrameStore, KeepsFramesAsReceivedInCaptureOrder) {
    const fs::path dir = tempDir("order");
    {  // An interrupted write of an earlier run, and a file that is not a raw frame.
        std::ofstream(dir / "00000000000000001_000000001.raw.tmp") << "half";
        std::ofstream(dir / "notes.txt") << "not a frame";
    }
    auto store = RawFrameStore::open(dir);
    ASSERT_TRUE(store.isOk()) << store.status().toString();
    EXPECT_FALSE(fs::exists(dir / "00000000000000001_000000001.raw.tmp"));
    const double t0 = 1.7e9;
    for (int64_t k : {3, 1, 2}) {
        const auto bytes = rawFrameMessage(utimeOf(k, t0), k);
        ASSERT_TRUE((*store)->put(utimeOf(k, t0), k, bytes).isOk());
    }
    // The same frame again (a repeated message) replaces it.
    ASSERT_TRUE((*store)->put(utimeOf(2, t0), 2, rawFrameMessage(utimeOf(2, t0), 2)).isOk());
    EXPECT_FALSE((*store)->put(-1, 2, rawFrameMessage(0, 2)).isOk());

    auto listed = listRawFrames(dir);
    ASSERT_TRUE(listed.isOk()) << listed.status().toString();
    ASSERT_EQ(listed->size(), 3u);
    for (size_t i = 0; i < 3; ++i) {
        EXPECT_EQ((*listed)[i].frame_index, static_cast<int64_t>(i + 1));
        EXPECT_EQ((*listed)[i].utime, utimeOf(static_cast<int64_t>(i + 1), t0));
        auto bytes = messages::readFile((*listed)[i].path, 1 << 20);
        ASSERT_TRUE(bytes.isOk());
        EXPECT_EQ(*bytes, rawFrameMessage(utimeOf(static_cast<int64_t>(i + 1), t0),
                                          static_cast<int64_t>(i + 1)));
    }
    auto absent = listRawFrames(dir / "missing");
    ASSERT_TRUE(absent.isOk());
    EXPECT_TRUE(absent->empty());
    fs::remove_all(dir);
}

// Frames that name their session (depth_frame3_t) are kept apart from another session's frame
// of the same capture time and index (two runs of the simulator); frames of older devices, which
// name none, are kept as before. Names that are neither are not raw frames.
TEST(RawFrameStore, FramesOfTwoSessionsAtOneInstantAreBothKept) {
    const fs::path dir = tempDir("sessions");
    auto store = RawFrameStore::open(dir);
    ASSERT_TRUE(store.isOk());
    const double t0 = 0.0;  // a simulator's clock
    ASSERT_TRUE((*store)->put(utimeOf(1, t0), 1, rawFrameMessage(utimeOf(1, t0), 1), 11).isOk());
    ASSERT_TRUE((*store)->put(utimeOf(1, t0), 1, rawFrameMessage(utimeOf(1, t0), 2), 7).isOk());
    ASSERT_TRUE((*store)->put(utimeOf(1, t0), 1, rawFrameMessage(utimeOf(1, t0), 3)).isOk());
    for (const char* name :
         {"00000000000000001_000000001_s.raw", "00000000000000001_000000001_7.raw",
          "00000000000000001_000000001_s7x.raw"})
        std::ofstream(dir / name) << "not a frame";
    auto listed = listRawFrames(dir);
    ASSERT_TRUE(listed.isOk()) << listed.status().toString();
    ASSERT_EQ(listed->size(), 3u);
    // Capture time, index, then session: none first, then 7, then 11.
    EXPECT_FALSE((*listed)[0].session_id.has_value());
    EXPECT_EQ((*listed)[1].session_id, 7);
    EXPECT_EQ((*listed)[2].session_id, 11);
    for (const StoredRawFrame& f : *listed) {
        EXPECT_EQ(f.utime, utimeOf(1, t0));
        EXPECT_EQ(f.frame_index, 1);
    }
    // Each session's fragments match their own frame rather than the one that names none (which
    // sorts first); a session without a frame of its own takes that one.
    const std::vector<Fragment> fragments = {fragmentOf(0, 1, 1, t0)};
    for (const int64_t session : {7, 11}) {
        const RawFrameCoverage c = rawFrameCoverage(*listed, fragments, session);
        ASSERT_EQ(c.matched, 1u);
        EXPECT_EQ(c.frames[0].session_id, session);
    }
    const RawFrameCoverage other = rawFrameCoverage(*listed, fragments, 12);
    ASSERT_EQ(other.matched, 1u);
    EXPECT_FALSE(other.frames[0].session_id.has_value());
    const std::vector<StoredRawFrame> named(listed->begin() + 1, listed->end());
    EXPECT_EQ(rawFrameCoverage(named, fragments, 11).frames[0].session_id, 11);
    EXPECT_EQ(rawFrameCoverage(named, fragments, 12).matched, 0u);
    fs::remove_all(dir);
}

TEST(RawFrameStore, CoverageMatchesIndexAndCaptureTimeOfTheSessionOnly) {
    const double t0 = 1.7e9, other_session = 1.7e9 + 3600.0;
    std::vector<StoredRawFrame> stored;
    // This session: frames 0-9 but 6 and 7; another session: frames 0-19 an hour later.
    for (int64_t k = 0; k < 10; ++k) {
        if (k != 6 && k != 7) stored.push_back(storedAt(utimeOf(k, t0), k, "a"));
    }
    for (int64_t k = 0; k < 20; ++k) stored.push_back(storedAt(utimeOf(k, other_session), k, "b"));
    // Frame 3 of this session stored 0.4 ms off (within the tolerance), frame 9 2 ms off (not).
    stored[3].utime += 400;
    stored[7].utime += 2000;  // frame 9 (6 and 7 are missing)
    const std::vector<Fragment> fragments = {fragmentOf(0, 0, 4, t0, /*failed=*/2),
                                             fragmentOf(1, 5, 9, t0)};
    const RawFrameCoverage c = rawFrameCoverage(stored, fragments);
    EXPECT_EQ(c.tracked_frames, 9u);  // frame 2's tracking failed
    EXPECT_EQ(c.matched, 6u);         // 0, 1, 3, 4; 5, 8
    EXPECT_EQ(c.min_fragment_id, 1u);
    EXPECT_DOUBLE_EQ(c.min_fragment_share, 2.0 / 5.0);
    std::vector<int64_t> indices;
    for (const StoredRawFrame& f : c.frames) {
        indices.push_back(f.frame_index);
        EXPECT_EQ(f.path, fs::path("a"));
    }
    EXPECT_EQ(indices, (std::vector<int64_t>{0, 1, 3, 4, 5, 8}));
    EXPECT_EQ(c.stride, 1);  // steps 1, 2, 1, 1, 3

    EXPECT_EQ(rawFrameCoverage({}, fragments).min_fragment_share, 0.0);
    EXPECT_EQ(rawFrameCoverage(stored, {}).min_fragment_share, 0.0);
}

// The default share admits a device streaming every 4th frame (stream.raw_frame_every = 4, the
// fragment surfaces' own stride): a 50-frame fragment then holds 12 or 13 of them, whatever the
// fragment's phase against the stride.
TEST(RawFrameStore, TheDefaultShareAdmitsEveryFourthFrameOfFiftyFrameFragments) {
    const double t0 = 1.7e9;
    std::vector<StoredRawFrame> stored;
    for (int64_t k = 0; k < 400; k += 4) stored.push_back(storedAt(utimeOf(k, t0), k, "a"));
    std::vector<Fragment> fragments;
    for (uint32_t i = 0; i < 8; ++i) fragments.push_back(fragmentOf(i, 50 * i, 50 * i + 49, t0));
    const RawFrameCoverage every4 = rawFrameCoverage(stored, fragments);
    EXPECT_DOUBLE_EQ(every4.min_fragment_share, 12.0 / 50.0);
    EXPECT_GE(every4.min_fragment_share, FinalModelConfig{}.min_raw_frame_share);
    EXPECT_EQ(every4.stride, 4);
    // Every 8th frame is too few.
    std::vector<StoredRawFrame> every8_frames;
    for (int64_t k = 0; k < 400; k += 8) every8_frames.push_back(storedAt(utimeOf(k, t0), k, "a"));
    const RawFrameCoverage every8 = rawFrameCoverage(every8_frames, fragments);
    EXPECT_LT(every8.min_fragment_share, FinalModelConfig{}.min_raw_frame_share);
    EXPECT_EQ(every8.stride, 8);
}

TEST(RawFrameStore, SourceReadsMetresAndColourAndLeavesOutDamagedFrames) {
    const fs::path dir = tempDir("source");
    auto store = RawFrameStore::open(dir);
    ASSERT_TRUE(store.isOk());
    const double t0 = 1.7e9;
    for (int64_t k = 0; k < 5; ++k) {
        const bool colour = k != 1;         // a depth-only frame
        const int width = k == 3 ? 10 : 8;  // a frame of another size than the camera
        ASSERT_TRUE((*store)
                        ->put(utimeOf(k, t0), k, rawFrameMessage(utimeOf(k, t0), k, colour, width))
                        .isOk());
    }
    auto listed = listRawFrames(dir);
    ASSERT_TRUE(listed.isOk());
    ASSERT_EQ(listed->size(), 5u);
    {  // Frame 2's file is cut short after it was stored.
        auto bytes = messages::readFile((*listed)[2].path, 1 << 20);
        ASSERT_TRUE(bytes.isOk());
        bytes->resize(bytes->size() / 2);
        ASSERT_TRUE(messages::writeFileAtomic((*listed)[2].path, *bytes).isOk());
    }
    auto source = openRawFrameSource(*listed, smallCamera());
    EXPECT_EQ(source->size(), std::optional<size_t>(5));
    std::vector<int64_t> read;
    for (auto frame = source->next(); frame.isOk(); frame = source->next()) {
        read.push_back(frame->index);
        EXPECT_NEAR(frame->timestamp_s, t0 + static_cast<double>(frame->index) / 30.0, 1e-6);
        ASSERT_EQ(frame->depth.width(), 8);
        EXPECT_FLOAT_EQ(frame->depth(5, 2), (1000.0f + 10.0f * frame->index + 5.0f) / 1000.0f);
        if (frame->index == 1) {
            EXPECT_TRUE(frame->colour.empty());
        } else {
            ASSERT_EQ(frame->colour.width(), 8);
            EXPECT_EQ(frame->colour(5, 2), (Rgb8{static_cast<uint8_t>(frame->index), 5, 2}));
        }
    }
    EXPECT_EQ(read, (std::vector<int64_t>{0, 1, 4}));
    EXPECT_EQ(source->next().status().code(), StatusCode::kOutOfRange);

    // A stop request ends the reading.
    auto stopped = openRawFrameSource(*listed, smallCamera(), [] { return true; });
    EXPECT_EQ(stopped->next().status().code(), StatusCode::kCancelled);
    fs::remove_all(dir);
}

}  // namespace
}  // namespace plumb::backend
