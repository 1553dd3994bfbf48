// SPDX-License-Identifier: Apache-2.0
#pragma once

// A frame source whose depth is undistorted with a DepthCalibration
// (common/calibration/depth_calibration.hpp) on the way out.
//
// Thread-safety: CalibratedSource is a FrameSource (one consumer thread).

#include <memory>
#include <string>

#include "common/calibration/depth_calibration.hpp"
#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"

namespace plumb {

/// A FrameSource whose frames' depth is undistorted with a DepthCalibration; everything else
/// (intrinsics, grey image, ground truth, errors, end of stream) passes through unchanged.
class CalibratedSource final : public FrameSourceDecorator {
  public:
    CalibratedSource(std::unique_ptr<FrameSource> inner, DepthCalibration calibration);

    Result<Frame> next() override;
    std::string description() const override;

  private:
    DepthCalibration calibration_;
};

}  // namespace plumb
