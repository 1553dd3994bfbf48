// SPDX-License-Identifier: Apache-2.0
#include "drivers/dataset/depth_png.hpp"

#include <fmt/format.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <system_error>
#include <vector>

// Host builds decode and encode with OpenCV; builds without OpenCV (the aarch64 device build, see
// toolchains/) use libpng directly. Both give the same pixels and the same errors.
#if PLUMB_DRIVERS_LIBPNG
#include <png.h>

#include <csetjmp>
// libpng reports errors by longjmp; nothing read after a jump is modified after its setjmp.
#pragma GCC diagnostic ignored "-Wclobbered"
#else
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#endif

namespace plumb::dataset {
namespace {

constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

#if !PLUMB_DRIVERS_LIBPNG
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
// libpng from memory: the reader walks `bytes`; errors longjmp back with their message.
struct PngMemory {
    const std::vector<unsigned char>* bytes = nullptr;
    size_t offset = 0;
    std::string error;
};

void pngRead(png_structp png, png_bytep out, png_size_t n) {
    auto* mem = static_cast<PngMemory*>(png_get_io_ptr(png));
    if (mem->offset + n > mem->bytes->size()) png_error(png, "truncated");
    std::memcpy(out, mem->bytes->data() + mem->offset, n);
    mem->offset += n;
}

void pngError(png_structp png, png_const_charp message) {
    auto* mem = static_cast<PngMemory*>(png_get_error_ptr(png));
    mem->error = message;
    png_longjmp(png, 1);
}

void pngWarning(png_structp, png_const_charp) {}

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

// Encodes a single-channel image of 8 or 16 bits (native-endian samples), or with `channels` = 3
// an 8-bit RGB image, as PNG.
Status encodePng(const std::filesystem::path& path, const void* pixels, int width, int height,
                 int bit_depth, std::vector<unsigned char>* bytes, int channels = 1) {
    PngOut out;
    png_structp png =
        png_create_write_struct(PNG_LIBPNG_VER_STRING, &out, pngWriteError, pngWarning);
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
    std::error_code ec;
    const auto file_status = std::filesystem::status(path, ec);
    if (!std::filesystem::exists(file_status)) {
        return notFound(fmt::format("depth image {} does not exist", name));
    }
    if (!std::filesystem::is_regular_file(file_status)) {
        return corrupt(fmt::format("depth image {} is not a regular file", name));
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) return ioError(fmt::format("cannot open depth image {}", name));
    std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)),
                                     std::istreambuf_iterator<char>());
    if (in.bad()) return ioError(fmt::format("cannot read depth image {}", name));
    if (bytes.size() < sizeof(kPngSignature) ||
        std::memcmp(bytes.data(), kPngSignature, sizeof(kPngSignature)) != 0) {
        return corrupt(
            fmt::format("{}: not a PNG file ({} bytes, no PNG signature)", name, bytes.size()));
    }
#if PLUMB_DRIVERS_LIBPNG
    PngMemory mem;
    mem.bytes = &bytes;
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &mem, pngError, pngWarning);
    if (png == nullptr) return corrupt(fmt::format("{}: cannot decode PNG", name));
    png_infop info = png_create_info_struct(png);
    Depth16Image out;
    std::string shape_error;
    if (info == nullptr || setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, nullptr);
        return corrupt(fmt::format("{}: cannot decode PNG (truncated or damaged, {} bytes): {}",
                                   name, bytes.size(), mem.error));
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
    out = Depth16Image(width, height);
    std::vector<png_bytep> rows(static_cast<size_t>(height));
    for (int v = 0; v < height; ++v) rows[v] = reinterpret_cast<png_bytep>(&out(0, v));
    png_read_image(png, rows.data());
    png_read_end(png, nullptr);
    png_destroy_read_struct(&png, &info, nullptr);
#else
    cv::Mat mat;
    try {
        mat = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
    } catch (const cv::Exception& e) {
        return corrupt(fmt::format("{}: cannot decode PNG: {}", name, e.what()));
    }
    if (mat.empty()) {
        return corrupt(fmt::format("{}: cannot decode PNG (truncated or damaged, {} bytes)", name,
                                   bytes.size()));
    }
    if (mat.depth() != CV_16U) {
        return corrupt(
            fmt::format("{}: expected 16-bit depth, got {}", name, bitDepthName(mat.depth())));
    }
    if (mat.channels() != 1) {
        return corrupt(fmt::format("{}: expected 1 channel, got {}", name, mat.channels()));
    }
    if (mat.cols != width || mat.rows != height) {
        return corrupt(
            fmt::format("{}: expected {}x{}, got {}x{}", name, width, height, mat.cols, mat.rows));
    }
    Depth16Image out(width, height);
    for (int v = 0; v < height; ++v) {
        std::memcpy(&out(0, v), mat.ptr<uint16_t>(v), sizeof(uint16_t) * width);
    }
#endif
    return out;
}

Status writeDepthPng(const std::filesystem::path& path, const Depth16Image& depth) {
    PLUMB_CHECK(!depth.empty()) << "writing an empty depth image to " << path;
#if PLUMB_DRIVERS_LIBPNG
    std::vector<unsigned char> bytes;
    PLUMB_RETURN_IF_ERROR(encodePng(path, depth.data(), depth.width(), depth.height(), 16, &bytes));
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
#if PLUMB_DRIVERS_LIBPNG
    PLUMB_RETURN_IF_ERROR(encodePng(path, gray.data(), gray.width(), gray.height(), 8, &bytes));
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

Status writeColourPng(const std::filesystem::path& path, const ColourImage& colour) {
    PLUMB_CHECK(!colour.empty()) << "writing an empty colour image to " << path;
    std::vector<unsigned char> bytes;
#if PLUMB_DRIVERS_LIBPNG
    PLUMB_RETURN_IF_ERROR(
        encodePng(path, colour.data(), colour.width(), colour.height(), 8, &bytes, 3));
#else
    // OpenCV encodes BGR; the file holds RGB.
    cv::Mat bgr(colour.height(), colour.width(), CV_8UC3);
    for (int v = 0; v < colour.height(); ++v) {
        const Rgb8* in = &colour(0, v);
        auto* out = bgr.ptr<unsigned char>(v);
        for (int u = 0; u < colour.width(); ++u) {
            out[3 * u] = in[u].b;
            out[3 * u + 1] = in[u].g;
            out[3 * u + 2] = in[u].r;
        }
    }
    try {
        if (!cv::imencode(".png", bgr, bytes)) {
            return ioError(fmt::format("cannot encode {} as PNG", path.string()));
        }
    } catch (const cv::Exception& e) {
        return ioError(fmt::format("cannot encode {} as PNG: {}", path.string(), e.what()));
    }
#endif
    return writeBytes(path, bytes);
}

}  // namespace plumb::dataset
