// SPDX-License-Identifier: Apache-2.0
#pragma once

// OpenNI2 depth cameras (PrimeSense Carmine, Asus Xtion, Orbbec Astra, Kinect through a driver)
// and OpenNI2 `.oni` recordings as a FrameSource (`openni2[:uri]`, `openni2:/path/file.oni`).
//
// Live devices: depth mode 640x480@30 or 320x240@60 (DEPTH_1_MM, or DEPTH_100_UM when that is
// what the device offers), depth-to-colour registration switched on when the device supports it,
// mirroring off, device timestamps mapped to host time (DeviceClock). When the camera vanishes
// (OpenNI2 disconnect event, or no frame within frame_timeout_ms) next() returns
// StatusCode::kUnavailable; later calls wait up to reconnect_wait_ms for the same URI to come
// back, reopen it with the same settings and stream again (reconnects() counts them).
// Recordings play in OpenNI2's "manual" speed (one frame per read, none dropped, no repeat) and
// end with kOutOfRange; their timestamps are the recorded device times.
//
// Colour (Frame::colour): when the device or recording has a colour sensor (and config.colour),
// its RGB888 stream is opened beside depth, at the depth's size and rate when offered (else the
// closest RGB888 mode, resized to the depth size), mirroring off, depth-to-colour registration on
// when the device supports it (config.registration), depth/colour frame sync requested where the
// device offers it. Each depth frame takes the colour frame whose device timestamp is closest to
// its own within colour_max_difference_us (each colour frame used once); when none has arrived
// yet, next() waits up to colour_wait_ms (at most half a frame period, so that no depth frame is
// replaced unread) for it, unless the colour stream has sent nothing yet or nothing for
// colour_stall_ms (then depth goes on alone). Recordings pair the same way, reading the colour
// frame that follows each depth frame in the file. A depth frame without a matching colour frame,
// or whose colour frame is damaged (logged), has no colour. A device without colour, or whose
// colour stream cannot be opened (logged), streams depth exactly as before. Without registration
// the colour is only roughly aligned with depth: description() says so.
//
// Thread-safety: one consumer calls next(); OpenNI2 callbacks only touch atomics and a mutex.

#include <memory>
#include <string>
#include <vector>

#include "common/frame/frame_source.hpp"

namespace plumb::openni2 {

struct OpenNI2Config;
Status recordOni(const OpenNI2Config& config, const std::string& path, size_t num_frames);

struct OpenNI2Config {
    /// Device URI (from listDevices), a `.oni` file, or empty for the first device.
    std::string uri;
    /// Depth mode: 640x480@30 or 320x240@60 (any mode the device lists is accepted).
    int width = 640;
    int height = 480;
    int fps = 30;
    /// Register depth to the colour camera when the device supports it.
    bool registration = true;
    /// No frame within this time = the device is stalled (kUnavailable), ms.
    int frame_timeout_ms = 2000;
    /// How long one next() waits for a vanished device to return, ms.
    int reconnect_wait_ms = 1000;
    /// Stop after this many frames (kOutOfRange); 0 = never.
    size_t max_frames = 0;
    /// Intrinsics override (cameraPreset name or file); empty = from the field of view.
    std::string intrinsics;
    /// Open the colour stream when the device or recording has one; false = depth only.
    bool colour = true;
    /// A colour frame pairs with a depth frame when their device timestamps differ by at most
    /// this, microseconds; 0 = half the depth frame period (16.7 ms at 30 Hz).
    int64_t colour_max_difference_us = 0;
    /// After a depth frame, how long next() waits for its colour frame, ms (capped at half the
    /// depth frame period).
    int colour_wait_ms = 10;
    /// A colour stream silent for this long is stalled: depth frames stop waiting for it, ms.
    int colour_stall_ms = 1000;
};

/// One OpenNI2 device as the drivers report it.
struct DeviceEntry {
    std::string uri;
    std::string vendor;
    std::string name;
    int usb_vendor_id = 0;
    int usb_product_id = 0;
};

/// Devices OpenNI2 can open now (initialises OpenNI2 for the call). An OpenNI2 that cannot
/// initialise (no drivers) is an error naming OpenNI2's own explanation.
Result<std::vector<DeviceEntry>> listDevices();

/// True when `uri` names an OpenNI2 recording (a .oni file) rather than a device.
bool isOniFile(const std::string& uri);

class OpenNI2Source final : public FrameSource {
  public:
    static Result<std::unique_ptr<OpenNI2Source>> open(const OpenNI2Config& config);
    ~OpenNI2Source() override;

    const PinholeCamera& camera() const override;
    Result<Frame> next() override;
    std::optional<size_t> size() const override;
    bool canSkipErrors() const override { return true; }
    std::string description() const override;

    /// The URI actually opened (the first device's when config.uri was empty).
    const std::string& uri() const;
    bool isRecording() const;
    /// True while frames can arrive (false after a disconnect until the device is reopened).
    bool connected() const;
    /// How many times the device was reopened after a disconnect.
    int reconnects() const;
    /// Whether depth-to-colour registration is on.
    bool registered() const;
    /// Whether a colour stream is open (frames may carry colour).
    bool hasColour() const;
    /// Frames returned with colour, and without it although a colour stream is open.
    size_t framesWithColour() const;
    size_t framesWithoutColour() const;
    /// OpenNI2 frame index of the last frame returned (the device's own counter).
    int lastDeviceFrameIndex() const;

    struct Impl;

  private:
    friend Status recordOni(const OpenNI2Config& config, const std::string& path,
                            size_t num_frames);
    explicit OpenNI2Source(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

/// Records at least `num_frames` depth frames of the device config.uri (same mode options as
/// OpenNI2Source) into the `.oni` file `path` with OpenNI2's recorder (lossless), from the first
/// frame the stream sends, with the colour stream too when the device has one and config.colour;
/// played back, recorded frame j (1-based) is stream frame j - 1.
Status recordOni(const OpenNI2Config& config, const std::string& path, size_t num_frames);

}  // namespace plumb::openni2
