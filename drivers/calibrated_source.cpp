// SPDX-License-Identifier: Apache-2.0
#include "drivers/calibrated_source.hpp"

#include <fmt/format.h>

#include <utility>

namespace plumb {

CalibratedSource::CalibratedSource(std::unique_ptr<FrameSource> inner, DepthCalibration calibration)
    : FrameSourceDecorator(std::move(inner)), calibration_(std::move(calibration)) {}

Result<Frame> CalibratedSource::next() {
    Result<Frame> frame = inner().next();
    if (!frame.isOk()) return frame;
    frame->depth = calibration_.undistort(std::move(frame->depth));
    return frame;
}

std::string CalibratedSource::description() const {
    return fmt::format("{}, depth calibrated with {}", inner().description(),
                       calibration_.source());
}

}  // namespace plumb
