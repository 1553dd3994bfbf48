// SPDX-License-Identifier: Apache-2.0
#pragma once

// Opens a FrameSource from a URI:
//   dataset:<dir>     recorded dataset, layout detected (drivers/dataset)
//   sim:<scene>       simulated handheld scanner (drivers/sim)
//   openni2[:<uri>]   OpenNI2 device (first one without a URI) or .oni recording (drivers/openni2)
//   v4l2:/dev/videoN[?colour=/dev/videoM&colour_format=F&colour_size=WxH]
//                     UVC/V4L2 depth camera, with the colour of a second node (drivers/v4l2)
// A bare directory path is taken as dataset:<dir>.
//
// A live camera (openni2 device, v4l2 node) may not be plugged in yet when a program starts;
// openFrameSourceWhenPresent waits for it, woken early by USB hot-plug arrivals (ArrivalRelay).

#include <atomic>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "common/frame/frame_source.hpp"

namespace plumb {

struct SourceOptions {
    /// Intrinsics override: a preset name (see cameraPreset) or a file; empty = detect or default.
    std::string intrinsics;
    /// Depth units per metre override; 0 = the dataset's own (TUM/ICL-NUIM 5000, Redwood 1000).
    double depth_scale = 0.0;
    /// Stop after this many frames; 0 = all.
    size_t max_frames = 0;
    /// Seed for sources with randomness (the simulator's noise and hand shake).
    uint64_t seed = 1;
    /// Simulator depth noise (sim::parseNoiseMode: redwood, undistorted, parametric, off);
    /// empty = the simulator's default (redwood with the measured distortion table).
    std::string sim_noise;
    /// Live cameras (openni2, v4l2): depth mode "WxH@fps", e.g. "640x480@30" or "320x240@60".
    std::string depth_mode = "640x480@30";
    /// Deliver colour (Frame::colour) when the source has it (datasets with colour images,
    /// OpenNI2 colour streams, V4L2 colour nodes); false = depth only, as from a source without
    /// colour (`--no-colour`).
    bool colour = true;
    /// Depth calibration (drivers/calibrated_source.hpp): empty or "sensor" = the sensor's own
    /// (the simulated sensor with the measured distortion table is calibrated with that table,
    /// like a CLAMS-calibrated camera; other sources have none), "none" = raw depth, anything
    /// else = a CLAMS / Redwood dist-model.txt file.
    std::string depth_calibration;
};

/// Opens the source and, when a depth calibration applies (SourceOptions::depth_calibration),
/// wraps it in a CalibratedSource.
Result<std::unique_ptr<FrameSource>> openFrameSource(const std::string& uri,
                                                     const SourceOptions& options = {});

/// Wraps `raw` as SourceOptions::depth_calibration `choice` says (`sensor_table`: the sensor's
/// own table file, empty when it has none): in a CalibratedSource, or not at all. For sources
/// opened elsewhere (e.g. `plumb`'s store: frames). Errors: checkDepthCalibration's, and a table
/// that does not load.
Result<std::unique_ptr<FrameSource>> withDepthCalibration(std::unique_ptr<FrameSource> raw,
                                                          const std::string& choice,
                                                          const std::string& sensor_table = {});
/// Checks a --depth-calibration value: "", "sensor", "none" or an existing file.
Status checkDepthCalibration(const std::string& value);

/// Checks, without opening anything, the values a command line gives openFrameSource, so that a
/// typo is reported as such before any work: the intrinsics (empty, a camera preset, or for
/// sources other than sim: an existing file), the depth calibration (checkDepthCalibration) and
/// the scene of a sim: URI (sim::checkSceneName). Not whether the files parse or a camera is
/// there: openFrameSource says that. InvalidArgument or NotFound naming the value otherwise.
Status checkSourceArguments(const std::string& uri, const SourceOptions& options);

/// True when `uri` names a live camera (an OpenNI2 device or a V4L2 node) rather than a
/// recording, a dataset or the simulator: a camera that can be absent, leave and come back.
bool isLiveCameraUri(const std::string& uri);

/// True when opening `uri` failed with `status` because the live camera is not there (kNotFound
/// or kUnavailable from an OpenNI2 device or V4L2 node): what openFrameSourceWhenPresent waits out.
bool isAbsentCamera(const std::string& uri, const Status& status);

/// How long to wait at start for a live camera that is not plugged in.
struct CameraWait {
    /// Seconds; 0 = fail at once, < 0 = until stopped.
    double timeout_s = 0.0;
    /// Pause between open attempts, ms; a camera arrival (ArrivalRelay::arrived) ends it early.
    int retry_ms = 1000;
    /// A "still waiting" line every this many seconds.
    double report_s = 10.0;
};

/// Carries USB hot-plug arrivals (from the libusb event thread) to whoever waits for a camera:
/// first to openFrameSourceWhenPresent, then, once attached, to the open source
/// (FrameSource::cameraArrived). Thread-safe. The attached source must stay alive until it is
/// detached (attach(nullptr)) or the notifier stopped.
class ArrivalRelay {
  public:
    void arrived();
    void attach(FrameSource* source);
    /// Waits up to `ms` for an arrival not yet consumed; true when there was one.
    bool waitForArrival(int ms);

  private:
    std::mutex mutex_;
    std::condition_variable changed_;
    bool pending_ = false;
    FrameSource* source_ = nullptr;
};

/// openFrameSource, but a live camera that is absent (kNotFound / kUnavailable) is tried again
/// every `wait.retry_ms` or at the next arrival on `relay` (may be null) until it opens,
/// `wait.timeout_s` passes or `stop` returns true (both kUnavailable, naming the last error).
/// Other sources and other errors return at once. Logs the wait and its progress.
Result<std::unique_ptr<FrameSource>> openFrameSourceWhenPresent(const std::string& uri,
                                                                const SourceOptions& options,
                                                                const CameraWait& wait,
                                                                ArrivalRelay* relay,
                                                                const std::function<bool()>& stop);

}  // namespace plumb
