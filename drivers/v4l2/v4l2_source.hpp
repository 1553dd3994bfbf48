// SPDX-License-Identifier: Apache-2.0
#pragma once

// UVC / V4L2 depth cameras (Intel RealSense D4xx/SR300, Orbbec UVC models, ToF webcams) as a
// FrameSource (`v4l2:/dev/videoN`). Opens the node, negotiates a 16-bit depth format — Z16
// (RealSense, and Intel's INVZ which uvcvideo maps to Z16), INZI (SR300: a 10-bit IR plane
// followed by a Z16 plane), Y16 / Y16_BE (Orbbec and others expose depth as 16-bit grey) — streams
// through mmap'ed buffers, maps buffer timestamps to host time, and turns the driver's failures
// into Status: a poll timeout or ENODEV (camera unplugged) is kUnavailable and later next() calls
// try to reopen the same node; short, zero-size, error-flagged buffers are kCorrupt and skipped.
//
// Colour (Frame::colour): cameras such as the RealSense D4xx expose their RGB camera as a second
// video node. With V4l2Config::colour_device (`v4l2:/dev/videoN?colour=/dev/videoM`) that node is
// streamed beside the depth node in RGB3, BGR3, YUYV or MJPG (drivers/v4l2/colour_formats.hpp),
// and each depth frame takes the colour frame whose buffer timestamp (both nodes stamp with the
// same monotonic clock) is closest to its own within colour_max_difference_us (each colour frame
// used once). When none has come yet, next() waits at most half a frame period for it unless the
// colour node has sent nothing yet or nothing for colour_stall_ms. A depth frame without a
// matching colour frame, or whose colour frame is damaged (logged), has no colour. Colour of
// another size than the depth is resized to it. The colour comes from a second camera and is NOT
// registered to the depth (pixels only roughly correspond); description() says so. A colour node
// that cannot be opened
// is an error of open(); one that vanishes later is logged and the depth goes on without colour
// until the camera is reopened.
//
// All system calls go through V4l2Io (drivers/v4l2/v4l2_io.hpp), so tests replay recordings.
// Not thread-safe: one consumer calls next().

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "common/frame/frame_source.hpp"
#include "drivers/device_clock.hpp"
#include "drivers/v4l2/v4l2_io.hpp"

namespace plumb::v4l2 {

struct V4l2Config {
    /// Device node.
    std::string device = "/dev/video0";
    /// Requested size; the driver must grant exactly this.
    int width = 640;
    int height = 480;
    /// Requested frame rate (VIDIOC_S_PARM; drivers that refuse it keep their own).
    int fps = 30;
    /// Forced pixel format (fourcc text such as "Z16 "); empty = first of Z16, INZI, Y16, Y16_BE.
    std::string format;
    /// Depth units per metre (RealSense and Orbbec default: 1000 = millimetres).
    double units_per_m = 1000.0;
    /// Number of mmap buffers requested (drivers may grant fewer; at least 2 are needed).
    int num_buffers = 4;
    /// No buffer within this time = kUnavailable, ms.
    int timeout_ms = 2000;
    /// Pause before each reopen attempt after the camera vanished, ms; a USB hot-plug arrival
    /// (cameraArrived) ends it early.
    int reconnect_wait_ms = 500;
    /// Stop after this many frames (kOutOfRange); 0 = never.
    size_t max_frames = 0;
    /// Intrinsics (cameraPreset name or file); empty = PrimeSense-like default scaled to width.
    std::string intrinsics;
    /// Colour node of the same camera (e.g. a RealSense's RGB node); empty = depth only.
    std::string colour_device;
    /// Forced colour format (fourcc text: "RGB3", "BGR3", "YUYV", "MJPG"); empty = the first of
    /// colourFormats() the node offers.
    std::string colour_format;
    /// Requested colour size; 0 = the depth size. The driver may grant another size (the colour
    /// is then resized to the depth size).
    int colour_width = 0;
    int colour_height = 0;
    /// A colour frame pairs with a depth frame when their timestamps differ by at most this,
    /// microseconds; 0 = half the depth frame period.
    int64_t colour_max_difference_us = 0;
    /// A colour node silent for this long is stalled: depth frames stop waiting for it, ms.
    int colour_stall_ms = 1000;
};

/// Parses `v4l2:` source targets: "/dev/videoN[?colour=/dev/videoM&colour_format=YUYV
/// &colour_size=WxH]" into `config` (device and colour fields). kInvalidArgument names a bad or
/// unknown key.

/// Fourcc as text ("Z16 ") and back.
std::string fourccName(uint32_t fourcc);
Result<uint32_t> parseFourcc(const std::string& text);

/// The depth formats we decode, in order of preference.
const std::vector<uint32_t>& depthFormats();

/// A V4L2 capture node as listDevices reports it.
struct NodeInfo {
    std::string path;
    std::string card;    ///< VIDIOC_QUERYCAP card name
    std::string driver;  ///< kernel driver (uvcvideo)
    std::vector<uint32_t> formats;
    bool has_depth = false;  ///< offers one of depthFormats()
};

/// Queries one node (open, QUERYCAP, ENUM_FMT, close).
Result<NodeInfo> queryNode(const std::string& path, const std::shared_ptr<V4l2Io>& io);

/// /dev/video* nodes that offer a depth format.
std::vector<NodeInfo> listDepthNodes(const std::shared_ptr<V4l2Io>& io = systemIo());

Status parseV4l2Target(const std::string& target, V4l2Config* config);

class V4l2Source final : public FrameSource {
  public:
    /// `colour_io` serves the colour node (null = `io`; tests replay each node separately).
    static Result<std::unique_ptr<V4l2Source>> open(const V4l2Config& config,
                                                    std::shared_ptr<V4l2Io> io = systemIo(),
                                                    std::shared_ptr<V4l2Io> colour_io = nullptr);
    ~V4l2Source() override;

    const PinholeCamera& camera() const override { return camera_; }
    Result<Frame> next() override;
    bool canSkipErrors() const override { return true; }
    std::string description() const override;
    /// Ends the wait before the next reopen attempt (else reconnect_wait_ms).
    void cameraArrived() override;

    uint32_t format() const { return fourcc_; }
    bool connected() const { return fd_.valid(); }
    int reconnects() const { return reconnects_; }
    /// V4L2 sequence number of the last frame returned.
    uint32_t lastSequence() const { return last_sequence_; }
    /// Whether the colour node is streaming, and its format (0 without).
    bool hasColour() const { return colour_fd_.valid(); }
    uint32_t colourFormat() const { return colour_fourcc_; }
    /// Frames returned with colour, and without it although a colour node was configured.
    size_t framesWithColour() const { return with_colour_; }
    size_t framesWithoutColour() const { return without_colour_; }

  private:
    struct ColourSample {
        uint64_t timestamp_us = 0;  ///< buffer timestamp (monotonic clock)
        uint32_t sequence = 0;
        ColourImage image;  ///< at the depth's size
    };

    V4l2Source(const V4l2Config& config, std::shared_ptr<V4l2Io> io,
               std::shared_ptr<V4l2Io> colour_io);
    Status startColour();
    void stopColour();
    /// Dequeues colour frames: waits up to `timeout_ms` for the first, then takes what is ready,
    /// stopping after one stamped later than `until_us`. A vanished node stops colour (logged).
    void drainColour(int timeout_ms, uint64_t until_us);
    /// Pairs the depth frame stamped `depth_us` with its colour frame (header comment).
    void attachColour(uint64_t depth_us, Frame* frame);
    Status start();
    void stop();
    Status queue(uint32_t index);
    Result<Frame> decode(const uint8_t* data, uint32_t bytesused, uint32_t sequence,
                         uint64_t timestamp_us);

    V4l2Config config_;
    std::shared_ptr<V4l2Io> io_;
    UniqueFd fd_;
    std::vector<MappedBuffer> buffers_;
    bool streaming_ = false;
    uint32_t fourcc_ = 0;
    uint32_t bytes_per_line_ = 0;
    PinholeCamera camera_;
    DeviceClock clock_;
    std::string card_;
    size_t returned_ = 0;
    int reconnects_ = 0;
    bool lost_ = false;  ///< the camera vanished; next() reopens
    std::string lost_reason_;
    uint32_t last_sequence_ = 0;
    std::mutex arrival_mutex_;
    std::condition_variable arrival_;
    bool arrived_ = false;  ///< a camera arrived since the last reopen attempt

    // The colour node.
    std::shared_ptr<V4l2Io> colour_io_;
    UniqueFd colour_fd_;
    std::vector<MappedBuffer> colour_buffers_;
    bool colour_streaming_ = false;
    uint32_t colour_fourcc_ = 0;
    uint32_t colour_bytes_per_line_ = 0;
    int colour_width_ = 0;
    int colour_height_ = 0;
    std::string colour_card_;
    std::deque<ColourSample> colour_frames_;
    bool colour_seen_ = false;  ///< a colour frame came since the node was opened
    std::chrono::steady_clock::time_point last_colour_time_;
    size_t with_colour_ = 0;
    size_t without_colour_ = 0;
};

}  // namespace plumb::v4l2
