// SPDX-License-Identifier: Apache-2.0
#include "drivers/v4l2/colour_formats.hpp"

#include <fmt/format.h>
#include <linux/videodev2.h>

#include <algorithm>

#include "drivers/dataset/depth_png.hpp"
#include "drivers/v4l2/v4l2_source.hpp"

namespace plumb::v4l2 {
namespace {

uint8_t clampByte(int value) { return static_cast<uint8_t>(std::clamp(value, 0, 255)); }

}  // namespace

const std::vector<uint32_t>& colourFormats() {
    static const std::vector<uint32_t> kFormats = [] {
        std::vector<uint32_t> f = {V4L2_PIX_FMT_RGB24, V4L2_PIX_FMT_BGR24, V4L2_PIX_FMT_YUYV};
        if (dataset::canDecodeJpeg()) f.push_back(V4L2_PIX_FMT_MJPEG);
        return f;
    }();
    return kFormats;
}

Rgb8 yuvToRgb(int y, int u, int v) {
    // The coefficients of the header comment in 8.8 fixed point (298 = 1.164 * 256, ...).
    const int c = 298 * (y - 16) + 128;
    const int d = u - 128;
    const int e = v - 128;
    return Rgb8{clampByte((c + 409 * e) >> 8), clampByte((c - 100 * d - 208 * e) >> 8),
                clampByte((c + 516 * d) >> 8)};
}

uint32_t minBytesPerLine(uint32_t fourcc, int width) {
    switch (fourcc) {
        case V4L2_PIX_FMT_RGB24:
        case V4L2_PIX_FMT_BGR24:
            return static_cast<uint32_t>(width) * 3;
        case V4L2_PIX_FMT_YUYV:
            return static_cast<uint32_t>(width) * 2;
        default:
            return 0;
    }
}

Result<ColourImage> decodeColourFrame(uint32_t fourcc, std::span<const uint8_t> bytes, int width,
                                      int height, uint32_t bytes_per_line,
                                      const std::string& what) {
    if (width <= 0 || height <= 0) {
        return corrupt(fmt::format("{}: colour size {}x{}", what, width, height));
    }
    if (fourcc == V4L2_PIX_FMT_MJPEG) {
        auto image = dataset::decodeColourImage(bytes, what);
        if (!image.isOk()) return image;
        if (image->width() != width || image->height() != height) {
            return corrupt(fmt::format("{}: JPEG is {}x{}, the stream {}x{}", what, image->width(),
                                       image->height(), width, height));
        }
        return image;
    }
    const uint32_t min_line = minBytesPerLine(fourcc, width);
    if (min_line == 0) {
        return unsupported(fmt::format("{}: colour format {} is not decoded (RGB3, BGR3, YUYV{})",
                                       what, fourccName(fourcc),
                                       dataset::canDecodeJpeg() ? ", MJPG" : ""));
    }
    if (fourcc == V4L2_PIX_FMT_YUYV && width % 2 != 0) {
        return corrupt(fmt::format("{}: YUYV needs an even width, got {}", what, width));
    }
    const uint32_t line = bytes_per_line != 0 ? bytes_per_line : min_line;
    const size_t needed = static_cast<size_t>(line) * (height - 1) + min_line;
    if (line < min_line || bytes.size() < needed) {
        return corrupt(fmt::format("{}: short colour frame: {} bytes, {} {}x{} needs {}", what,
                                   bytes.size(), fourccName(fourcc), width, height, needed));
    }
    ColourImage out(width, height);
    for (int v = 0; v < height; ++v) {
        const uint8_t* row = bytes.data() + static_cast<size_t>(line) * v;
        if (fourcc == V4L2_PIX_FMT_RGB24) {
            for (int u = 0; u < width; ++u)
                out(u, v) = Rgb8{row[3 * u], row[3 * u + 1], row[3 * u + 2]};
        } else if (fourcc == V4L2_PIX_FMT_BGR24) {
            for (int u = 0; u < width; ++u)
                out(u, v) = Rgb8{row[3 * u + 2], row[3 * u + 1], row[3 * u]};
        } else {  // YUYV: Y0 U Y1 V
            for (int u = 0; u < width; u += 2) {
                const uint8_t* p = row + 2 * u;
                out(u, v) = yuvToRgb(p[0], p[1], p[3]);
                out(u + 1, v) = yuvToRgb(p[2], p[1], p[3]);
            }
        }
    }
    return out;
}

}  // namespace plumb::v4l2
