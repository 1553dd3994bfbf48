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
// All system calls go through V4l2Io (drivers/v4l2/v4l2_io.hpp), so tests replay recordings.
// Not thread-safe: one consumer calls next().

#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "drivers/device_clock.hpp"
#include "drivers/frame_source.hpp"
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
};

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

class V4l2Source final : public FrameSource {
  public:
    static Result<std::unique_ptr<V4l2Source>> open(const V4l2Config& config,
                                                    std::shared_ptr<V4l2Io> io = systemIo());
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

  private:
    V4l2Source(const V4l2Config& config, std::shared_ptr<V4l2Io> io);
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
};

}  // namespace plumb::v4l2
