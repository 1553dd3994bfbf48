// SPDX-License-Identifier: Apache-2.0
#pragma once

// Row-major images with value semantics. Depth is float metres with 0 = invalid
// (DepthImage); sensors and files carry uint16 with a depth scale (units per metre).
//
// Thread-safety: value types; const access from several threads is safe, a write needs
// exclusive access.

#include <cstdint>
#include <utility>
#include <vector>

#include "common/core/check.hpp"

namespace plumb {

template <typename T>
class Image {
  public:
    Image() = default;
    Image(int width, int height, T fill = T{})
        : width_(width), height_(height), data_(static_cast<size_t>(width) * height, fill) {
        PLUMB_CHECK(width >= 0 && height >= 0) << "image size " << width << "x" << height;
    }

    /// An image holding `pixels` (row-major, width * height of them).
    Image(int width, int height, std::vector<T> pixels)
        : width_(width), height_(height), data_(std::move(pixels)) {
        PLUMB_CHECK(width >= 0 && height >= 0 &&
                    data_.size() == static_cast<size_t>(width) * static_cast<size_t>(height))
            << "image size " << width << "x" << height << " for " << data_.size() << " pixels";
    }

    int width() const { return width_; }
    int height() const { return height_; }
    size_t size() const { return data_.size(); }
    bool empty() const { return data_.empty(); }

    /// Pixel at column u, row v. Not bounds-checked in release builds; see `inside`.
    T& operator()(int u, int v) { return data_[static_cast<size_t>(v) * width_ + u]; }
    const T& operator()(int u, int v) const { return data_[static_cast<size_t>(v) * width_ + u]; }
    bool inside(int u, int v) const { return u >= 0 && v >= 0 && u < width_ && v < height_; }

    T* data() { return data_.data(); }
    const T* data() const { return data_.data(); }
    std::vector<T>& pixels() { return data_; }
    const std::vector<T>& pixels() const { return data_; }

    bool operator==(const Image& other) const = default;

  private:
    int width_ = 0;
    int height_ = 0;
    std::vector<T> data_;
};

using DepthImage = Image<float>;       ///< metres, 0 = invalid
using Depth16Image = Image<uint16_t>;  ///< raw sensor/file units, 0 = invalid
using GrayImage = Image<uint8_t>;      ///< 8-bit intensity

/// One 8-bit RGB pixel (sRGB-encoded as the camera delivers it).
struct Rgb8 {
    uint8_t r = 0;
    uint8_t g = 0;
    uint8_t b = 0;
    bool operator==(const Rgb8& other) const = default;
};
static_assert(sizeof(Rgb8) == 3, "colour images are 3 bytes a pixel");

using ColourImage = Image<Rgb8>;  ///< 8-bit RGB, row-major, 3 bytes a pixel

/// Luma of an RGB pixel in [0, 1]: I = (0.299 R + 0.587 G + 0.114 B) / 255 (ITU-R BT.601, the
/// intensity of reference §7b.1).
inline float intensity(const Rgb8& c) {
    return (0.299f * c.r + 0.587f * c.g + 0.114f * c.b) * (1.0f / 255.0f);
}

/// Intensity image in [0, 1] of a colour image (see intensity()).
Image<float> toIntensity(const ColourImage& colour);

/// uint16 units -> metres: d_m = raw / depth_scale (e.g. 1000 for mm, 5000 for TUM/ICL-NUIM).
/// Values below `min_depth_m` or above `max_depth_m` (when > 0) become 0 (invalid).
DepthImage toMetres(const Depth16Image& raw, double depth_scale, double min_depth_m = 0.0,
                    double max_depth_m = 0.0);

/// Metres -> uint16 units, rounded to nearest; invalid, non-finite and out-of-range values become
/// 0.
Depth16Image toRaw(const DepthImage& depth, double depth_scale);

/// Number of valid (> 0, finite) pixels.
size_t countValid(const DepthImage& depth);

}  // namespace plumb
