// SPDX-License-Identifier: Apache-2.0
// The V4L2 source against replayed sessions (drivers/v4l2/replay_io.hpp): recordings built from
// the simulator's frames in the byte layouts UVC depth cameras deliver (Z16, INZI, Y16-BE), an
// unplug and re-plug mid-stream, damaged buffers and unusable formats.

#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include <cstring>
#include <fstream>
#include <functional>

#if PLUMB_TEST_HAVE_OPENCV
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#endif

#include "drivers/device_clock.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "drivers/usb/usb_devices.hpp"
#include "drivers/v4l2/colour_formats.hpp"
#include "drivers/v4l2/replay_io.hpp"
#include "drivers/v4l2/v4l2_source.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::v4l2 {
namespace {

constexpr int kW = 160;
constexpr int kH = 120;

std::vector<DepthImage> simFrames(size_t n) {
    sim::SimConfig config;
    config.camera = PinholeCamera().scaled(0.25);
    config.trajectory.num_frames = 30;
    config.seed = 7;
    config.trajectory.seed = 7;
    auto source = sim::SimSource::create(config);
    EXPECT_TRUE(source.isOk()) << source.status().toString();
    std::vector<DepthImage> out;
    for (size_t k = 0; k < n; ++k) out.push_back((*source)->render(k)->frame.depth);
    return out;
}

uint16_t toMm(float d) {
    return d > 0.0f && d < 65.0f ? static_cast<uint16_t>(std::lround(d * 1000.0f)) : 0;
}

/// A recording of `frames` in `format`, rows padded to `stride` bytes.
V4l2Recording makeRecording(const std::vector<DepthImage>& frames, uint32_t format,
                            uint32_t stride = kW * 2) {
    V4l2Recording r;
    r.path = "/dev/video4";
    r.card = "Intel(R) RealSense(TM) Depth Camera 435";
    r.formats = {V4L2_PIX_FMT_YUYV, format};
    r.pixelformat = format;
    r.width = kW;
    r.height = kH;
    r.bytesperline = stride;
    const uint32_t plane = stride * kH;
    r.sizeimage = format == V4L2_PIX_FMT_INZI ? 2 * plane : plane;
    for (size_t k = 0; k < frames.size(); ++k) {
        RecordedBuffer b;
        b.bytes.assign(r.sizeimage, 0);
        const uint32_t depth_offset = format == V4L2_PIX_FMT_INZI ? plane : 0;
        for (int v = 0; v < kH; ++v) {
            for (int u = 0; u < kW; ++u) {
                const uint16_t mm = toMm(frames[k](u, v));
                uint8_t* p = b.bytes.data() + depth_offset + v * stride + 2 * u;
                if (format == V4L2_PIX_FMT_Y16_BE) {
                    p[0] = static_cast<uint8_t>(mm >> 8);
                    p[1] = static_cast<uint8_t>(mm & 0xff);
                } else {
                    p[0] = static_cast<uint8_t>(mm & 0xff);
                    p[1] = static_cast<uint8_t>(mm >> 8);
                }
                if (format == V4L2_PIX_FMT_INZI) {  // IR plane: a ramp, 10-bit
                    const uint16_t ir = static_cast<uint16_t>((u * 4) & 0x3ff);
                    b.bytes[v * stride + 2 * u] = static_cast<uint8_t>(ir & 0xff);
                    b.bytes[v * stride + 2 * u + 1] = static_cast<uint8_t>(ir >> 8);
                }
            }
        }
        b.bytesused = r.sizeimage;
        b.sequence = static_cast<uint32_t>(k);
        b.timestamp_us = 5'000'000 + k * 33'333;
        r.buffers.push_back(std::move(b));
    }
    return r;
}

V4l2Config configFor(const V4l2Recording& r) {
    V4l2Config c;
    c.device = r.path;
    c.width = kW;
    c.height = kH;
    c.timeout_ms = 50;
    c.reconnect_wait_ms = 0;
    return c;
}

void expectFrameEquals(const Frame& frame, const DepthImage& sim) {
    ASSERT_EQ(frame.depth.width(), kW);
    ASSERT_EQ(frame.depth.height(), kH);
    size_t diff = 0;
    size_t valid = 0;
    for (int v = 0; v < kH; ++v) {
        for (int u = 0; u < kW; ++u) {
            const float expected = static_cast<float>(toMm(sim(u, v)) * (1.0 / 1000.0));
            diff += frame.depth(u, v) != expected ? 1 : 0;
            valid += expected > 0.0f ? 1 : 0;
        }
    }
    EXPECT_EQ(diff, 0u);
    EXPECT_GT(valid, frame.depth.size() / 3);  // not an empty view
}

TEST(V4l2Replay, StreamsRecordedZ16BuffersThenTimesOut) {
    const auto frames = simFrames(5);
    auto io = std::make_shared<ReplayIo>(makeRecording(frames, V4L2_PIX_FMT_Z16, kW * 2 + 64));
    {
        auto source = V4l2Source::open(configFor(makeRecording({}, V4L2_PIX_FMT_Z16)), io);
        ASSERT_TRUE(source.isOk()) << source.status().toString();
        EXPECT_EQ((*source)->format(), V4L2_PIX_FMT_Z16);
        EXPECT_EQ(io->mappings(), 4);
        double last_t = 0.0;
        for (size_t k = 0; k < frames.size(); ++k) {
            auto frame = (*source)->next();
            ASSERT_TRUE(frame.isOk()) << frame.status().toString();
            expectFrameEquals(*frame, frames[k]);
            EXPECT_EQ((*source)->lastSequence(), k);
            // Host time: replayed faster than real time, so only order and the clock are checked
            // here (DeviceClock's offset recovery is tested in test_drivers_usb).
            EXPECT_GE(frame->timestamp_s, last_t);
            EXPECT_LE(frame->timestamp_s, hostNowSeconds());
            last_t = frame->timestamp_s;
        }
        auto timeout = (*source)->next();
        EXPECT_EQ(timeout.status().code(), StatusCode::kUnavailable);
        EXPECT_NE(timeout.status().message().find("no frame"), std::string::npos)
            << timeout.status().toString();
    }
    EXPECT_EQ(io->openDescriptors(), 0);  // RAII: every fd closed, every buffer unmapped
    EXPECT_EQ(io->mappings(), 0);
}

TEST(V4l2Replay, UnplugIsUnavailableThenTheStreamResumes) {
    const auto frames = simFrames(7);
    auto io = std::make_shared<ReplayIo>(makeRecording(frames, V4L2_PIX_FMT_Z16));
    io->setUnplugAfter(3);
    io->setReplugAfterOpens(2);
    auto source = V4l2Source::open(configFor(makeRecording({}, V4L2_PIX_FMT_Z16)), io);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    size_t next_k = 0;
    int unavailable = 0;
    std::string first_error;
    for (int call = 0; call < 20 && next_k < frames.size(); ++call) {
        auto frame = (*source)->next();
        if (!frame.isOk()) {
            ASSERT_EQ(frame.status().code(), StatusCode::kUnavailable) << frame.status().toString();
            if (unavailable++ == 0) {
                first_error = frame.status().message();
                // The unplugged camera's descriptor and buffers are released at once.
                EXPECT_EQ(io->openDescriptors(), 0);
                EXPECT_EQ(io->mappings(), 0);
            }
            continue;
        }
        expectFrameEquals(*frame, frames[next_k]);
        ++next_k;
    }
    EXPECT_EQ(next_k, frames.size());  // nothing delivered was lost
    EXPECT_GE(unavailable, 2);
    EXPECT_NE(first_error.find("unplugged"), std::string::npos) << first_error;
    EXPECT_EQ((*source)->reconnects(), 1);
}

TEST(V4l2Replay, AHotplugArrivalReopensWithoutTheReconnectWait) {
    // The reconnect wait is ten minutes: only cameraArrived() can let next() reopen in time for
    // ctest. An arrival announced while next() is not waiting is kept for the next attempt.
    const auto frames = simFrames(4);
    auto io = std::make_shared<ReplayIo>(makeRecording(frames, V4L2_PIX_FMT_Z16));
    io->setUnplugAfter(2);
    io->setReplugAfterOpens(0);
    V4l2Config config = configFor(makeRecording({}, V4L2_PIX_FMT_Z16));
    config.reconnect_wait_ms = 600000;
    auto source = V4l2Source::open(config, io);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    for (size_t k = 0; k < 2; ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        expectFrameEquals(*frame, frames[k]);
    }
    // Re-queuing the second buffer found the camera gone: the next call would wait to reopen.
    EXPECT_FALSE((*source)->connected());
    // What plumb-device's hot-plug handler does when a known camera arrives. USB announces the
    // camera before uvcvideo has made its video node, so the first attempt can come too early
    // (the replay's first open after the replug fails); each later arrival event (a camera has
    // several interfaces) or the periodic retry tries again.
    const auto handler = usb::forwardArrivals(**source);
    handler(usb::UsbEvent::kArrived, usb::UsbCamera{});
    auto early = (*source)->next();
    ASSERT_EQ(early.status().code(), StatusCode::kUnavailable) << early.status().toString();
    EXPECT_NE(early.status().message().find("not back yet"), std::string::npos);
    handler(usb::UsbEvent::kArrived, usb::UsbCamera{});
    for (size_t k = 2; k < frames.size(); ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        expectFrameEquals(*frame, frames[k]);
    }
    EXPECT_EQ((*source)->reconnects(), 1);
    EXPECT_TRUE((*source)->connected());
}

TEST(V4l2Replay, DecodesInziAndBigEndianY16) {
    const auto frames = simFrames(2);
    for (uint32_t format : {V4L2_PIX_FMT_INZI, V4L2_PIX_FMT_Y16_BE}) {
        auto io = std::make_shared<ReplayIo>(makeRecording(frames, format));
        auto source = V4l2Source::open(configFor(makeRecording({}, format)), io);
        ASSERT_TRUE(source.isOk()) << source.status().toString();
        EXPECT_EQ((*source)->format(), format);
        for (const auto& sim : frames) {
            auto frame = (*source)->next();
            ASSERT_TRUE(frame.isOk()) << frame.status().toString();
            expectFrameEquals(*frame, sim);
            if (format == V4L2_PIX_FMT_INZI) {
                ASSERT_EQ(frame->gray.width(), kW);
                EXPECT_EQ(frame->gray(100, 5), (100 * 4 & 0x3ff) >> 2);
            }
        }
    }
}

TEST(V4l2Replay, DamagedBuffersAreClearErrorsAndSkipped) {
    const auto frames = simFrames(4);
    V4l2Recording r = makeRecording(frames, V4L2_PIX_FMT_Z16);
    r.buffers[0].bytesused = 0;                // zero-size frame
    r.buffers[1].bytesused = r.sizeimage / 2;  // short buffer
    r.buffers[1].bytes.resize(r.sizeimage / 2);
    r.buffers[2].flags = V4L2_BUF_FLAG_ERROR;  // driver-flagged damage
    auto io = std::make_shared<ReplayIo>(r);
    auto source = V4l2Source::open(configFor(r), io);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    auto empty = (*source)->next();
    EXPECT_EQ(empty.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(empty.status().message().find("empty"), std::string::npos);
    auto short_frame = (*source)->next();
    EXPECT_EQ(short_frame.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(short_frame.status().message().find("short"), std::string::npos)
        << short_frame.status().toString();
    auto flagged = (*source)->next();
    EXPECT_EQ(flagged.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(flagged.status().message().find("damaged"), std::string::npos);
    auto good = (*source)->next();
    ASSERT_TRUE(good.isOk()) << good.status().toString();
    expectFrameEquals(*good, frames[3]);
    EXPECT_EQ(good->index, 0);  // the first frame actually delivered
}

TEST(V4l2Replay, UnusableFormatsAndSizesAreRefused) {
    V4l2Recording colour = makeRecording({}, V4L2_PIX_FMT_Z16);
    colour.formats = {V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG};
    colour.pixelformat = V4L2_PIX_FMT_YUYV;
    auto no_depth = V4l2Source::open(configFor(colour), std::make_shared<ReplayIo>(colour));
    ASSERT_FALSE(no_depth.isOk());
    EXPECT_EQ(no_depth.status().code(), StatusCode::kUnsupported);
    EXPECT_NE(no_depth.status().message().find("YUYV, MJPG"), std::string::npos)
        << no_depth.status().toString();

    V4l2Recording z16 = makeRecording({}, V4L2_PIX_FMT_Z16);
    V4l2Config forced = configFor(z16);
    forced.format = "Y16";
    auto not_offered = V4l2Source::open(forced, std::make_shared<ReplayIo>(z16));
    ASSERT_FALSE(not_offered.isOk());
    EXPECT_EQ(not_offered.status().code(), StatusCode::kUnsupported);
    forced.format = "YUYV";
    auto not_depth = V4l2Source::open(forced, std::make_shared<ReplayIo>(z16));
    EXPECT_EQ(not_depth.status().code(), StatusCode::kUnsupported);

    V4l2Config bigger = configFor(z16);
    bigger.width = 640;
    bigger.height = 480;
    auto wrong_size = V4l2Source::open(bigger, std::make_shared<ReplayIo>(z16));
    ASSERT_FALSE(wrong_size.isOk());
    EXPECT_NE(wrong_size.status().message().find("granted"), std::string::npos);

    V4l2Recording tiny = z16;
    tiny.sizeimage = 100;
    auto small_image = V4l2Source::open(configFor(tiny), std::make_shared<ReplayIo>(tiny));
    ASSERT_FALSE(small_image.isOk());
    EXPECT_EQ(small_image.status().code(), StatusCode::kCorrupt);

    auto missing = openFrameSource("v4l2:/dev/video-plumb-does-not-exist");
    ASSERT_FALSE(missing.isOk());
    EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
    V4l2Config zero = configFor(z16);
    zero.width = 0;
    EXPECT_EQ(V4l2Source::open(zero, std::make_shared<ReplayIo>(z16)).status().code(),
              StatusCode::kInvalidArgument);
}

TEST(V4l2Replay, RecordingsRoundTripAndRecordingIoCapturesASession) {
    const auto frames = simFrames(3);
    const V4l2Recording original = makeRecording(frames, V4L2_PIX_FMT_Z16);
    auto recorder = std::make_shared<RecordingIo>(std::make_shared<ReplayIo>(original));
    {
        auto source = V4l2Source::open(configFor(original), recorder);
        ASSERT_TRUE(source.isOk());
        for (int i = 0; i < 3; ++i) ASSERT_TRUE((*source)->next().isOk());
    }
    const V4l2Recording& captured = recorder->recording();
    ASSERT_EQ(captured.buffers.size(), 3u);
    EXPECT_EQ(captured.formats, original.formats);
    EXPECT_EQ(captured.pixelformat, original.pixelformat);
    EXPECT_EQ(captured.buffers[2].bytes, original.buffers[2].bytes);
    EXPECT_EQ(captured.buffers[2].timestamp_us, original.buffers[2].timestamp_us);

    const auto dir = testing::freshTempDir("v4l2_recording");
    ASSERT_TRUE(saveRecording(captured, dir / "session.v4l2rec").isOk());
    auto loaded = loadRecording(dir / "session.v4l2rec");
    ASSERT_TRUE(loaded.isOk()) << loaded.status().toString();
    EXPECT_EQ(loaded->buffers.size(), 3u);
    EXPECT_EQ(loaded->buffers[1].bytes, original.buffers[1].bytes);
    auto replayed = V4l2Source::open(configFor(*loaded), std::make_shared<ReplayIo>(*loaded));
    ASSERT_TRUE(replayed.isOk());
    auto frame = (*replayed)->next();
    ASSERT_TRUE(frame.isOk());
    expectFrameEquals(*frame, frames[0]);

    // A truncated file is corrupt, not a crash.
    std::filesystem::resize_file(dir / "session.v4l2rec", 200);
    EXPECT_EQ(loadRecording(dir / "session.v4l2rec").status().code(), StatusCode::kCorrupt);
    std::ofstream(dir / "junk.v4l2rec") << "junk";
    EXPECT_EQ(loadRecording(dir / "junk.v4l2rec").status().code(), StatusCode::kCorrupt);
}

// ---------------------------------------------------------------------------------------------
// Colour from a second node.

/// The colour test pattern of frame k: {(u + k) mod 256, v mod 256, (7 k) mod 256}.
Rgb8 patternPixel(int u, int v, int64_t k) {
    return Rgb8{static_cast<uint8_t>((u + k) & 0xff), static_cast<uint8_t>(v & 0xff),
                static_cast<uint8_t>((7 * k) & 0xff)};
}

/// YUYV samples of frame k: Y from the column pair and k, U from the row, V from k.
void yuyvSamples(int u, int v, int64_t k, int* y, int* cb, int* cr) {
    *y = 16 + static_cast<int>((u + 3 * k) % 200);
    *cb = 100 + v % 60;
    *cr = 90 + static_cast<int>(k % 70);
}

/// A colour node's session: frame k at depth stamp + offset_us, in `format` at w x h; frames with
/// (k + 1) % skip == 0 are missing (skip 0: none).
V4l2Recording makeColourRecording(size_t n, uint32_t format, int w, int h, int64_t offset_us,
                                  int skip = 0) {
    V4l2Recording r;
    r.path = "/dev/video6";
    r.card = "Intel(R) RealSense(TM) Depth Camera 435 RGB";
    r.formats = {V4L2_PIX_FMT_NV12, format};  // NV12 is not decoded: skipped
    r.pixelformat = format;
    r.width = static_cast<uint32_t>(w);
    r.height = static_cast<uint32_t>(h);
    r.bytesperline = static_cast<uint32_t>(format == V4L2_PIX_FMT_YUYV ? 2 * w : 3 * w);
    r.sizeimage = r.bytesperline * r.height;
    for (size_t k = 0; k < n; ++k) {
        if (skip > 0 && (k + 1) % skip == 0) continue;
        RecordedBuffer b;
        b.bytes.assign(r.sizeimage, 0);
        for (int v = 0; v < h; ++v) {
            uint8_t* row = b.bytes.data() + static_cast<size_t>(v) * r.bytesperline;
            for (int u = 0; u < w; ++u) {
                if (format == V4L2_PIX_FMT_YUYV) {
                    int y = 0, cb = 0, cr = 0;
                    yuyvSamples(u, v, static_cast<int64_t>(k), &y, &cb, &cr);
                    row[2 * u] = static_cast<uint8_t>(y);
                    row[2 * u + 1] = static_cast<uint8_t>(u % 2 == 0 ? cb : cr);
                } else {
                    const Rgb8 c = patternPixel(u, v, static_cast<int64_t>(k));
                    row[3 * u] = c.r;
                    row[3 * u + 1] = c.g;
                    row[3 * u + 2] = c.b;
                }
            }
        }
        b.bytesused = r.sizeimage;
        b.sequence = static_cast<uint32_t>(k);
        b.timestamp_us = 5'000'000 + k * 33'333 + static_cast<uint64_t>(offset_us);
        r.buffers.push_back(std::move(b));
    }
    return r;
}

/// The colour frame k of makeColourRecording as the source must deliver it (at w x h).
ColourImage expectedColour(uint32_t format, int w, int h, int64_t k) {
    ColourImage c(w, h);
    for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
            if (format == V4L2_PIX_FMT_YUYV) {
                int y = 0, cb = 0, cr = 0;
                yuyvSamples(u, v, k, &y, &cb, &cr);
                int cb_pair = 0, cr_pair = 0, unused = 0;
                yuyvSamples(u - u % 2, v, k, &unused, &cb_pair, &unused);
                yuyvSamples(u - u % 2 + 1, v, k, &unused, &unused, &cr_pair);
                c(u, v) = yuvToRgb(y, cb_pair, cr_pair);
            } else {
                c(u, v) = patternPixel(u, v, k);
            }
        }
    }
    return c;
}

V4l2Config colourConfigFor(const V4l2Recording& depth, const V4l2Recording& colour) {
    V4l2Config c = configFor(depth);
    c.colour_device = colour.path;
    return c;
}

/// Reads frames until `n` came or an error; checks each frame's colour against its own sequence
/// number (or its absence when `missing(k)`); returns how many frames had colour.
size_t checkColourFrames(V4l2Source& source, size_t n, uint32_t format,
                         const std::vector<DepthImage>& depth,
                         const std::function<bool(int64_t)>& missing) {
    size_t with = 0;
    for (size_t i = 0; i < n; ++i) {
        auto frame = source.next();
        EXPECT_TRUE(frame.isOk()) << frame.status().toString();
        if (!frame.isOk()) break;
        const int64_t k = source.lastSequence();
        expectFrameEquals(*frame, depth[static_cast<size_t>(k)]);
        if (missing(k)) {
            EXPECT_TRUE(frame->colour.empty()) << "frame " << k;
            continue;
        }
        EXPECT_FALSE(frame->colour.empty()) << "frame " << k;
        if (frame->colour.empty()) continue;
        ++with;
        EXPECT_TRUE(frame->colour == expectedColour(format, kW, kH, k)) << "frame " << k;
    }
    return with;
}

TEST(V4l2Colour, Rgb24NodeIsPairedWithEachDepthFrame) {
    const auto frames = simFrames(6);
    const V4l2Recording depth = makeRecording(frames, V4L2_PIX_FMT_Z16);
    const V4l2Recording colour = makeColourRecording(6, V4L2_PIX_FMT_RGB24, kW, kH, 1000);
    auto depth_io = std::make_shared<ReplayIo>(depth);
    auto colour_io = std::make_shared<ReplayIo>(colour);
    V4l2Config config = colourConfigFor(depth, colour);
    config.colour_format = "RGB3";
    {
        auto source = V4l2Source::open(config, depth_io, colour_io);
        ASSERT_TRUE(source.isOk()) << source.status().toString();
        EXPECT_TRUE((*source)->hasColour());
        EXPECT_EQ((*source)->colourFormat(), V4L2_PIX_FMT_RGB24);
        EXPECT_NE((*source)->description().find("not registered to depth"), std::string::npos)
            << (*source)->description();
        EXPECT_EQ(checkColourFrames(**source, 6, V4L2_PIX_FMT_RGB24, frames,
                                    [](int64_t) { return false; }),
                  6u);
        EXPECT_EQ((*source)->framesWithColour(), 6u);
    }
    EXPECT_EQ(colour_io->openDescriptors(), 0);  // the colour node is released too
    EXPECT_EQ(colour_io->mappings(), 0);
}

TEST(V4l2Colour, YuyvWithAnOffsetAndDroppedColourFramesPairsByTimestamp) {
    // Colour 6 ms after depth (within half a 33 ms period), every third colour frame missing: no
    // depth frame may take a neighbour's colour.
    const auto frames = simFrames(9);
    const V4l2Recording depth = makeRecording(frames, V4L2_PIX_FMT_Z16);
    const V4l2Recording colour = makeColourRecording(9, V4L2_PIX_FMT_YUYV, kW, kH, 6000, 3);
    auto source =
        V4l2Source::open(colourConfigFor(depth, colour), std::make_shared<ReplayIo>(depth),
                         std::make_shared<ReplayIo>(colour));
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_EQ((*source)->colourFormat(), V4L2_PIX_FMT_YUYV);  // the first format it decodes
    EXPECT_EQ(checkColourFrames(**source, 9, V4L2_PIX_FMT_YUYV, frames,
                                [](int64_t k) { return (k + 1) % 3 == 0; }),
              6u);
    EXPECT_EQ((*source)->framesWithoutColour(), 3u);
}

TEST(V4l2Colour, ColourOfAnotherSizeIsResizedToTheDepth) {
    const auto frames = simFrames(2);
    const V4l2Recording depth = makeRecording(frames, V4L2_PIX_FMT_Z16);
    const V4l2Recording colour = makeColourRecording(2, V4L2_PIX_FMT_RGB24, 2 * kW, 2 * kH, 0);
    V4l2Config config = colourConfigFor(depth, colour);
    config.colour_width = 2 * kW;
    config.colour_height = 2 * kH;
    auto source = V4l2Source::open(config, std::make_shared<ReplayIo>(depth),
                                   std::make_shared<ReplayIo>(colour));
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_NE((*source)->description().find("resized to depth"), std::string::npos);
    auto frame = (*source)->next();
    ASSERT_TRUE(frame.isOk()) << frame.status().toString();
    ASSERT_EQ(frame->colour.width(), kW);
    ASSERT_EQ(frame->colour.height(), kH);
    // Depth pixel (u, v) covers colour pixels (2u, 2v)..(2u + 1, 2v + 1): the mean of the pair.
    EXPECT_NEAR(frame->colour(10, 20).g, 2 * 20 + 0.5, 1.0);
    EXPECT_NEAR(frame->colour(10, 20).r, 2 * 10 + 0.5, 1.0);
}

TEST(V4l2Colour, DamagedColourLeavesTheDepthFrameAndBadNodesAreRefused) {
    const auto frames = simFrames(3);
    const V4l2Recording depth = makeRecording(frames, V4L2_PIX_FMT_Z16);
    V4l2Recording colour = makeColourRecording(3, V4L2_PIX_FMT_RGB24, kW, kH, 0);
    colour.buffers[1].bytesused = colour.sizeimage / 2;  // short
    auto source =
        V4l2Source::open(colourConfigFor(depth, colour), std::make_shared<ReplayIo>(depth),
                         std::make_shared<ReplayIo>(colour));
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_EQ(checkColourFrames(**source, 3, V4L2_PIX_FMT_RGB24, frames,
                                [](int64_t k) { return k == 1; }),
              2u);

    // A node that does not exist, one without a colour format, a forced format not offered.
    V4l2Config missing = colourConfigFor(depth, colour);
    missing.colour_device = "/dev/video-plumb-none";
    auto none = V4l2Source::open(missing, std::make_shared<ReplayIo>(depth),
                                 std::make_shared<ReplayIo>(colour));
    ASSERT_FALSE(none.isOk());
    EXPECT_EQ(none.status().code(), StatusCode::kNotFound);
    EXPECT_NE(none.status().message().find("colour node"), std::string::npos);
    V4l2Recording grey = colour;
    grey.formats = {V4L2_PIX_FMT_GREY};
    grey.pixelformat = V4L2_PIX_FMT_GREY;
    auto no_format =
        V4l2Source::open(colourConfigFor(depth, grey), std::make_shared<ReplayIo>(depth),
                         std::make_shared<ReplayIo>(grey));
    ASSERT_FALSE(no_format.isOk());
    EXPECT_EQ(no_format.status().code(), StatusCode::kUnsupported);
    EXPECT_NE(no_format.status().message().find("offers GREY"), std::string::npos)
        << no_format.status().toString();
    V4l2Config forced = colourConfigFor(depth, colour);
    forced.colour_format = "BGR3";
    auto not_offered = V4l2Source::open(forced, std::make_shared<ReplayIo>(depth),
                                        std::make_shared<ReplayIo>(colour));
    ASSERT_FALSE(not_offered.isOk());
    EXPECT_NE(not_offered.status().message().find("does not offer BGR3"), std::string::npos)
        << not_offered.status().toString();
}

TEST(V4l2Colour, AfterAnUnplugTheColourNodeReopensWithTheDepthNode) {
    const auto frames = simFrames(7);
    const V4l2Recording depth = makeRecording(frames, V4L2_PIX_FMT_Z16);
    const V4l2Recording colour = makeColourRecording(7, V4L2_PIX_FMT_RGB24, kW, kH, 0);
    auto depth_io = std::make_shared<ReplayIo>(depth);
    auto colour_io = std::make_shared<ReplayIo>(colour);
    depth_io->setUnplugAfter(3);
    depth_io->setReplugAfterOpens(2);
    auto source = V4l2Source::open(colourConfigFor(depth, colour), depth_io, colour_io);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    size_t delivered = 0, with_colour_after = 0;
    bool released = false;
    for (int call = 0; call < 20 && delivered < 7; ++call) {
        auto frame = (*source)->next();
        if (!frame.isOk()) {
            ASSERT_EQ(frame.status().code(), StatusCode::kUnavailable) << frame.status().toString();
            released |= colour_io->openDescriptors() == 0 && colour_io->mappings() == 0;
            continue;
        }
        ++delivered;
        const int64_t k = (*source)->lastSequence();
        if (!frame->colour.empty()) {
            EXPECT_TRUE(frame->colour == expectedColour(V4L2_PIX_FMT_RGB24, kW, kH, k)) << k;
            with_colour_after += (*source)->reconnects() > 0 ? 1 : 0;
        }
    }
    EXPECT_EQ(delivered, 7u);
    EXPECT_TRUE(released);  // the colour node was closed with the depth node
    EXPECT_EQ((*source)->reconnects(), 1);
    EXPECT_GE(with_colour_after, 2u);
}

#if PLUMB_TEST_HAVE_OPENCV
TEST(V4l2Colour, MjpegFramesAreDecoded) {
    const auto frames = simFrames(3);
    const V4l2Recording depth = makeRecording(frames, V4L2_PIX_FMT_Z16);
    V4l2Recording colour = makeColourRecording(3, V4L2_PIX_FMT_RGB24, kW, kH, 0);
    colour.formats = {V4L2_PIX_FMT_MJPEG};
    colour.pixelformat = V4L2_PIX_FMT_MJPEG;
    colour.bytesperline = 0;
    for (size_t k = 0; k < colour.buffers.size(); ++k) {
        cv::Mat bgr(kH, kW, CV_8UC3);
        for (int v = 0; v < kH; ++v) {
            for (int u = 0; u < kW; ++u) {
                const Rgb8 c = patternPixel(u, v, static_cast<int64_t>(k));
                bgr.at<cv::Vec3b>(v, u) = cv::Vec3b(c.b, c.g, c.r);
            }
        }
        std::vector<uint8_t> jpeg;
        ASSERT_TRUE(cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 98}));
        colour.buffers[k].bytes = jpeg;
        colour.buffers[k].bytesused = static_cast<uint32_t>(jpeg.size());
    }
    colour.sizeimage = kW * kH * 3;
    auto source =
        V4l2Source::open(colourConfigFor(depth, colour), std::make_shared<ReplayIo>(depth),
                         std::make_shared<ReplayIo>(colour));
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_EQ((*source)->colourFormat(), V4L2_PIX_FMT_MJPEG);
    for (int64_t k = 0; k < 3; ++k) {
        auto frame = (*source)->next();
        ASSERT_TRUE(frame.isOk()) << frame.status().toString();
        ASSERT_FALSE(frame->colour.empty());
        // JPEG is lossy: compare the mean absolute error per channel.
        double error = 0.0;
        for (int v = 0; v < kH; ++v) {
            for (int u = 0; u < kW; ++u) {
                const Rgb8 a = frame->colour(u, v);
                const Rgb8 b = patternPixel(u, v, k);
                error += std::abs(a.r - b.r) + std::abs(a.g - b.g) + std::abs(a.b - b.b);
            }
        }
        EXPECT_LT(error / (3.0 * kW * kH), 3.0) << "frame " << k;
    }
}
#endif

TEST(V4l2Colour, YuvConversionAndTargetsParse) {
    EXPECT_EQ(yuvToRgb(16, 128, 128), (Rgb8{0, 0, 0}));
    EXPECT_EQ(yuvToRgb(235, 128, 128), (Rgb8{255, 255, 255}));
    const Rgb8 red = yuvToRgb(81, 90, 240);  // BT.601 limited-range red
    EXPECT_GE(red.r, 253);
    EXPECT_LE(red.g, 2);
    EXPECT_LE(red.b, 2);
    const Rgb8 grey = yuvToRgb(126, 128, 128);
    EXPECT_EQ(grey.r, grey.g);
    EXPECT_EQ(grey.g, grey.b);

    V4l2Config c;
    ASSERT_TRUE(parseV4l2Target(
                    "/dev/video4?colour=/dev/video6&colour_format=YUYV&colour_size=1280x720", &c)
                    .isOk());
    EXPECT_EQ(c.device, "/dev/video4");
    EXPECT_EQ(c.colour_device, "/dev/video6");
    EXPECT_EQ(c.colour_format, "YUYV");
    EXPECT_EQ(c.colour_width, 1280);
    EXPECT_EQ(c.colour_height, 720);
    EXPECT_EQ(parseV4l2Target("/dev/video4?bogus=1", &c).code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(parseV4l2Target("/dev/video4?colour_size=12", &c).code(),
              StatusCode::kInvalidArgument);
    EXPECT_EQ(parseV4l2Target("/dev/video4?colour", &c).code(), StatusCode::kInvalidArgument);
    auto bad = openFrameSource("v4l2:/dev/video-plumb-none?colour=/dev/x&zoom=2");
    ASSERT_FALSE(bad.isOk());
    EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(bad.status().message().find("unknown key 'zoom'"), std::string::npos);

    // Short and unknown colour frames are specific errors.
    const std::vector<uint8_t> bytes(10, 0);
    EXPECT_EQ(decodeColourFrame(V4L2_PIX_FMT_RGB24, bytes, 4, 4, 0, "f").status().code(),
              StatusCode::kCorrupt);
    EXPECT_EQ(decodeColourFrame(V4L2_PIX_FMT_NV12, bytes, 4, 4, 0, "f").status().code(),
              StatusCode::kUnsupported);
    EXPECT_EQ(decodeColourFrame(V4L2_PIX_FMT_YUYV, bytes, 3, 1, 0, "f").status().code(),
              StatusCode::kCorrupt);
}

TEST(V4l2Fourcc, NamesAndParses) {
    EXPECT_EQ(fourccName(V4L2_PIX_FMT_Z16), "Z16 ");
    EXPECT_EQ(fourccName(V4L2_PIX_FMT_Y16_BE), "Y16 -BE");
    EXPECT_EQ(*parseFourcc("Z16"), V4L2_PIX_FMT_Z16);
    EXPECT_EQ(*parseFourcc("Y16 -BE"), V4L2_PIX_FMT_Y16_BE);
    EXPECT_FALSE(parseFourcc("TOOLONG").isOk());
}

}  // namespace
}  // namespace plumb::v4l2
