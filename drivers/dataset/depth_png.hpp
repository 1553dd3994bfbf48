// SPDX-License-Identifier: Apache-2.0
#pragma once

// 16-bit single-channel depth PNGs (TUM, ICL-NUIM, Redwood, 7-Scenes, plumb's simulator). Pixel
// values are depth units; divide by the dataset's depth scale for metres; 0 = invalid.

#include <filesystem>

#include "common/core/status.hpp"
#include "common/image/image.hpp"

namespace plumb::dataset {

/// Reads a depth PNG that must be 16-bit, single channel, `width` x `height`.
/// Errors, each naming the file:
///   kNotFound  the file does not exist;
///   kIoError   it exists but cannot be read;
///   kCorrupt   not a PNG, truncated or otherwise undecodable, "expected 16-bit depth, got 8-bit",
///              "expected 1 channel, got 3", "expected 640x480, got 320x240".
Result<Depth16Image> readDepthPng(const std::filesystem::path& path, int width, int height);

/// Writes a 16-bit single-channel PNG (lossless; round trip is exact).
Status writeDepthPng(const std::filesystem::path& path, const Depth16Image& depth);

/// Writes an 8-bit single-channel PNG (grey images of the simulator).
Status writeGrayPng(const std::filesystem::path& path, const GrayImage& gray);

/// Writes an 8-bit 3-channel PNG in RGB order (colour images of the simulator; lossless).
Status writeColourPng(const std::filesystem::path& path, const ColourImage& colour);

}  // namespace plumb::dataset
