// SPDX-License-Identifier: Apache-2.0
#pragma once

// Opens a FrameSource from a URI:
//   dataset:<dir>     recorded dataset, layout detected (drivers/dataset)
//   sim:<scene>       simulated handheld scanner (drivers/sim)
//   openni2[:<uri>]   OpenNI2 device (first one without a URI) or .oni recording (drivers/openni2)
//   v4l2:/dev/videoN  UVC/V4L2 depth camera (drivers/v4l2)
// A bare directory path is taken as dataset:<dir>.

#include <memory>
#include <string>

#include "drivers/frame_source.hpp"

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
    /// Depth calibration (drivers/depth_calibration.hpp): empty or "sensor" = the sensor's own
    /// (the simulated sensor with the measured distortion table is calibrated with that table,
    /// like a CLAMS-calibrated camera; other sources have none), "none" = raw depth, anything
    /// else = a CLAMS / Redwood dist-model.txt file.
    std::string depth_calibration;
};

/// Opens the source and, when a depth calibration applies (SourceOptions::depth_calibration),
/// wraps it in a CalibratedSource.
Result<std::unique_ptr<FrameSource>> openFrameSource(const std::string& uri,
                                                     const SourceOptions& options = {});

/// Checks a --depth-calibration value: "", "sensor", "none" or an existing file.
Status checkDepthCalibration(const std::string& value);

}  // namespace plumb
