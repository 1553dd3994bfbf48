// SPDX-License-Identifier: Apache-2.0
#pragma once

// 16-bit single-channel depth PNGs (TUM, ICL-NUIM, Redwood, 7-Scenes, plumb's simulator). Pixel
// values are depth units; divide by the dataset's depth scale for metres; 0 = invalid.
// Also the datasets' 8-bit colour images (PNG; JPEG where OpenCV decodes it), always returned in
// RGB order whatever the decoder's own channel order is.
//
// Thread-safety: the functions keep no state between calls; concurrent calls on different
// files are safe.

#include <filesystem>
#include <span>
#include <string>

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

/// Reads an 8-bit colour image: PNG (RGB, RGBA with the alpha dropped, or palette), or JPEG in
/// builds with OpenCV. Pixels in RGB order as stored in the file.
/// Errors, each naming the file:
///   kNotFound     the file does not exist;
///   kIoError      it exists but cannot be read;
///   kCorrupt      not a PNG/JPEG, truncated or otherwise undecodable, "expected 8-bit colour,
///                 got 16-bit", "expected 3 channels (RGB), got 1";
///   kUnsupported  a JPEG in a build without OpenCV (the aarch64 device build).
Result<ColourImage> readColourImage(const std::filesystem::path& path);

/// Decodes an 8-bit colour image held in memory (PNG or JPEG, as readColourImage; `name` names
/// it in errors, e.g. "V4L2 colour frame 12").
Result<ColourImage> decodeColourImage(std::span<const uint8_t> bytes, const std::string& name);

/// True when this build decodes JPEG (OpenCV builds; not the libpng-only device build).
bool canDecodeJpeg();

/// How readColourImage treats an image whose size differs from the depth image's.
enum class ColourSize {
    kExact,   ///< a different size is kCorrupt ("expected 640x480, got 320x240")
    kResize,  ///< resampled to the depth size (resizeColour); for unregistered colour (7-Scenes)
};

/// readColourImage, then checks or adapts the size to `width` x `height` as `size` says.
Result<ColourImage> readColourImage(const std::filesystem::path& path, int width, int height,
                                    ColourSize size);

/// Bilinear resampling of `colour` to `width` x `height` (> 0), pixel centres aligned
/// (u_src = (u + 0.5) * w_src / width - 0.5, clamped at the borders); a same-size call copies.
ColourImage resizeColour(const ColourImage& colour, int width, int height);

/// Writes an 8-bit RGB PNG (lossless; RGB order in the file, as PNG defines it).
Status writeColourPng(const std::filesystem::path& path, const ColourImage& colour);

}  // namespace plumb::dataset
