// SPDX-License-Identifier: Apache-2.0
#pragma once

// A FrameSource decorator that records every frame it passes on as a plumb dataset folder
// (drivers/dataset/dataset.hpp, "plumb" layout), so a live scan can be replayed later with
// `--source dataset:DIR` or reconstructed with `plumb reconstruct`:
//
//   depth/NNNNNN.png   16-bit depth in millimetres (depth_scale 1000), 0 = invalid
//   depth.txt          `timestamp depth/NNNNNN.png` per frame (the frame's host/dataset stamp)
//   intrinsics.json    the source's camera and depth scale
//   capture.txt        `index timestamp name` per frame: the source's own frame name (an OpenNI2
//                      device frame number, a dataset file), to trace a recorded frame back
//   groundtruth.txt    TUM poses, only when the source knows them (simulator, datasets)
//   rgb/NNNNNN.png     8-bit RGB colour, only for frames that carry colour (Frame::colour), with
//                      the number of the depth image it belongs to
//   rgb.txt            `timestamp rgb/NNNNNN.png` per colour image (the depth frame's stamp)
//   associations.txt   `timestamp depth/NNNNNN.png timestamp rgb/NNNNNN.png` per colour image:
//                      the exact pairing, which the dataset reader prefers over matching rgb.txt
//                      stamps (frames closer than 0.02 s apart could otherwise swap colour)
//
// The colour is stored as the source delivered it (registered to the depth, the depth's size).
// Every list line is written after its image and flushed, so a scan that is cut off leaves a
// readable recording of the frames captured so far. A failed write is the frame's error
// (kIoError), never a silently incomplete recording.
//
// Not thread-safe, as every FrameSource: one consumer calls next() at a time.

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "common/frame/frame_source.hpp"

namespace plumb {

class RecordingSource final : public FrameSourceDecorator {
  public:
    /// kFailedPrecondition when `dir` already holds a recording (depth.txt): recordings are never
    /// overwritten. Lets a program refuse the folder before it opens a camera.
    static Status checkFolder(const std::filesystem::path& dir);

    /// Creates `dir` (and depth/) and writes intrinsics.json, after checkFolder.
    static Result<std::unique_ptr<RecordingSource>> create(std::unique_ptr<FrameSource> inner,
                                                           const std::filesystem::path& dir);
    Result<Frame> next() override;
    /// A skipped frame is still read and recorded: the recording keeps every frame.
    Status skip() override { return next().status(); }
    std::string description() const override;

    /// Frames recorded so far.
    size_t recorded() const { return recorded_; }

    /// Units per metre of the recorded PNGs.
    static constexpr double kDepthScale = 1000.0;

  private:
    struct FileCloser {
        void operator()(std::FILE* f) const { std::fclose(f); }
    };
    using File = std::unique_ptr<std::FILE, FileCloser>;

    RecordingSource(std::unique_ptr<FrameSource> inner, std::filesystem::path dir);
    Status record(const Frame& frame);
    static Result<File> openList(const std::filesystem::path& path, const char* header);
    Status appendLine(const File& file, const char* what, const std::string& line);
    /// Writes rgb/NNNNNN.png (creating rgb/ the first time).
    Status writeColour(const Frame& frame, const std::string& number);
    /// Lists rgb/NNNNNN.png in rgb.txt and associations.txt (created with their first line).
    Status listColour(const Frame& frame, const std::string& number);

    std::filesystem::path dir_;
    File depth_list_;
    File capture_list_;
    File ground_truth_;  ///< opened at the first frame with a pose
    File colour_list_;   ///< rgb.txt, created with the first frame with colour
    File associations_;  ///< associations.txt, created with rgb.txt
    size_t recorded_ = 0;
};

}  // namespace plumb
