// SPDX-License-Identifier: Apache-2.0
#include "drivers/dataset/depth_png.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <system_error>
#include <vector>

// Every build decodes PNG with libpng, whose errors and warnings become the Status message
// (libpng's default handlers would print "libpng error: ..." to stderr). Host builds encode PNG
// and decode JPEG with OpenCV; builds without OpenCV (the aarch64 device build, see toolchains/)
// encode with libpng too and read no JPEG. Both give the same pixels and the same errors.
#include <png.h>

#include <csetjmp>
// libpng reports errors by longjmp; nothing read after a jump is modified after its setjmp.
#pragma GCC diagnostic ignored "-Wclobbered"
#if PLUMB_DRIVERS_OPENCV
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#endif

namespace plumb::dataset {
namespace {

constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

// libpng from memory: the reader walks `bytes`; errors longjmp back with their message, warnings
// are kept for the message of a failure.
struct PngMemory {
    const std::vector<unsigned char>* bytes = nullptr;
    size_t offset = 0;
    std::string error;
    std::string warnings;
};

void pngRead(png_structp png, png_bytep out, png_size_t n) {
    auto* mem = static_cast<PngMemory*>(png_get_io_ptr(png));
    if (mem->offset + n > mem->bytes->size()) png_error(png, "the data ends early");
    std::memcpy(out, mem->bytes->data() + mem->offset, n);
    mem->offset += n;
}

void pngReadError(png_structp png, png_const_charp message) {
    static_cast<PngMemory*>(png_get_error_ptr(png))->error = message;
    png_longjmp(png, 1);
}

void pngReadWarning(png_structp png, png_const_charp message) {
    std::string& warnings = static_cast<PngMemory*>(png_get_error_ptr(png))->warnings;
    warnings += (warnings.empty() ? "" : "; ") + std::string(message);
}

/// The reader with plumb's handlers: nothing goes to stderr.
png_structp createPngReader(PngMemory* mem) {
    return png_create_read_struct(PNG_LIBPNG_VER_STRING, mem, pngReadError, pngReadWarning);
}

/// "<name>: cannot decode PNG (truncated or damaged, N bytes): <libpng's error>[ (warnings: ...)]"
Status pngFailure(const std::string& name, const PngMemory& mem) {
    std::string text = fmt::format("{}: cannot decode PNG (truncated or damaged, {} bytes): {}",
                                   name, mem.bytes->size(), mem.error);
    if (!mem.warnings.empty()) text += " (warnings: " + mem.warnings + ")";
    return corrupt(text);
}

#if PLUMB_DRIVERS_OPENCV
const char* bitDepthName(int cv_depth) {
    switch (cv_depth) {
        case CV_8U:
        case CV_8S:
            return "8-bit";
        case CV_16U:
        case CV_16S:
            return "16-bit";
        case CV_32S:
        case CV_32F:
            return "32-bit";
        case CV_64F:
            return "64-bit";
        default:
            return "unknown";
    }
}
#else
struct PngOut {
    std::vector<unsigned char> bytes;
    std::string error;
};

void pngWrite(png_structp png, png_bytep data, png_size_t n) {
    auto* out = static_cast<PngOut*>(png_get_io_ptr(png));
    out->bytes.insert(out->bytes.end(), data, data + n);
}

void pngFlush(png_structp) {}

void pngWriteError(png_structp png, png_const_charp message) {
    static_cast<PngOut*>(png_get_error_ptr(png))->error = message;
    png_longjmp(png, 1);
}

void pngWriteWarning(png_structp, png_const_charp) {}

// Encodes an image of 8 or 16 bits per sample (native-endian samples), `channels` 1 (grey) or 3
// (RGB), as PNG.
Status encodePng(const std::filesystem::path& path, const void* pixels, int width, int height,
                 int bit_depth, int channels, std::vector<unsigned char>* bytes) {
    PngOut out;
    png_structp png =
        png_create_write_struct(PNG_LIBPNG_VER_STRING, &out, pngWriteError, pngWriteWarning);
    if (png == nullptr) return ioError(fmt::format("cannot encode {} as PNG", path.string()));
    png_infop info = png_create_info_struct(png);
    const size_t bytes_per_row = static_cast<size_t>(width) * channels * (bit_depth / 8);
    std::vector<png_bytep> rows(static_cast<size_t>(height));
    for (int v = 0; v < height; ++v) {
        rows[v] = const_cast<png_bytep>(static_cast<const unsigned char*>(pixels) +  // NOLINT
                                        bytes_per_row * v);
    }
    if (info == nullptr || setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return ioError(fmt::format("cannot encode {} as PNG: {}", path.string(), out.error));
    }
    png_set_write_fn(png, &out, pngWrite, pngFlush);
    png_set_IHDR(png, info, width, height, bit_depth,
                 channels == 3 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    if (bit_depth == 16) png_set_swap(png);  // PNG is big-endian; our samples are native
    png_write_image(png, rows.data());
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    *bytes = std::move(out.bytes);
    return Status::ok();
}
#endif

/// The whole file; `what` ("depth image", "colour image") names it in errors.
Result<std::vector<unsigned char>> readBytes(const std::filesystem::path& path, const char* what) {
    const std::string name = path.string();
    std::error_code ec;
    const auto file_status = std::filesystem::status(path, ec);
    if (!std::filesystem::exists(file_status)) {
        return notFound(fmt::format("{} {} does not exist", what, name));
    }
    if (!std::filesystem::is_regular_file(file_status)) {
        return corrupt(fmt::format("{} {} is not a regular file", what, name));
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) return ioError(fmt::format("cannot open {} {}", what, name));
    std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)),
                                     std::istreambuf_iterator<char>());
    if (in.bad()) return ioError(fmt::format("cannot read {} {}", what, name));
    return bytes;
}

bool isPng(const std::vector<unsigned char>& bytes) {
    return bytes.size() >= sizeof(kPngSignature) &&
           std::memcmp(bytes.data(), kPngSignature, sizeof(kPngSignature)) == 0;
}

/// JPEG files start with an SOI marker followed by another marker.
bool isJpeg(const std::vector<unsigned char>& bytes) {
    return bytes.size() >= 3 && bytes[0] == 0xff && bytes[1] == 0xd8 && bytes[2] == 0xff;
}

Status writeBytes(const std::filesystem::path& path, const std::vector<unsigned char>& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) return ioError(fmt::format("cannot create {}", path.string()));
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
    out.flush();
    if (!out) return ioError(fmt::format("cannot write {} (disk full?)", path.string()));
    return Status::ok();
}

}  // namespace

Result<Depth16Image> readDepthPng(const std::filesystem::path& path, int width, int height) {
    const std::string name = path.string();
    auto file = readBytes(path, "depth image");
    if (!file.isOk()) return file.status();
    const std::vector<unsigned char>& bytes = *file;
    if (!isPng(bytes)) {
        return corrupt(
            fmt::format("{}: not a PNG file ({} bytes, no PNG signature)", name, bytes.size()));
    }
    PngMemory mem;
    mem.bytes = &bytes;
    png_structp png = createPngReader(&mem);
    if (png == nullptr) return corrupt(fmt::format("{}: cannot decode PNG", name));
    png_infop info = png_create_info_struct(png);
    Depth16Image out;
    std::string shape_error;
    if (info == nullptr || setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, nullptr);
        return pngFailure(name, mem);
    }
    png_set_read_fn(png, &mem, pngRead);
    png_read_info(png, info);
    const int bit_depth = png_get_bit_depth(png, info);
    const int channels = png_get_channels(png, info);
    const int w = static_cast<int>(png_get_image_width(png, info));
    const int h = static_cast<int>(png_get_image_height(png, info));
    if (bit_depth != 16) {
        shape_error = fmt::format("{}: expected 16-bit depth, got {}-bit", name, bit_depth);
    } else if (channels != 1) {
        shape_error = fmt::format("{}: expected 1 channel, got {}", name, channels);
    } else if (w != width || h != height) {
        shape_error = fmt::format("{}: expected {}x{}, got {}x{}", name, width, height, w, h);
    }
    if (!shape_error.empty()) {
        png_destroy_read_struct(&png, &info, nullptr);
        return corrupt(shape_error);
    }
    png_set_swap(png);  // big-endian samples to native
    png_set_interlace_handling(png);
    png_read_update_info(png, info);
    out = Depth16Image(width, height);
    std::vector<png_bytep> rows(static_cast<size_t>(height));
    for (int v = 0; v < height; ++v) rows[v] = reinterpret_cast<png_bytep>(&out(0, v));
    png_read_image(png, rows.data());
    png_read_end(png, nullptr);
    png_destroy_read_struct(&png, &info, nullptr);
    return out;
}

Status writeDepthPng(const std::filesystem::path& path, const Depth16Image& depth) {
    PLUMB_CHECK(!depth.empty()) << "writing an empty depth image to " << path;
#if !PLUMB_DRIVERS_OPENCV
    std::vector<unsigned char> bytes;
    PLUMB_RETURN_IF_ERROR(
        encodePng(path, depth.data(), depth.width(), depth.height(), 16, 1, &bytes));
#else
    // OpenCV does not modify the buffer when encoding; the const_cast only satisfies cv::Mat.
    const cv::Mat mat(depth.height(), depth.width(), CV_16UC1,
                      const_cast<uint16_t*>(depth.data()));  // NOLINT
    std::vector<unsigned char> bytes;
    try {
        if (!cv::imencode(".png", mat, bytes)) {
            return ioError(fmt::format("cannot encode {} as PNG", path.string()));
        }
    } catch (const cv::Exception& e) {
        return ioError(fmt::format("cannot encode {} as PNG: {}", path.string(), e.what()));
    }
#endif
    return writeBytes(path, bytes);
}

Status writeGrayPng(const std::filesystem::path& path, const GrayImage& gray) {
    PLUMB_CHECK(!gray.empty()) << "writing an empty grey image to " << path;
    std::vector<unsigned char> bytes;
#if !PLUMB_DRIVERS_OPENCV
    PLUMB_RETURN_IF_ERROR(encodePng(path, gray.data(), gray.width(), gray.height(), 8, 1, &bytes));
#else
    const cv::Mat mat(gray.height(), gray.width(), CV_8UC1,
                      const_cast<uint8_t*>(gray.data()));  // NOLINT
    try {
        if (!cv::imencode(".png", mat, bytes)) {
            return ioError(fmt::format("cannot encode {} as PNG", path.string()));
        }
    } catch (const cv::Exception& e) {
        return ioError(fmt::format("cannot encode {} as PNG: {}", path.string(), e.what()));
    }
#endif
    return writeBytes(path, bytes);
}

namespace {

/// Decodes an 8-bit PNG to RGB (palettes expanded, alpha dropped); errors name `name`.
Result<ColourImage> decodeColourPng(const std::vector<unsigned char>& bytes,
                                    const std::string& name) {
    PngMemory mem;
    mem.bytes = &bytes;
    png_structp png = createPngReader(&mem);
    if (png == nullptr) return corrupt(fmt::format("{}: cannot decode PNG", name));
    png_infop info = png_create_info_struct(png);
    ColourImage out;
    std::string shape_error;
    if (info == nullptr || setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, nullptr);
        return pngFailure(name, mem);
    }
    png_set_read_fn(png, &mem, pngRead);
    png_read_info(png, info);
    const int bit_depth = png_get_bit_depth(png, info);
    const int color_type = png_get_color_type(png, info);
    const int channels = png_get_channels(png, info);
    if (bit_depth == 16) {
        shape_error = fmt::format("{}: expected 8-bit colour, got 16-bit", name);
    } else if ((color_type & PNG_COLOR_MASK_COLOR) == 0) {
        shape_error = fmt::format("{}: expected 3 channels (RGB), got {}", name, channels);
    }
    if (!shape_error.empty()) {
        png_destroy_read_struct(&png, &info, nullptr);
        return corrupt(shape_error);
    }
    if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
    // Alpha, stored or from a transparency chunk (which palette expansion turns into alpha).
    if ((color_type & PNG_COLOR_MASK_ALPHA) != 0 || png_get_valid(png, info, PNG_INFO_tRNS)) {
        png_set_strip_alpha(png);
    }
    png_set_interlace_handling(png);
    png_read_update_info(png, info);
    const int w = static_cast<int>(png_get_image_width(png, info));
    const int h = static_cast<int>(png_get_image_height(png, info));
    if (png_get_channels(png, info) != 3 || png_get_rowbytes(png, info) != size_t{3} * w) {
        png_destroy_read_struct(&png, &info, nullptr);
        return corrupt(fmt::format("{}: cannot convert the PNG to 8-bit RGB", name));
    }
    out = ColourImage(w, h);
    std::vector<png_bytep> rows(static_cast<size_t>(h));
    for (int v = 0; v < h; ++v) rows[v] = reinterpret_cast<png_bytep>(&out(0, v));
    png_read_image(png, rows.data());
    png_read_end(png, nullptr);
    png_destroy_read_struct(&png, &info, nullptr);
    return out;
}

#if PLUMB_DRIVERS_OPENCV
/// Decodes an 8-bit JPEG with OpenCV (BGR) into RGB; errors name `name`.
Result<ColourImage> decodeJpegOpenCv(const std::vector<unsigned char>& bytes,
                                     const std::string& name) {
    constexpr const char* kind = "JPEG";
    cv::Mat mat;
    try {
        mat = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
    } catch (const cv::Exception& e) {
        return corrupt(fmt::format("{}: cannot decode {}: {}", name, kind, e.what()));
    }
    if (mat.empty()) {
        return corrupt(fmt::format("{}: cannot decode {} (truncated or damaged, {} bytes)", name,
                                   kind, bytes.size()));
    }
    if (mat.depth() != CV_8U) {
        return corrupt(
            fmt::format("{}: expected 8-bit colour, got {}", name, bitDepthName(mat.depth())));
    }
    if (mat.channels() != 3 && mat.channels() != 4) {
        return corrupt(fmt::format("{}: expected 3 channels (RGB), got {}", name, mat.channels()));
    }
    const int step = mat.channels();
    ColourImage out(mat.cols, mat.rows);
    for (int v = 0; v < mat.rows; ++v) {
        const uint8_t* row = mat.ptr<uint8_t>(v);
        for (int u = 0; u < mat.cols; ++u) {
            const uint8_t* bgr = row + static_cast<size_t>(step) * u;
            out(u, v) = Rgb8{bgr[2], bgr[1], bgr[0]};
        }
    }
    return out;
}
#endif

}  // namespace

Result<ColourImage> decodeColourImage(std::span<const uint8_t> data, const std::string& name) {
    const std::vector<unsigned char> bytes(data.begin(), data.end());
    const bool png = isPng(bytes);
    if (!png && !isJpeg(bytes)) {
        return corrupt(fmt::format(
            "{}: not a PNG or JPEG file ({} bytes, no PNG or JPEG signature)", name, bytes.size()));
    }
    if (png) return decodeColourPng(bytes, name);
#if PLUMB_DRIVERS_OPENCV
    return decodeJpegOpenCv(bytes, name);
#else
    return unsupported(
        fmt::format("{}: JPEG colour needs a build with OpenCV (this build reads PNG only)", name));
#endif
}

bool canDecodeJpeg() { return PLUMB_DRIVERS_OPENCV != 0; }

Result<ColourImage> readColourImage(const std::filesystem::path& path) {
    auto file = readBytes(path, "colour image");
    if (!file.isOk()) return file.status();
    return decodeColourImage(*file, path.string());
}

Result<ColourImage> readColourImage(const std::filesystem::path& path, int width, int height,
                                    ColourSize size) {
    auto colour = readColourImage(path);
    if (!colour.isOk()) return colour;
    if (colour->width() == width && colour->height() == height) return colour;
    if (size == ColourSize::kExact) {
        return corrupt(fmt::format("{}: expected {}x{}, got {}x{}", path.string(), width, height,
                                   colour->width(), colour->height()));
    }
    return resizeColour(*colour, width, height);
}

ColourImage resizeColour(const ColourImage& colour, int width, int height) {
    PLUMB_CHECK(width > 0 && height > 0 && !colour.empty())
        << "resizing a " << colour.width() << "x" << colour.height() << " colour image to " << width
        << "x" << height;
    if (colour.width() == width && colour.height() == height) return colour;
    const double sx = static_cast<double>(colour.width()) / width;
    const double sy = static_cast<double>(colour.height()) / height;
    const int max_u = colour.width() - 1;
    const int max_v = colour.height() - 1;
    ColourImage out(width, height);
    for (int v = 0; v < height; ++v) {
        const double y = std::clamp((v + 0.5) * sy - 0.5, 0.0, static_cast<double>(max_v));
        const int v0 = static_cast<int>(y);
        const int v1 = std::min(v0 + 1, max_v);
        const double fy = y - v0;
        for (int u = 0; u < width; ++u) {
            const double x = std::clamp((u + 0.5) * sx - 0.5, 0.0, static_cast<double>(max_u));
            const int u0 = static_cast<int>(x);
            const int u1 = std::min(u0 + 1, max_u);
            const double fx = x - u0;
            const auto blend = [&](uint8_t Rgb8::*channel) {
                const double top =
                    (1.0 - fx) * (colour(u0, v0).*channel) + fx * (colour(u1, v0).*channel);
                const double bottom =
                    (1.0 - fx) * (colour(u0, v1).*channel) + fx * (colour(u1, v1).*channel);
                return static_cast<uint8_t>(std::lround((1.0 - fy) * top + fy * bottom));
            };
            out(u, v) = Rgb8{blend(&Rgb8::r), blend(&Rgb8::g), blend(&Rgb8::b)};
        }
    }
    return out;
}

Status writeColourPng(const std::filesystem::path& path, const ColourImage& colour) {
    PLUMB_CHECK(!colour.empty()) << "writing an empty colour image to " << path;
    std::vector<unsigned char> bytes;
#if !PLUMB_DRIVERS_OPENCV
    PLUMB_RETURN_IF_ERROR(
        encodePng(path, colour.data(), colour.width(), colour.height(), 8, 3, &bytes));
#else
    // OpenCV encodes BGR: swap into a scratch image so the file holds RGB.
    cv::Mat mat(colour.height(), colour.width(), CV_8UC3);
    for (int v = 0; v < colour.height(); ++v) {
        uint8_t* row = mat.ptr<uint8_t>(v);
        for (int u = 0; u < colour.width(); ++u) {
            const Rgb8& c = colour(u, v);
            row[3 * u] = c.b;
            row[3 * u + 1] = c.g;
            row[3 * u + 2] = c.r;
        }
    }
    try {
        if (!cv::imencode(".png", mat, bytes)) {
            return ioError(fmt::format("cannot encode {} as PNG", path.string()));
        }
    } catch (const cv::Exception& e) {
        return ioError(fmt::format("cannot encode {} as PNG: {}", path.string(), e.what()));
    }
#endif
    return writeBytes(path, bytes);
}

}  // namespace plumb::dataset
