// SPDX-License-Identifier: Apache-2.0
// The real OpenNI2 path (initialise, enumerate, open, mode, stream, record, play back, disconnect,
// reconnect) against the virtual OpenNI2 device (drivers/openni2/sim_driver), which this test
// executable loads through its RUNPATH: build/openni2-runtime/libOpenNI2.so.0 with
// OpenNI2/Drivers/libPlumbSimDevice.so.0 beside it. Every frame that comes out must equal the
// simulator's frame with the same index, quantised as the device sends it.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <string>

#include "drivers/device_clock.hpp"
#include "drivers/device_list.hpp"
#include "drivers/openni2/openni2_source.hpp"
#include "drivers/openni2/sim_device.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::openni2 {
namespace {

/// The simulator's frame k as the virtual device sends it (mm or 100 um pixels). Sources are
/// cached per (uri, size): creating one loads the noise table.
DepthImage expectedFrame(const std::string& uri, int width, int height, size_t k,
                         double units = 1000.0) {
    static std::map<std::string, std::unique_ptr<sim::SimSource>> cache;
    const std::string key = uri + "@" + std::to_string(width) + "x" + std::to_string(height);
    auto& source = cache[key];
    if (!source) {
        auto spec = parseSimDeviceUri(uri);
        EXPECT_TRUE(spec.isOk()) << spec.status().toString();
        auto config = simConfigFor(*spec, width, height);
        EXPECT_TRUE(config.isOk());
        auto created = sim::SimSource::create(*config);
        EXPECT_TRUE(created.isOk()) << created.status().toString();
        source = std::move(created).value();
    }
    auto frame = source->render(k);
    EXPECT_TRUE(frame.isOk());
    DepthImage out = frame->frame.depth;
    for (float& d : out.pixels()) d = pixelToDepth(depthToPixel(d, units), units);
    return out;
}

/// The simulator's colour of frame k (empty while the simulator renders none).
ColourImage expectedColour(const std::string& uri, int width, int height, size_t k) {
    auto spec = parseSimDeviceUri(uri);
    EXPECT_TRUE(spec.isOk());
    auto config = simConfigFor(*spec, width, height);
    EXPECT_TRUE(config.isOk());
    auto source = sim::SimSource::create(*config);
    EXPECT_TRUE(source.isOk()) << source.status().toString();
    auto frame = (*source)->render(k);
    EXPECT_TRUE(frame.isOk());
    return frame->frame.colour;
}

/// Reads `n` frames; every frame that has colour must carry the test pattern of its own device
/// frame index (unmirrored), and the frames listed by `without(k)` must have none. Returns how
/// many frames had colour.
size_t checkPatternFrames(OpenNI2Source& source, int n, int width, int height,
                          const std::function<bool(int)>& without) {
    size_t with = 0;
    for (int i = 0; i < n; ++i) {
        auto frame = source.next();
        EXPECT_TRUE(frame.isOk()) << frame.status().toString();
        if (!frame.isOk()) continue;
        const int k = source.lastDeviceFrameIndex();
        if (without(k)) {
            EXPECT_TRUE(frame->colour.empty()) << "frame " << k;
            continue;
        }
        if (frame->colour.empty()) continue;  // colour that came too late for its depth frame
        ++with;
        EXPECT_EQ(frame->colour.width(), width);
        EXPECT_EQ(frame->colour.height(), height);
        EXPECT_TRUE(frame->colour == simColourPattern(k, width, height))
            << "frame " << k << " carries colour (" << int(frame->colour(0, 0).r) << ", "
            << int(frame->colour(0, 0).b) << ") at (0, 0)";
    }
    return with;
}

/// Number of pixels that differ; also checks that the frame has real content.
size_t countDifferences(const DepthImage& a, const DepthImage& b) {
    EXPECT_EQ(a.width(), b.width());
    EXPECT_EQ(a.height(), b.height());
    if (a.width() != b.width() || a.height() != b.height()) return a.size();
    size_t diff = 0;
    for (size_t i = 0; i < a.size(); ++i) diff += a.pixels()[i] != b.pixels()[i] ? 1 : 0;
    return diff;
}

size_t validPixels(const DepthImage& d) {
    size_t n = 0;
    for (float v : d.pixels()) n += v > 0.0f ? 1 : 0;
    return n;
}

TEST(OpenNI2Virtual, ListsTheVirtualDevice) {
    auto devices = listDevices();
    ASSERT_TRUE(devices.isOk()) << devices.status().toString();
    bool found = false;
    for (const auto& d : *devices) found |= d.uri == "plumb-sim://living_room";
    EXPECT_TRUE(found);
    const std::string text = formatDeviceList(listDepthDevices());
    EXPECT_NE(text.find("openni2:plumb-sim://living_room"), std::string::npos) << text;
}

TEST(OpenNI2Virtual, StreamsTheSimulatorsFramesUnmirrored) {
    const std::string uri = "plumb-sim://living_room?frames=300";
    OpenNI2Config config;
    config.uri = uri;
    auto source = OpenNI2Source::open(config);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_EQ((*source)->camera().width, 640);
    EXPECT_NEAR((*source)->camera().fx, 525.0, 1e-3);
    EXPECT_NEAR((*source)->camera().cx, 319.5, 1e-9);
    EXPECT_FALSE((*source)->registered());  // the default virtual device does not register
    int last_index = -1;
    double last_time = 0.0;
    for (int i = 0; i < 6; ++i) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        const int k = (*source)->lastDeviceFrameIndex();
        EXPECT_GT(k, last_index);
        EXPECT_EQ(frame->index, i);
        EXPECT_GE(frame->timestamp_s, last_time);
        EXPECT_NEAR(frame->timestamp_s, hostNowSeconds(), 5.0);  // host clock, not device clock
        last_index = k;
        last_time = frame->timestamp_s;
        const DepthImage expected = expectedFrame(uri, 640, 480, static_cast<size_t>(k));
        EXPECT_GT(validPixels(expected), expected.size() / 3);  // not an empty view
        EXPECT_EQ(countDifferences(frame->depth, expected), 0u) << "frame " << k;
        // The scene is not left-right symmetric: a mirrored stream would have failed above.
        DepthImage mirrored = expected;
        for (int v = 0; v < 480; ++v) {
            for (int u = 0; u < 640; ++u) mirrored(u, v) = expected(639 - u, v);
        }
        EXPECT_GT(countDifferences(frame->depth, mirrored), expected.size() / 10);
    }
}

TEST(OpenNI2Virtual, Mode320x240At60In100Micrometres) {
    const std::string uri = "plumb-sim://living_room?frames=600&seed=3";
    SourceOptions options;
    options.depth_mode = "320x240@60";
    options.max_frames = 3;
    auto source = openFrameSource("openni2:" + uri, options);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_EQ((*source)->camera().width, 320);
    EXPECT_NEAR((*source)->camera().fx, 262.5, 1e-3);
    auto* oni = dynamic_cast<OpenNI2Source*>(source->get());
    ASSERT_NE(oni, nullptr);
    for (int i = 0; i < 3; ++i) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        const DepthImage expected =
            expectedFrame(uri, 320, 240, static_cast<size_t>(oni->lastDeviceFrameIndex()));
        EXPECT_EQ(countDifferences(frame->depth, expected), 0u);
    }
    EXPECT_EQ((*source)->next().status().code(), StatusCode::kOutOfRange);  // max_frames
}

TEST(OpenNI2Virtual, RegistrationWhenTheDeviceHasIt) {
    OpenNI2Config config;
    config.uri = "plumb-sim://living_room?frames=10&registration=1";
    auto source = OpenNI2Source::open(config);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_TRUE((*source)->registered());
    config.registration = false;
    config.uri = "plumb-sim://living_room?frames=10&registration=1&seed=2";
    auto off = OpenNI2Source::open(config);
    ASSERT_TRUE(off.isOk());
    EXPECT_FALSE((*off)->registered());
}

TEST(OpenNI2Virtual, UnplugIsReportedAndTheScanResumes) {
    const std::string uri = "plumb-sim://living_room?frames=60&unplug_at=4&unplug_frames=6";
    OpenNI2Config config;
    config.uri = uri;
    config.reconnect_wait_ms = 300;
    auto source = OpenNI2Source::open(config);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    int frames_before = 0;
    int unavailable = 0;
    std::string message;
    int resumed_index = -1;
    for (int call = 0; call < 60 && resumed_index < 0; ++call) {
        auto frame = (*source)->next();
        if (frame.isOk()) {
            if (unavailable == 0) {
                ++frames_before;
                EXPECT_LT((*source)->lastDeviceFrameIndex(), 4);
            } else {
                resumed_index = (*source)->lastDeviceFrameIndex();
                const DepthImage expected =
                    expectedFrame(uri, 640, 480, static_cast<size_t>(resumed_index));
                EXPECT_EQ(countDifferences(frame->depth, expected), 0u);
            }
            continue;
        }
        ASSERT_EQ(frame.status().code(), StatusCode::kUnavailable) << frame.status().toString();
        if (unavailable++ == 0) message = frame.status().message();
        EXPECT_FALSE((*source)->connected());
    }
    EXPECT_GE(frames_before, 1);
    EXPECT_GE(unavailable, 1);
    EXPECT_NE(message.find("disconnected"), std::string::npos) << message;
    EXPECT_GE(resumed_index, 10);  // frames 4..9 were lost while unplugged
    EXPECT_EQ((*source)->reconnects(), 1);
    EXPECT_TRUE((*source)->connected());
}

TEST(OpenNI2Virtual, RecordsToOniAndPlaysBackTheSameFrames) {
    const auto dir = testing::freshTempDir("openni2_record");
    const std::string oni = (dir / "scan.oni").string();
    const std::string uri = "plumb-sim://living_room?frames=300&seed=5";
    OpenNI2Config record;
    record.uri = uri;
    ASSERT_TRUE(recordOni(record, oni, 8).isOk());
    ASSERT_TRUE(std::filesystem::exists(oni));

    auto source = openFrameSource("openni2:" + oni);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    auto* player = dynamic_cast<OpenNI2Source*>(source->get());
    ASSERT_NE(player, nullptr);
    EXPECT_TRUE(player->isRecording());
    ASSERT_TRUE((*source)->size().has_value());
    const size_t n = *(*source)->size();
    EXPECT_GE(n, 8u);
    EXPECT_NEAR((*source)->camera().fx, 525.0, 1e-3);
    size_t played = 0;
    int last = -1;
    while (true) {
        auto frame = (*source)->next();
        if (!frame.isOk()) {
            EXPECT_EQ(frame.status().code(), StatusCode::kOutOfRange) << frame.status().toString();
            break;
        }
        ++played;
        // The player numbers recorded frames 1..N; the recording began with stream frame 0.
        const int k = player->lastDeviceFrameIndex() - 1;
        EXPECT_EQ(k, last + 1);  // manual playback: none dropped
        last = k;
        const DepthImage expected = expectedFrame(uri, 640, 480, static_cast<size_t>(k));
        EXPECT_EQ(countDifferences(frame->depth, expected), 0u) << "recorded frame " << k;
        ASSERT_LT(played, 100u);
    }
    EXPECT_EQ(played, n);
}

TEST(OpenNI2Virtual, ColourIsPairedWithItsOwnDepthFrameUnmirrored) {
    const std::string uri = "plumb-sim://living_room?frames=300&registration=1&colour=pattern";
    OpenNI2Config config;
    config.uri = uri;
    auto source = OpenNI2Source::open(config);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_TRUE((*source)->hasColour());
    EXPECT_TRUE((*source)->registered());
    EXPECT_NE((*source)->description().find("colour RGB888 640x480@30"), std::string::npos)
        << (*source)->description();
    // The virtual device has no frame sync: frames pair by timestamp.
    EXPECT_NE((*source)->description().find("paired by timestamp"), std::string::npos);
    const size_t with = checkPatternFrames(**source, 12, 640, 480, [](int) { return false; });
    EXPECT_GE(with, 10u);  // the first frame or so may come before any colour frame was seen
    EXPECT_EQ((*source)->framesWithColour(), with);
    EXPECT_EQ((*source)->framesWithColour() + (*source)->framesWithoutColour(), 12u);
}

TEST(OpenNI2Virtual, ColourPairsByTimestampDespiteAnOffsetAndDroppedColourFrames) {
    // Colour 5 ms after depth, and every third frame without colour: no depth frame may take a
    // neighbour's colour frame instead.
    const std::string uri =
        "plumb-sim://living_room?frames=300&registration=1&colour=pattern&colour_offset_us=5000"
        "&colour_skip=3&seed=4";
    SourceOptions options;
    options.depth_mode = "320x240@60";
    auto source = openFrameSource("openni2:" + uri, options);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    auto* oni = dynamic_cast<OpenNI2Source*>(source->get());
    ASSERT_NE(oni, nullptr);
    const size_t with =
        checkPatternFrames(*oni, 15, 320, 240, [](int k) { return (k + 1) % 3 == 0; });
    EXPECT_GE(with, 8u);  // 10 of the 15 frames have a colour frame
}

TEST(OpenNI2Virtual, SimulatorColourFlowsThroughOpenNI2) {
    // Written against Frame::colour of the simulator: frames carry exactly the colour it renders
    // for the same frame (none while it renders none).
    const std::string uri = "plumb-sim://living_room?frames=300&registration=1&seed=6";
    OpenNI2Config config;
    config.uri = uri;
    auto source = OpenNI2Source::open(config);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_TRUE((*source)->hasColour());
    constexpr int kFrames = 12;
    size_t rendered = 0, with = 0;
    for (int i = 0; i < kFrames; ++i) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        const int k = (*source)->lastDeviceFrameIndex();
        const ColourImage expected = expectedColour(uri, 640, 480, static_cast<size_t>(k));
        rendered += expected.empty() ? 0 : 1;
        if (expected.empty()) {
            EXPECT_TRUE(frame->colour.empty()) << "frame " << k;
        } else if (!frame->colour.empty()) {
            ++with;
            EXPECT_TRUE(frame->colour == expected) << "frame " << k;
        }
    }
    // The stream is paced like a camera and the driver waits at most half a frame period for a
    // depth frame's colour, so on a loaded machine a few frames go without; most must carry it.
    if (rendered > 0) {
        EXPECT_GE(2 * with, rendered);
    }
    std::printf("[ colour   ] the simulator rendered colour for %zu of %d frames, %zu carried it\n",
                rendered, kFrames, with);
}

TEST(OpenNI2Virtual, WithoutColourTheDeviceStreamsDepthAsBefore) {
    for (const std::string uri : {"plumb-sim://living_room?frames=300&colour=0",
                                  "plumb-sim://living_room?frames=300&colour=pattern&seed=8"}) {
        OpenNI2Config config;
        config.uri = uri;
        config.colour = uri.find("colour=0") != std::string::npos;  // off in the second case
        auto source = OpenNI2Source::open(config);
        ASSERT_TRUE(source.isOk()) << source.status().toString();
        EXPECT_FALSE((*source)->hasColour()) << uri;
        EXPECT_NE((*source)->description().find("no colour"), std::string::npos);
        for (int i = 0; i < 3; ++i) {
            auto frame = (*source)->next();
            ASSERT_TRUE(frame.isOk()) << frame.status().toString();
            EXPECT_TRUE(frame->colour.empty());
            const DepthImage expected = expectedFrame(
                uri, 640, 480, static_cast<size_t>((*source)->lastDeviceFrameIndex()));
            EXPECT_EQ(countDifferences(frame->depth, expected), 0u);
        }
    }
}

TEST(OpenNI2Virtual, ADamagedColourFrameLeavesItsDepthFrameWithoutColour) {
    const std::string uri =
        "plumb-sim://living_room?frames=300&registration=1&colour=pattern&fault=colour_short"
        "&fault_at=4&seed=9";
    OpenNI2Config config;
    config.uri = uri;
    auto source = OpenNI2Source::open(config);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const size_t with = checkPatternFrames(**source, 10, 640, 480, [](int k) { return k == 4; });
    EXPECT_GE(with, 7u);
}

TEST(OpenNI2Virtual, RecordsColourToOniAndPlaysItBackPaired) {
    const auto dir = testing::freshTempDir("openni2_record_colour");
    const std::string oni = (dir / "scan.oni").string();
    const std::string uri = "plumb-sim://living_room?frames=300&seed=5&colour=pattern";
    OpenNI2Config record;
    record.uri = uri;
    ASSERT_TRUE(recordOni(record, oni, 8).isOk());
    auto source = openFrameSource("openni2:" + oni);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    auto* player = dynamic_cast<OpenNI2Source*>(source->get());
    ASSERT_NE(player, nullptr);
    EXPECT_TRUE(player->hasColour());
    const size_t n = *(*source)->size();
    size_t with = 0;
    int last = -1;
    for (size_t i = 0; i < n; ++i) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        const int k = player->lastDeviceFrameIndex() - 1;  // the player numbers frames from 1
        EXPECT_EQ(k, last + 1);                            // no depth frame skipped
        last = k;
        EXPECT_EQ(countDifferences(frame->depth, expectedFrame(uri, 640, 480, k)), 0u);
        if (frame->colour.empty()) continue;
        ++with;
        EXPECT_TRUE(frame->colour == simColourPattern(k, 640, 480)) << "recorded frame " << k;
    }
    EXPECT_GE(with + 1, n);  // the last depth frame may have been recorded without its colour
    EXPECT_EQ((*source)->next().status().code(), StatusCode::kOutOfRange);
}

TEST(OpenNI2Virtual, DamagedFramesGiveClearErrorsAndStreamingGoesOn) {
    struct Case {
        const char* fault;
        StatusCode code;
        const char* text;
    };
    for (const Case& c : {Case{"short", StatusCode::kCorrupt, "short"},
                          Case{"empty", StatusCode::kCorrupt, "empty"},
                          Case{"format", StatusCode::kUnsupported, "RGB888"}}) {
        OpenNI2Config config;
        config.uri = std::string("plumb-sim://living_room?frames=300&fault_at=2&fault=") + c.fault;
        auto source = OpenNI2Source::open(config);
        ASSERT_TRUE(source.isOk()) << source.status().toString();
        bool saw_error = false;
        int after = 0;
        for (int call = 0; call < 12 && after < 1; ++call) {
            auto frame = (*source)->next();
            if (!frame.isOk()) {
                EXPECT_EQ(frame.status().code(), c.code) << frame.status().toString();
                EXPECT_NE(frame.status().message().find(c.text), std::string::npos)
                    << frame.status().toString();
                saw_error = true;
            } else if (saw_error) {
                ++after;
            }
        }
        EXPECT_TRUE(saw_error) << c.fault;
        EXPECT_EQ(after, 1) << c.fault;
    }
}

TEST(OpenNI2Virtual, BadRequestsGiveSpecificErrors) {
    OpenNI2Config config;
    config.uri = "plumb-sim://living_room?frames=5";
    config.width = 1024;
    config.height = 768;
    auto mode = OpenNI2Source::open(config);
    ASSERT_FALSE(mode.isOk());
    EXPECT_EQ(mode.status().code(), StatusCode::kUnsupported);
    EXPECT_NE(mode.status().message().find("320x240@60"), std::string::npos)
        << mode.status().toString();  // the error lists what the device offers

    config = {};
    config.uri = "plumb-sim://living_room?zoom=1";
    auto bad_uri = OpenNI2Source::open(config);
    ASSERT_FALSE(bad_uri.isOk());
    EXPECT_EQ(bad_uri.status().code(), StatusCode::kUnavailable);

    auto missing = openFrameSource("openni2:/nonexistent/scan.oni");
    ASSERT_FALSE(missing.isOk());
    EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);

    const auto dir = testing::freshTempDir("openni2_bad");
    const auto garbage = dir / "garbage.oni";
    std::ofstream(garbage) << "this is not an ONI file";
    auto bad_file = openFrameSource("openni2:" + garbage.string());
    EXPECT_FALSE(bad_file.isOk());

    SourceOptions options;
    options.depth_mode = "640x480";
    auto bad_mode = openFrameSource("openni2:plumb-sim://living_room", options);
    ASSERT_FALSE(bad_mode.isOk());
    EXPECT_EQ(bad_mode.status().code(), StatusCode::kInvalidArgument);

    EXPECT_FALSE(parseSimDeviceUri("plumb-sim://x?frames=abc").isOk());
    EXPECT_FALSE(parseSimDeviceUri("plumb-sim://?frames=3").isOk());
    EXPECT_FALSE(parseSimDeviceUri("plumb-sim://x?colour=rgb").isOk());
    EXPECT_FALSE(parseSimDeviceUri("plumb-sim://x?colour_offset_us=-1").isOk());
    EXPECT_EQ(parseSimDeviceUri("plumb-sim://x?colour=pattern&colour_skip=4")->colour_skip, 4);
}

}  // namespace
}  // namespace plumb::openni2
