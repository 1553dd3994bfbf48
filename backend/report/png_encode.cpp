// SPDX-License-Identifier: Apache-2.0
#include "backend/report/png_encode.hpp"

#include <png.h>

#include <csetjmp>
#include <vector>

namespace plumb::backend {

namespace {

// libpng reports errors by longjmp; nothing read after a jump is modified after its setjmp.
struct PngOut {
    std::string bytes;
    std::string error;
};

void pngWrite(png_structp png, png_bytep data, png_size_t n) {
    auto* out = static_cast<PngOut*>(png_get_io_ptr(png));
    out->bytes.append(reinterpret_cast<const char*>(data), n);
}

void pngFlush(png_structp) {}

void pngError(png_structp png, png_const_charp message) {
    static_cast<PngOut*>(png_get_error_ptr(png))->error = message;
    png_longjmp(png, 1);
}

void pngWarning(png_structp, png_const_charp) {}

}  // namespace

Result<std::string> encodePng(const RgbImage& image) {
    if (image.width <= 0 || image.height <= 0 ||
        image.rgb.size() != 3 * static_cast<size_t>(image.width) * image.height)
        return invalidArgument("cannot encode an empty or inconsistent image as PNG");
    PngOut out;
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &out, pngError, pngWarning);
    if (png == nullptr) return ioError("cannot create a PNG encoder");
    png_infop info = png_create_info_struct(png);
    std::vector<png_bytep> rows(static_cast<size_t>(image.height));
    for (int v = 0; v < image.height; ++v)
        rows[v] = const_cast<png_bytep>(image.rgb.data() +  // NOLINT: libpng only reads rows
                                        3 * static_cast<size_t>(image.width) * v);
    if (info == nullptr || setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return ioError("cannot encode PNG: " + out.error);
    }
    png_set_write_fn(png, &out, pngWrite, pngFlush);
    png_set_compression_level(png, 9);
    png_set_IHDR(png, info, image.width, image.height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    png_write_image(png, rows.data());
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    return std::move(out.bytes);
}

std::string base64(std::string_view bytes) {
    static constexpr char kAlphabet[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    out.reserve((bytes.size() + 2) / 3 * 4);
    size_t i = 0;
    for (; i + 2 < bytes.size(); i += 3) {
        const uint32_t v = (uint32_t(uint8_t(bytes[i])) << 16) |
                           (uint32_t(uint8_t(bytes[i + 1])) << 8) | uint32_t(uint8_t(bytes[i + 2]));
        out += kAlphabet[(v >> 18) & 63];
        out += kAlphabet[(v >> 12) & 63];
        out += kAlphabet[(v >> 6) & 63];
        out += kAlphabet[v & 63];
    }
    const size_t rest = bytes.size() - i;
    if (rest > 0) {
        uint32_t v = uint32_t(uint8_t(bytes[i])) << 16;
        if (rest == 2) v |= uint32_t(uint8_t(bytes[i + 1])) << 8;
        out += kAlphabet[(v >> 18) & 63];
        out += kAlphabet[(v >> 12) & 63];
        out += rest == 2 ? kAlphabet[(v >> 6) & 63] : '=';
        out += '=';
    }
    return out;
}

std::string pngDataUri(const RgbImage& image) {
    Result<std::string> png = encodePng(image);
    if (!png.isOk()) return {};
    return "data:image/png;base64," + base64(*png);
}

}  // namespace plumb::backend
