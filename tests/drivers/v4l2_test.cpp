// SPDX-License-Identifier: Apache-2.0
// The V4L2 source against replayed sessions (drivers/v4l2/replay_io.hpp): recordings built from
// the simulator's frames in the byte layouts UVC depth cameras deliver (Z16, INZI, Y16-BE), an
// unplug and re-plug mid-stream, damaged buffers and unusable formats.

#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include <cstring>
#include <fstream>

#include "drivers/device_clock.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "drivers/usb/usb_devices.hpp"
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

TEST(V4l2Fourcc, NamesAndParses) {
    EXPECT_EQ(fourccName(V4L2_PIX_FMT_Z16), "Z16 ");
    EXPECT_EQ(fourccName(V4L2_PIX_FMT_Y16_BE), "Y16 -BE");
    EXPECT_EQ(*parseFourcc("Z16"), V4L2_PIX_FMT_Z16);
    EXPECT_EQ(*parseFourcc("Y16 -BE"), V4L2_PIX_FMT_Y16_BE);
    EXPECT_FALSE(parseFourcc("TOOLONG").isOk());
}

}  // namespace
}  // namespace plumb::v4l2
