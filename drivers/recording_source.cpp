// SPDX-License-Identifier: Apache-2.0
#include "drivers/recording_source.hpp"

#include <Eigen/Geometry>
#include <system_error>

#include "common/core/logging.hpp"
#include "drivers/dataset/depth_png.hpp"
#include "drivers/dataset/intrinsics_file.hpp"

namespace plumb {

/// Creates `path` with `header` written and flushed.
Result<RecordingSource::File> RecordingSource::openList(const std::filesystem::path& path,
                                                        const char* header) {
    File file(std::fopen(path.c_str(), "w"));
    if (file == nullptr) {
        return ioError(fmt::format("cannot create {}: {}", path.string(),
                                   std::error_code(errno, std::generic_category()).message()));
    }
    if (std::fputs(header, file.get()) < 0 || std::fflush(file.get()) != 0) {
        return ioError("cannot write " + path.string());
    }
    return file;
}

RecordingSource::RecordingSource(std::unique_ptr<FrameSource> inner, std::filesystem::path dir)
    : FrameSourceDecorator(std::move(inner)), dir_(std::move(dir)) {}

Status RecordingSource::checkFolder(const std::filesystem::path& dir) {
    std::error_code ec;
    if (std::filesystem::exists(dir / "depth.txt", ec)) {
        return failedPrecondition(fmt::format(
            "{} already holds a recording (depth.txt); choose a new folder", dir.string()));
    }
    return Status::ok();
}

Result<std::unique_ptr<RecordingSource>> RecordingSource::create(std::unique_ptr<FrameSource> inner,
                                                                 const std::filesystem::path& dir) {
    if (inner == nullptr) return invalidArgument("RecordingSource needs a source");
    PLUMB_RETURN_IF_ERROR(checkFolder(dir));
    std::error_code ec;
    std::filesystem::create_directories(dir / "depth", ec);
    if (ec) {
        return ioError(fmt::format("cannot create the recording folder {}: {}",
                                   (dir / "depth").string(), ec.message()));
    }
    PLUMB_RETURN_IF_ERROR(
        dataset::writeIntrinsicsJson(dir / "intrinsics.json", inner->camera(), kDepthScale));
    std::unique_ptr<RecordingSource> source(new RecordingSource(std::move(inner), dir));
    auto depth = openList(dir / "depth.txt",
                          "# depth maps recorded by plumb-device\n# timestamp filename\n");
    if (!depth.isOk()) return depth.status();
    source->depth_list_ = std::move(depth).value();
    auto capture = openList(dir / "capture.txt", "# index timestamp source frame name\n");
    if (!capture.isOk()) return capture.status();
    source->capture_list_ = std::move(capture).value();
    return source;
}

std::string RecordingSource::description() const {
    return fmt::format("{}, recorded to {}", inner().description(), dir_.string());
}

Result<Frame> RecordingSource::next() {
    auto frame = inner().next();
    if (!frame.isOk()) return frame;
    PLUMB_RETURN_IF_ERROR(record(*frame));
    return frame;
}

Status RecordingSource::appendLine(const File& file, const char* what, const std::string& line) {
    if (std::fputs(line.c_str(), file.get()) < 0 || std::fflush(file.get()) != 0) {
        return ioError(fmt::format("recording {}: cannot append to {}: {}", dir_.string(), what,
                                   std::error_code(errno, std::generic_category()).message()));
    }
    return Status::ok();
}

Status RecordingSource::writeColour(const Frame& frame, const std::string& number) {
    if (frame.colour.width() != frame.depth.width() ||
        frame.colour.height() != frame.depth.height()) {
        return failedPrecondition(fmt::format(
            "recording {}: frame {} has {}x{} colour for {}x{} depth (colour must be registered "
            "to the depth)",
            dir_.string(), frame.index, frame.colour.width(), frame.colour.height(),
            frame.depth.width(), frame.depth.height()));
    }
    if (colour_list_ == nullptr) {
        std::error_code ec;
        std::filesystem::create_directories(dir_ / "rgb", ec);
        if (ec) {
            return ioError(
                fmt::format("cannot create {}: {}", (dir_ / "rgb").string(), ec.message()));
        }
    }
    return dataset::writeColourPng(dir_ / "rgb" / (number + ".png"), frame.colour);
}

Status RecordingSource::listColour(const Frame& frame, const std::string& number) {
    const std::string stamp = fmt::format("{:.6f}", frame.timestamp_s);
    const std::string colour_line = fmt::format("{} rgb/{}.png\n", stamp, number);
    const std::string pair_line =
        fmt::format("{} depth/{}.png {} rgb/{}.png\n", stamp, number, stamp, number);
    // The lists are created together with their first line, so neither is ever without one.
    if (colour_list_ == nullptr) {
        auto list = openList(
            dir_ / "rgb.txt",
            ("# colour images recorded by plumb-device\n# timestamp filename\n" + colour_line)
                .c_str());
        if (!list.isOk()) return list.status();
        colour_list_ = std::move(list).value();
    } else {
        PLUMB_RETURN_IF_ERROR(appendLine(colour_list_, "rgb.txt", colour_line));
    }
    if (associations_ == nullptr) {
        auto pairs = openList(dir_ / "associations.txt",
                              ("# timestamp depth timestamp colour\n" + pair_line).c_str());
        if (!pairs.isOk()) return pairs.status();
        associations_ = std::move(pairs).value();
        return Status::ok();
    }
    return appendLine(associations_, "associations.txt", pair_line);
}

Status RecordingSource::record(const Frame& frame) {
    const std::string number = fmt::format("{:06d}", recorded_);
    const std::string name = "depth/" + number + ".png";
    PLUMB_RETURN_IF_ERROR(dataset::writeDepthPng(dir_ / name, toRaw(frame.depth, kDepthScale)));
    const bool colour = !frame.colour.empty();
    if (colour) PLUMB_RETURN_IF_ERROR(writeColour(frame, number));
    // The images first, then the lines that list them: a cut-off recording lists only whole
    // frames.
    if (frame.T_W_C_gt) {
        if (ground_truth_ == nullptr) {
            auto gt = openList(dir_ / "groundtruth.txt", "# timestamp tx ty tz qx qy qz qw\n");
            if (!gt.isOk()) return gt.status();
            ground_truth_ = std::move(gt).value();
        }
        Eigen::Quaterniond q(frame.T_W_C_gt->rotation());
        if (q.w() < 0.0) q.coeffs() = -q.coeffs();
        const Eigen::Vector3d t = frame.T_W_C_gt->translation();
        PLUMB_RETURN_IF_ERROR(
            appendLine(ground_truth_, "groundtruth.txt",
                       fmt::format("{:.6f} {} {} {} {} {} {} {}\n", frame.timestamp_s, t.x(), t.y(),
                                   t.z(), q.x(), q.y(), q.z(), q.w())));
    }
    PLUMB_RETURN_IF_ERROR(
        appendLine(capture_list_, "capture.txt",
                   fmt::format("{} {:.6f} {}\n", frame.index, frame.timestamp_s, frame.name)));
    PLUMB_RETURN_IF_ERROR(
        appendLine(depth_list_, "depth.txt", fmt::format("{:.6f} {}\n", frame.timestamp_s, name)));
    ++recorded_;
    // The colour lists after depth.txt: associations.txt never names a depth image that depth.txt
    // does not list (a recording cut off here has this frame without colour).
    if (colour) PLUMB_RETURN_IF_ERROR(listColour(frame, number));
    return Status::ok();
}

}  // namespace plumb
