// SPDX-License-Identifier: Apache-2.0
#pragma once

// The colour pixel formats plumb reads from a V4L2 colour node (a RealSense's RGB camera is a
// second UVC node beside the depth node), decoded to 8-bit RGB:
//   RGB3 (V4L2_PIX_FMT_RGB24)  R, G, B bytes per pixel
//   BGR3 (V4L2_PIX_FMT_BGR24)  B, G, R bytes per pixel
//   YUYV (V4L2_PIX_FMT_YUYV)   Y0 U Y1 V per pixel pair, ITU-R BT.601 limited range (Y 16-235,
//                              U/V 16-240, as UVC cameras send it), both pixels of a pair share
//                              U and V
//   MJPG (V4L2_PIX_FMT_MJPEG)  one JPEG per frame; only in builds that decode JPEG (OpenCV)
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/core/status.hpp"
#include "common/image/image.hpp"

namespace plumb::v4l2 {

/// The colour formats this build decodes, in order of preference (lossless first).
const std::vector<uint32_t>& colourFormats();

/// BT.601 limited-range YCbCr to RGB, integer arithmetic (rounded, clamped to [0, 255]):
/// R = 1.164 (Y - 16) + 1.596 (V - 128), G = 1.164 (Y - 16) - 0.392 (U - 128) - 0.813 (V - 128),
/// B = 1.164 (Y - 16) + 2.017 (U - 128).
Rgb8 yuvToRgb(int y, int u, int v);

/// Decodes one frame of `fourcc`, `width` x `height`, rows `bytes_per_line` apart (ignored for
/// MJPG), from the `bytes` the driver filled. kCorrupt for too few bytes or an undecodable JPEG,
/// kUnsupported for another format; `what` names the frame in errors.
Result<ColourImage> decodeColourFrame(uint32_t fourcc, std::span<const uint8_t> bytes, int width,
                                      int height, uint32_t bytes_per_line, const std::string& what);

/// Bytes per line a format needs at `width` (0 for MJPG, whose frames vary in size).
uint32_t minBytesPerLine(uint32_t fourcc, int width);

}  // namespace plumb::v4l2
