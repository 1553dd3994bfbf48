// SPDX-License-Identifier: Apache-2.0
#include "common/frame/frame_recorder.hpp"

#include <fmt/format.h>

#include <utility>

namespace plumb {

size_t frameBytes(const Frame& frame) {
    return frame.depth.size() * sizeof(float) + frame.gray.size() * sizeof(uint8_t) +
           frame.colour.size() * sizeof(Rgb8) + frame.name.size() + sizeof(Frame);
}

FrameRecorder::FrameRecorder(FrameSource& inner, size_t budget_bytes)
    : inner_(inner), budget_bytes_(budget_bytes) {
    if (budget_bytes_ == 0) drop("no memory is set aside for them");
}

void FrameRecorder::drop(std::string why) {
    if (dropped_) return;
    dropped_ = true;
    dropped_because_ = std::move(why);
    std::vector<Frame>().swap(frames_);
    bytes_ = 0;
}

Result<Frame> FrameRecorder::next() {
    Result<Frame> frame = inner_.next();
    if (!frame.isOk()) {
        if (frame.status().code() == StatusCode::kOutOfRange) {
            ended_ = true;
        } else {
            drop("a frame could not be read (" + frame.status().message() + ")");
        }
        return frame;
    }
    if (dropped_ || ended_) return frame;
    const size_t bytes = frameBytes(*frame);
    if (bytes_ + bytes > budget_bytes_) {
        drop(fmt::format("they need more than the {:.0f} MB set aside for them",
                         static_cast<double>(budget_bytes_) / 1e6));
        return frame;
    }
    frames_.push_back(*frame);
    bytes_ += bytes;
    return frame;
}

Status FrameRecorder::skip() {
    drop("a frame was skipped");
    return inner_.skip();
}

std::shared_ptr<const std::vector<Frame>> FrameRecorder::take() {
    if (!complete()) return nullptr;
    auto frames = std::make_shared<const std::vector<Frame>>(std::move(frames_));
    frames_.clear();
    bytes_ = 0;
    drop("they were handed on");
    return frames;
}

ReplaySource::ReplaySource(std::shared_ptr<const std::vector<Frame>> frames,
                           const PinholeCamera& camera, std::string description)
    : frames_(std::move(frames)), camera_(camera), description_(std::move(description)) {}

Result<Frame> ReplaySource::next() {
    if (position_ >= frames_->size()) return outOfRange("end of the kept frames");
    return (*frames_)[position_++];
}

Status ReplaySource::skip() {
    if (position_ >= frames_->size()) return outOfRange("end of the kept frames");
    ++position_;
    return Status::ok();
}

}  // namespace plumb
