// SPDX-License-Identifier: Apache-2.0
#pragma once

// A FrameSource that only counts the hot-plug arrivals it is told about (cameraArrived), for
// tests of whatever forwards USB arrivals to a source.

#include <atomic>
#include <string>

#include "common/frame/frame_source.hpp"

namespace plumb::testing {

class ArrivalCounter final : public FrameSource {
  public:
    const PinholeCamera& camera() const override { return camera_; }
    Result<Frame> next() override { return outOfRange("no frames"); }
    std::string description() const override { return "arrival counter"; }
    void cameraArrived() override { ++arrivals; }
    std::atomic<int> arrivals{0};

  private:
    PinholeCamera camera_;
};

}  // namespace plumb::testing
