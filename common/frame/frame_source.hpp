// SPDX-License-Identifier: Apache-2.0
#pragma once

// The frame vocabulary shared by device and backend: every source of depth frames (sensors,
// recorded datasets, LCM-log replay, the simulated scanner; their implementations live in drivers/)
// sits behind FrameSource, so the pipeline cannot tell them apart.

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "common/camera/pinhole.hpp"
#include "common/core/status.hpp"
#include "common/image/image.hpp"

namespace plumb {

struct Frame {
    int64_t index = 0;         ///< 0-based position in the stream
    double timestamp_s = 0.0;  ///< capture time in seconds (dataset or host clock)
    DepthImage depth;          ///< metres, 0 = invalid, camera().width x camera().height
    GrayImage gray;            ///< optional intensity image (empty when the source has none)
    /// 8-bit RGB registered to `depth` (pixel (u, v) sees what depth pixel (u, v) sees, same
    /// size), or empty when the source has no colour. Sources whose colour camera is not
    /// registered to the depth camera (7-Scenes) say so in their description.
    ColourImage colour;
    std::string name;  ///< file name or other identifier, for messages
    /// Ground-truth camera-to-world pose, when the source knows it (datasets, simulator).
    std::optional<Eigen::Isometry3d> T_W_C_gt;
};

/// A stream of depth frames. Not thread-safe: one consumer calls next() at a time.
class FrameSource {
  public:
    virtual ~FrameSource() = default;

    /// Intrinsics of every frame this source yields.
    virtual const PinholeCamera& camera() const = 0;

    /// The next frame. At the end of the stream returns StatusCode::kOutOfRange; any other error
    /// (corrupt file, unplugged sensor) describes that frame, and the caller may call next() again
    /// to skip it when the source allows (see `canSkipErrors`).
    virtual Result<Frame> next() = 0;

    /// Passes over the next frame without producing it: the same as next() minus the frame.
    /// Sources that can (datasets, the simulator) neither decode nor render it. At the end of the
    /// stream returns StatusCode::kOutOfRange; other errors as next().
    virtual Status skip() { return next().status(); }

    /// Number of frames when known in advance (datasets, simulator), nullopt for live sensors.
    virtual std::optional<size_t> size() const { return std::nullopt; }

    /// True when next() after an error moves on to the following frame.
    virtual bool canSkipErrors() const { return false; }

    /// One line for logs: "TUM dataset ../data/x (252 frames, 640x480 fx=...)".
    virtual std::string description() const = 0;

    /// The source that produces the frames when this one wraps another (CalibratedSource),
    /// else itself: what to ask for source-specific facts such as the simulator's ground truth.
    virtual const FrameSource& underlying() const { return *this; }

    /// A camera of the kind this source reads appeared on the bus (USB hot-plug, see
    /// drivers/usb/usb_devices.hpp): a source waiting for its unplugged camera tries to reopen it
    /// at once instead of at its next attempt. The one method that is thread-safe: it is called
    /// from the hot-plug thread while another thread is in next(). Sources that never reconnect,
    /// or that learn of arrivals from their own driver (OpenNI2), ignore it.
    virtual void cameraArrived() {}
};

/// Base of sources that wrap another one (depth calibration, recording): everything passes
/// through to `inner` unless the wrapper overrides it.
class FrameSourceDecorator : public FrameSource {
  public:
    explicit FrameSourceDecorator(std::unique_ptr<FrameSource> inner) : inner_(std::move(inner)) {}

    const PinholeCamera& camera() const override { return inner_->camera(); }
    Result<Frame> next() override { return inner_->next(); }
    Status skip() override { return inner_->skip(); }
    std::optional<size_t> size() const override { return inner_->size(); }
    bool canSkipErrors() const override { return inner_->canSkipErrors(); }
    std::string description() const override { return inner_->description(); }
    const FrameSource& underlying() const override { return inner_->underlying(); }
    void cameraArrived() override { inner_->cameraArrived(); }

  protected:
    FrameSource& inner() { return *inner_; }
    const FrameSource& inner() const { return *inner_; }

  private:
    std::unique_ptr<FrameSource> inner_;
};

}  // namespace plumb
