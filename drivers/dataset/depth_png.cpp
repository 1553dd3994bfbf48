// SPDX-License-Identifier: Apache-2.0
#include "drivers/dataset/depth_png.hpp"

#include <fmt/format.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <system_error>
#include <vector>

namespace plumb::dataset {
namespace {

constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

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
    return out;
}

Status writeDepthPng(const std::filesystem::path& path, const Depth16Image& depth) {
    PLUMB_CHECK(!depth.empty()) << "writing an empty depth image to " << path;
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
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) return ioError(fmt::format("cannot create {}", path.string()));
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
    out.flush();
    if (!out) return ioError(fmt::format("cannot write {} (disk full?)", path.string()));
    return Status::ok();
}

}  // namespace plumb::dataset
