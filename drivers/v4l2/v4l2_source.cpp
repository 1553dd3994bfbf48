// SPDX-License-Identifier: Apache-2.0
#include "drivers/v4l2/v4l2_source.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <linux/videodev2.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "common/core/logging.hpp"
#include "drivers/dataset/depth_png.hpp"
#include "drivers/v4l2/colour_formats.hpp"

namespace plumb::v4l2 {
namespace {

std::string errnoText(int negative_errno) { return std::strerror(-negative_errno); }

bool isGone(int r) { return r == -ENODEV || r == -ENXIO || r == -ENOENT || r == -EIO; }

std::string cardName(const v4l2_capability& cap) {
    return std::string(reinterpret_cast<const char*>(cap.card),
                       strnlen(reinterpret_cast<const char*>(cap.card), sizeof(cap.card)));
}

/// Bytes of depth data a frame of this format needs (INZI carries an IR plane first).
size_t neededBytes(uint32_t fourcc, uint32_t bytes_per_line, int height) {
    const size_t plane = static_cast<size_t>(bytes_per_line) * height;
    return fourcc == V4L2_PIX_FMT_INZI ? 2 * plane : plane;
}

}  // namespace

std::string fourccName(uint32_t f) {
    std::string s;
    for (int i = 0; i < 4; ++i) {
        const char c = static_cast<char>((f >> (8 * i)) & 0x7f);
        s += (c >= 32 && c < 127) ? c : '?';
    }
    if ((f & (1u << 31)) != 0) s += "-BE";
    return s;
}

Result<uint32_t> parseFourcc(const std::string& text) {
    std::string t = text;
    bool be = false;
    if (t.size() > 3 && t.substr(t.size() - 3) == "-BE") {
        be = true;
        t.resize(t.size() - 3);
    }
    if (t.empty() || t.size() > 4) {
        return invalidArgument("'" + text + "' is not a fourcc (e.g. \"Z16 \", \"Y16 \", INZI)");
    }
    while (t.size() < 4) t += ' ';
    uint32_t f = v4l2_fourcc(t[0], t[1], t[2], t[3]);
    if (be) f |= 1u << 31;
    return f;
}

const std::vector<uint32_t>& depthFormats() {
    static const std::vector<uint32_t> kFormats = {V4L2_PIX_FMT_Z16, V4L2_PIX_FMT_INZI,
                                                   V4L2_PIX_FMT_Y16, V4L2_PIX_FMT_Y16_BE};
    return kFormats;
}

Result<NodeInfo> queryNode(const std::string& path, const std::shared_ptr<V4l2Io>& io) {
    const int raw = io->open(path, O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (raw < 0) {
        if (raw == -ENOENT) return notFound("V4L2 device '" + path + "' does not exist");
        if (isGone(raw)) return unavailable("V4L2 device '" + path + "' is gone");
        return ioError("cannot open V4L2 device '" + path + "': " + errnoText(raw));
    }
    UniqueFd fd(io, raw);
    v4l2_capability cap{};
    if (int r = io->ioctl(fd.get(), VIDIOC_QUERYCAP, &cap); r < 0) {
        return unsupported("'" + path + "' is not a V4L2 device (VIDIOC_QUERYCAP: " + errnoText(r) +
                           ")");
    }
    NodeInfo info;
    info.path = path;
    info.card = cardName(cap);
    info.driver = std::string(reinterpret_cast<const char*>(cap.driver),
                              strnlen(reinterpret_cast<const char*>(cap.driver), 16));
    const uint32_t caps =
        (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
    if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0) return info;  // metadata or output node
    for (uint32_t i = 0; i < 64; ++i) {
        v4l2_fmtdesc desc{};
        desc.index = i;
        desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        if (io->ioctl(fd.get(), VIDIOC_ENUM_FMT, &desc) < 0) break;
        info.formats.push_back(desc.pixelformat);
        const auto& d = depthFormats();
        if (std::find(d.begin(), d.end(), desc.pixelformat) != d.end()) info.has_depth = true;
    }
    return info;
}

std::vector<NodeInfo> listDepthNodes(const std::shared_ptr<V4l2Io>& io) {
    std::vector<std::string> paths;
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator("/dev", ec)) {
        const std::string name = entry.path().filename().string();
        if (name.rfind("video", 0) == 0) paths.push_back(entry.path().string());
    }
    std::sort(paths.begin(), paths.end());
    std::vector<NodeInfo> out;
    for (const auto& p : paths) {
        auto info = queryNode(p, io);
        if (info.isOk() && info->has_depth) out.push_back(std::move(info).value());
    }
    return out;
}

Status parseV4l2Target(const std::string& target, V4l2Config* config) {
    const auto q = target.find('?');
    config->device = target.substr(0, q);
    if (config->device.empty()) return invalidArgument("v4l2: source names no device node");
    if (q == std::string::npos) return Status::ok();
    const std::string query = target.substr(q + 1);
    size_t pos = 0;
    while (pos <= query.size()) {
        const auto amp = query.find('&', pos);
        const std::string item =
            query.substr(pos, amp == std::string::npos ? std::string::npos : amp - pos);
        pos = amp == std::string::npos ? query.size() + 1 : amp + 1;
        if (item.empty()) continue;
        const auto eq = item.find('=');
        const std::string key = item.substr(0, eq);
        const std::string value = eq == std::string::npos ? "" : item.substr(eq + 1);
        if (value.empty()) {
            return invalidArgument("v4l2 source '" + target + "': '" + item + "' is not key=value");
        }
        if (key == "colour") {
            config->colour_device = value;
        } else if (key == "colour_format") {
            auto f = parseFourcc(value);
            if (!f.isOk()) return f.status();
            config->colour_format = value;
        } else if (key == "colour_size") {
            int w = 0, h = 0;
            char x = 0, extra = 0;
            if (std::sscanf(value.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || x != 'x' ||
                w <= 0 || h <= 0) {
                return invalidArgument("v4l2 source: colour_size '" + value + "' is not WxH");
            }
            config->colour_width = w;
            config->colour_height = h;
        } else {
            return invalidArgument("v4l2 source '" + target + "': unknown key '" + key +
                                   "' (colour, colour_format, colour_size)");
        }
    }
    return Status::ok();
}

V4l2Source::V4l2Source(const V4l2Config& config, std::shared_ptr<V4l2Io> io,
                       std::shared_ptr<V4l2Io> colour_io)
    : config_(config), io_(std::move(io)), colour_io_(std::move(colour_io)) {
    if (!colour_io_) colour_io_ = io_;
}

V4l2Source::~V4l2Source() {
    stopColour();
    stop();
}

Result<std::unique_ptr<V4l2Source>> V4l2Source::open(const V4l2Config& config,
                                                     std::shared_ptr<V4l2Io> io,
                                                     std::shared_ptr<V4l2Io> colour_io) {
    if (config.width <= 0 || config.height <= 0 || config.fps <= 0 || config.num_buffers < 2 ||
        config.timeout_ms <= 0 || !(config.units_per_m > 0.0)) {
        return invalidArgument(fmt::format(
            "V4L2 source: need width, height, fps, timeout_ms, units_per_m > 0 and num_buffers "
            ">= 2 (got {}x{}@{}, timeout {} ms, {} units/m, {} buffers)",
            config.width, config.height, config.fps, config.timeout_ms, config.units_per_m,
            config.num_buffers));
    }
    if (config.colour_width < 0 || config.colour_height < 0 || config.colour_stall_ms < 0 ||
        config.colour_max_difference_us < 0) {
        return invalidArgument("V4L2 source: colour size, stall time and tolerance must be >= 0");
    }
    std::unique_ptr<V4l2Source> source(new V4l2Source(config, std::move(io), std::move(colour_io)));
    if (!config.intrinsics.empty()) {
        auto camera = cameraPreset(config.intrinsics);
        if (!camera.isOk()) return camera.status();
        if (camera->width != config.width || camera->height != config.height) {
            return invalidArgument(fmt::format("intrinsics '{}' are {}x{}, the stream {}x{}",
                                               config.intrinsics, camera->width, camera->height,
                                               config.width, config.height));
        }
        source->camera_ = *camera;
    } else {
        source->camera_ = PinholeCamera().scaled(config.width / 640.0);
        source->camera_.width = config.width;
        source->camera_.height = config.height;
    }
    PLUMB_RETURN_IF_ERROR(source->start());
    if (!config.colour_device.empty()) {
        if (Status s = source->startColour(); !s.isOk()) {
            source->stop();
            return Status(s.code(), "colour node: " + s.message());
        }
    }
    return source;
}

Status V4l2Source::startColour() {
    const std::string& path = config_.colour_device;
    auto node = queryNode(path, colour_io_);
    if (!node.isOk()) return node.status();
    colour_card_ = node->card;
    std::string offered;
    for (uint32_t f : node->formats) {
        offered += fmt::format("{}{}", offered.empty() ? "" : ", ", fourccName(f));
    }
    if (offered.empty()) offered = "nothing";
    const auto offers = [&](uint32_t f) {
        return std::find(node->formats.begin(), node->formats.end(), f) != node->formats.end();
    };
    const auto& decodable = colourFormats();
    uint32_t wanted = 0;
    if (!config_.colour_format.empty()) {
        auto f = parseFourcc(config_.colour_format);
        if (!f.isOk()) return f.status();
        if (std::find(decodable.begin(), decodable.end(), *f) == decodable.end()) {
            return unsupported("V4L2 colour format '" + config_.colour_format +
                               "' is not one this build decodes");
        }
        if (!offers(*f)) {
            return unsupported("'" + path + "' does not offer " + fourccName(*f) + " (it offers " +
                               offered + ")");
        }
        wanted = *f;
    } else {
        for (uint32_t f : decodable) {
            if (offers(f)) {
                wanted = f;
                break;
            }
        }
        if (wanted == 0) {
            return unsupported("'" + path + "' (" + colour_card_ + ") offers " + offered +
                               ": no colour format plumb decodes");
        }
    }
    const int raw = colour_io_->open(path, O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (raw < 0) {
        if (isGone(raw)) return unavailable("V4L2 colour node '" + path + "' is gone");
        return ioError("cannot open V4L2 colour node '" + path + "': " + errnoText(raw));
    }
    colour_fd_ = UniqueFd(colour_io_, raw);
    const auto fail = [&](Status s) {
        stopColour();
        return s;
    };
    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    fmt.fmt.pix.width =
        static_cast<uint32_t>(config_.colour_width > 0 ? config_.colour_width : config_.width);
    fmt.fmt.pix.height =
        static_cast<uint32_t>(config_.colour_height > 0 ? config_.colour_height : config_.height);
    fmt.fmt.pix.pixelformat = wanted;
    fmt.fmt.pix.field = V4L2_FIELD_NONE;
    if (int r = colour_io_->ioctl(colour_fd_.get(), VIDIOC_S_FMT, &fmt); r < 0) {
        return fail(ioError("VIDIOC_S_FMT " + fourccName(wanted) + " on '" + path +
                            "' failed: " + errnoText(r)));
    }
    const auto& pix = fmt.fmt.pix;
    if (pix.pixelformat != wanted || pix.width == 0 || pix.height == 0 || pix.width > 8192 ||
        pix.height > 8192) {
        return fail(unsupported(fmt::format("'{}' granted {} {}x{} instead of {}", path,
                                            fourccName(pix.pixelformat), pix.width, pix.height,
                                            fourccName(wanted))));
    }
    colour_fourcc_ = wanted;
    colour_width_ = static_cast<int>(pix.width);
    colour_height_ = static_cast<int>(pix.height);
    const uint32_t min_line = minBytesPerLine(wanted, colour_width_);
    colour_bytes_per_line_ = pix.bytesperline != 0 ? pix.bytesperline : min_line;
    if (colour_bytes_per_line_ < min_line) {
        return fail(
            corrupt(fmt::format("'{}' reports {} bytes per line for {} {} pixels", path,
                                colour_bytes_per_line_, colour_width_, fourccName(wanted))));
    }
    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    parm.parm.capture.timeperframe.numerator = 1;
    parm.parm.capture.timeperframe.denominator = static_cast<uint32_t>(config_.fps);
    (void)colour_io_->ioctl(colour_fd_.get(), VIDIOC_S_PARM, &parm);
    v4l2_requestbuffers req{};
    req.count = static_cast<uint32_t>(config_.num_buffers);
    req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    req.memory = V4L2_MEMORY_MMAP;
    if (int r = colour_io_->ioctl(colour_fd_.get(), VIDIOC_REQBUFS, &req); r < 0 || req.count < 2) {
        return fail(
            ioError(fmt::format("'{}' refused mmap buffers (VIDIOC_REQBUFS: {}, granted {})", path,
                                r < 0 ? errnoText(r) : "ok", req.count)));
    }
    const size_t needed = static_cast<size_t>(colour_bytes_per_line_) * colour_height_;
    for (uint32_t i = 0; i < req.count; ++i) {
        v4l2_buffer buf{};
        buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        buf.memory = V4L2_MEMORY_MMAP;
        buf.index = i;
        if (int r = colour_io_->ioctl(colour_fd_.get(), VIDIOC_QUERYBUF, &buf); r < 0) {
            return fail(ioError("VIDIOC_QUERYBUF on '" + path + "' failed: " + errnoText(r)));
        }
        void* p = colour_io_->mmap(buf.length, colour_fd_.get(), static_cast<off_t>(buf.m.offset));
        if (p == nullptr) {
            return fail(ioError(
                fmt::format("mmap of buffer {} ({} bytes) of '{}' failed", i, buf.length, path)));
        }
        colour_buffers_.emplace_back(colour_io_, p, buf.length);
        if (buf.length < needed) {
            return fail(corrupt(fmt::format("'{}' buffer {} holds {} bytes; a frame needs {}", path,
                                            i, buf.length, needed)));
        }
        if (int r = colour_io_->ioctl(colour_fd_.get(), VIDIOC_QBUF, &buf); r < 0) {
            return fail(ioError("VIDIOC_QBUF on '" + path + "' failed: " + errnoText(r)));
        }
    }
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (int r = colour_io_->ioctl(colour_fd_.get(), VIDIOC_STREAMON, &type); r < 0) {
        return fail(ioError("VIDIOC_STREAMON on '" + path + "' failed: " + errnoText(r)));
    }
    colour_streaming_ = true;
    colour_seen_ = false;
    colour_frames_.clear();
    return Status::ok();
}

void V4l2Source::stopColour() {
    if (colour_fd_.valid() && colour_streaming_) {
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        (void)colour_io_->ioctl(colour_fd_.get(), VIDIOC_STREAMOFF, &type);
    }
    colour_streaming_ = false;
    colour_buffers_.clear();
    if (colour_fd_.valid()) {
        v4l2_requestbuffers req{};
        req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        req.memory = V4L2_MEMORY_MMAP;
        (void)colour_io_->ioctl(colour_fd_.get(), VIDIOC_REQBUFS, &req);
    }
    colour_fd_.reset();
    colour_frames_.clear();
}

void V4l2Source::drainColour(int timeout_ms, uint64_t until_us) {
    const auto gone = [&](const std::string& why) {
        log::warn(
            "V4L2 colour node '{}' {}; depth goes on without colour until the camera is "
            "reopened",
            config_.colour_device, why);
        stopColour();
    };
    for (int wait = timeout_ms; colour_fd_.valid(); wait = 0) {
        const int ready = colour_io_->poll(colour_fd_.get(), wait);
        if (ready == 0) return;
        if (ready < 0) return gone("vanished (" + errnoText(ready) + ")");
        v4l2_buffer buf{};
        buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        buf.memory = V4L2_MEMORY_MMAP;
        const int r = colour_io_->ioctl(colour_fd_.get(), VIDIOC_DQBUF, &buf);
        if (r == -EAGAIN) return;
        if (r < 0) return gone("failed to dequeue (" + errnoText(r) + ")");
        if (buf.index >= colour_buffers_.size()) {
            return gone(
                fmt::format("returned buffer index {} of {}", buf.index, colour_buffers_.size()));
        }
        const uint64_t ts_us = static_cast<uint64_t>(buf.timestamp.tv_sec) * 1000000ULL +
                               static_cast<uint64_t>(buf.timestamp.tv_usec);
        const std::string what =
            fmt::format("V4L2 colour frame {} from '{}'", buf.sequence, config_.colour_device);
        last_colour_time_ = std::chrono::steady_clock::now();
        colour_seen_ = true;
        if ((buf.flags & V4L2_BUF_FLAG_ERROR) != 0) {
            log::warn("{} is flagged as damaged by the driver; skipped", what);
        } else {
            const MappedBuffer& mapped = colour_buffers_[buf.index];
            const size_t used = std::min<size_t>(buf.bytesused, mapped.length());
            auto image = decodeColourFrame(colour_fourcc_, {mapped.data(), used}, colour_width_,
                                           colour_height_, colour_bytes_per_line_, what);
            if (!image.isOk()) {
                log::warn("{}; skipped", image.status().message());
            } else {
                ColourImage sized =
                    image->width() == config_.width && image->height() == config_.height
                        ? std::move(image).value()
                        : dataset::resizeColour(*image, config_.width, config_.height);
                colour_frames_.push_back({ts_us, buf.sequence, std::move(sized)});
                while (colour_frames_.size() > 16) colour_frames_.pop_front();
            }
        }
        v4l2_buffer again{};
        again.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        again.memory = V4L2_MEMORY_MMAP;
        again.index = buf.index;
        if (int q = colour_io_->ioctl(colour_fd_.get(), VIDIOC_QBUF, &again); q < 0) {
            return gone("refused a buffer back (" + errnoText(q) + ")");
        }
        if (ts_us > until_us) return;  // caught up with the depth frame
    }
}

void V4l2Source::attachColour(uint64_t depth_us, Frame* frame) {
    const int64_t tolerance_us = config_.colour_max_difference_us > 0
                                     ? config_.colour_max_difference_us
                                     : 500000 / std::max(1, config_.fps);
    const uint64_t until_us = depth_us + static_cast<uint64_t>(tolerance_us);
    const auto closest = [&] {
        auto best = colour_frames_.end();
        int64_t best_difference = tolerance_us + 1;
        for (auto it = colour_frames_.begin(); it != colour_frames_.end(); ++it) {
            const int64_t difference =
                std::llabs(static_cast<int64_t>(it->timestamp_us) - static_cast<int64_t>(depth_us));
            if (difference < best_difference) {
                best_difference = difference;
                best = it;
            }
        }
        return best;
    };
    const auto caught_up = [&] {
        return !colour_frames_.empty() && colour_frames_.back().timestamp_us > until_us;
    };
    if (!caught_up()) drainColour(0, until_us);
    // Waiting longer than half a frame period would hold up the depth stream; a colour node that
    // never sent a frame, or went silent, is not waited for at all.
    using Clock = std::chrono::steady_clock;
    const auto deadline =
        Clock::now() + std::chrono::microseconds(500000 / std::max(1, config_.fps));
    while (colour_fd_.valid() && colour_seen_ && closest() == colour_frames_.end() &&
           !caught_up() && Clock::now() < deadline &&
           Clock::now() - last_colour_time_ < std::chrono::milliseconds(config_.colour_stall_ms)) {
        drainColour(2, until_us);
    }
    const auto best = closest();
    if (best != colour_frames_.end()) {
        frame->colour = std::move(best->image);
        colour_frames_.erase(colour_frames_.begin(), best + 1);  // older ones pair with nothing
        ++with_colour_;
    } else {
        ++without_colour_;
    }
    while (!colour_frames_.empty() &&
           static_cast<int64_t>(colour_frames_.front().timestamp_us) + tolerance_us <
               static_cast<int64_t>(depth_us)) {
        colour_frames_.pop_front();
    }
}

Status V4l2Source::start() {
    const std::string& path = config_.device;
    auto node = queryNode(path, io_);
    if (!node.isOk()) return node.status();
    card_ = node->card;
    const int raw = io_->open(path, O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (raw < 0) {
        if (isGone(raw)) return unavailable("V4L2 device '" + path + "' is gone");
        return ioError("cannot open V4L2 device '" + path + "': " + errnoText(raw));
    }
    fd_ = UniqueFd(io_, raw);
    v4l2_capability cap{};
    if (int r = io_->ioctl(fd_.get(), VIDIOC_QUERYCAP, &cap); r < 0) {
        fd_.reset();
        return unsupported("'" + path + "' is not a V4L2 device: " + errnoText(r));
    }
    const uint32_t caps =
        (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
    if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0 || (caps & V4L2_CAP_STREAMING) == 0) {
        fd_.reset();
        return unsupported("'" + path + "' (" + card_ +
                           ") is not a streaming video-capture device");
    }

    // Format: the forced one, or the first depth format in our preference order.
    std::string offered;
    for (uint32_t f : node->formats) {
        offered += fmt::format("{}{}", offered.empty() ? "" : ", ", fourccName(f));
    }
    if (offered.empty()) offered = "nothing";
    uint32_t wanted = 0;
    if (!config_.format.empty()) {
        auto f = parseFourcc(config_.format);
        if (!f.isOk()) return f.status();
        const auto& d = depthFormats();
        if (std::find(d.begin(), d.end(), *f) == d.end()) {
            fd_.reset();
            return unsupported("V4L2 format '" + config_.format +
                               "' is not a depth format we decode (Z16, INZI, Y16, Y16-BE)");
        }
        if (std::find(node->formats.begin(), node->formats.end(), *f) == node->formats.end()) {
            fd_.reset();
            return unsupported("'" + path + "' does not offer " + fourccName(*f) + " (it offers " +
                               offered + ")");
        }
        wanted = *f;
    } else {
        for (uint32_t f : depthFormats()) {
            if (std::find(node->formats.begin(), node->formats.end(), f) != node->formats.end()) {
                wanted = f;
                break;
            }
        }
        if (wanted == 0) {
            fd_.reset();
            return unsupported("'" + path + "' (" + card_ + ") offers " + offered +
                               ": no depth format (Z16, INZI, Y16, Y16-BE)");
        }
    }
    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    fmt.fmt.pix.width = static_cast<uint32_t>(config_.width);
    fmt.fmt.pix.height = static_cast<uint32_t>(config_.height);
    fmt.fmt.pix.pixelformat = wanted;
    fmt.fmt.pix.field = V4L2_FIELD_NONE;
    if (int r = io_->ioctl(fd_.get(), VIDIOC_S_FMT, &fmt); r < 0) {
        fd_.reset();
        if (isGone(r)) return unavailable("V4L2 device '" + path + "' vanished while configuring");
        return ioError("VIDIOC_S_FMT " + fourccName(wanted) + " on '" + path +
                       "' failed: " + errnoText(r));
    }
    if (fmt.fmt.pix.pixelformat != wanted ||
        fmt.fmt.pix.width != static_cast<uint32_t>(config_.width) ||
        fmt.fmt.pix.height != static_cast<uint32_t>(config_.height)) {
        fd_.reset();
        return unsupported(fmt::format("'{}' granted {} {}x{} instead of {} {}x{}", path,
                                       fourccName(fmt.fmt.pix.pixelformat), fmt.fmt.pix.width,
                                       fmt.fmt.pix.height, fourccName(wanted), config_.width,
                                       config_.height));
    }
    fourcc_ = wanted;
    bytes_per_line_ = fmt.fmt.pix.bytesperline != 0 ? fmt.fmt.pix.bytesperline
                                                    : static_cast<uint32_t>(config_.width * 2);
    if (bytes_per_line_ < static_cast<uint32_t>(config_.width * 2)) {
        fd_.reset();
        return corrupt(fmt::format("'{}' reports {} bytes per line for {} 16-bit pixels", path,
                                   bytes_per_line_, config_.width));
    }
    const size_t needed = neededBytes(fourcc_, bytes_per_line_, config_.height);
    if (fmt.fmt.pix.sizeimage != 0 && fmt.fmt.pix.sizeimage < needed) {
        fd_.reset();
        return corrupt(fmt::format("'{}' reports an image size of {} bytes; {} {}x{} needs {}",
                                   path, fmt.fmt.pix.sizeimage, fourccName(fourcc_), config_.width,
                                   config_.height, needed));
    }

    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    parm.parm.capture.timeperframe.numerator = 1;
    parm.parm.capture.timeperframe.denominator = static_cast<uint32_t>(config_.fps);
    (void)io_->ioctl(fd_.get(), VIDIOC_S_PARM, &parm);  // optional: some drivers have one rate

    v4l2_requestbuffers req{};
    req.count = static_cast<uint32_t>(config_.num_buffers);
    req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    req.memory = V4L2_MEMORY_MMAP;
    if (int r = io_->ioctl(fd_.get(), VIDIOC_REQBUFS, &req); r < 0 || req.count < 2) {
        fd_.reset();
        return ioError(fmt::format("'{}' refused mmap buffers (VIDIOC_REQBUFS: {}, granted {})",
                                   path, r < 0 ? errnoText(r) : "ok", req.count));
    }
    buffers_.clear();
    for (uint32_t i = 0; i < req.count; ++i) {
        v4l2_buffer buf{};
        buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        buf.memory = V4L2_MEMORY_MMAP;
        buf.index = i;
        if (int r = io_->ioctl(fd_.get(), VIDIOC_QUERYBUF, &buf); r < 0) {
            stop();
            return ioError("VIDIOC_QUERYBUF on '" + path + "' failed: " + errnoText(r));
        }
        void* p = io_->mmap(buf.length, fd_.get(), static_cast<off_t>(buf.m.offset));
        if (p == nullptr) {
            stop();
            return ioError(
                fmt::format("mmap of buffer {} ({} bytes) of '{}' failed", i, buf.length, path));
        }
        buffers_.emplace_back(io_, p, buf.length);
        if (buf.length < needed) {
            stop();
            return corrupt(fmt::format("'{}' buffer {} holds {} bytes; a frame needs {}", path, i,
                                       buf.length, needed));
        }
    }
    for (uint32_t i = 0; i < buffers_.size(); ++i) {
        if (Status s = queue(i); !s.isOk()) {
            stop();
            return s;
        }
    }
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (int r = io_->ioctl(fd_.get(), VIDIOC_STREAMON, &type); r < 0) {
        stop();
        return ioError("VIDIOC_STREAMON on '" + path + "' failed: " + errnoText(r));
    }
    streaming_ = true;
    lost_ = false;
    return Status::ok();
}

void V4l2Source::stop() {
    if (fd_.valid() && streaming_) {
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        (void)io_->ioctl(fd_.get(), VIDIOC_STREAMOFF, &type);
    }
    streaming_ = false;
    buffers_.clear();  // munmap before the descriptor closes
    if (fd_.valid()) {
        v4l2_requestbuffers req{};
        req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        req.memory = V4L2_MEMORY_MMAP;
        (void)io_->ioctl(fd_.get(), VIDIOC_REQBUFS, &req);  // count 0 frees the driver's buffers
    }
    fd_.reset();
}

Status V4l2Source::queue(uint32_t index) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = index;
    if (int r = io_->ioctl(fd_.get(), VIDIOC_QBUF, &buf); r < 0) {
        if (isGone(r)) return unavailable("V4L2 device '" + config_.device + "' unplugged");
        return ioError("VIDIOC_QBUF on '" + config_.device + "' failed: " + errnoText(r));
    }
    return Status::ok();
}

Result<Frame> V4l2Source::decode(const uint8_t* data, uint32_t bytesused, uint32_t sequence,
                                 uint64_t timestamp_us) {
    const int w = config_.width;
    const int h = config_.height;
    if (bytesused == 0) {
        return corrupt(
            fmt::format("V4L2 frame {} from '{}' is empty (0 bytes)", sequence, config_.device));
    }
    const size_t needed = neededBytes(fourcc_, bytes_per_line_, h);
    if (bytesused < needed) {
        return corrupt(fmt::format("V4L2 frame {} from '{}' is short: {} bytes, {} {}x{} needs {}",
                                   sequence, config_.device, bytesused, fourccName(fourcc_), w, h,
                                   needed));
    }
    Frame frame;
    frame.index = static_cast<int64_t>(returned_);
    frame.depth = DepthImage(w, h);
    const size_t plane = static_cast<size_t>(bytes_per_line_) * h;
    const uint8_t* depth = fourcc_ == V4L2_PIX_FMT_INZI ? data + plane : data;
    const bool big_endian = fourcc_ == V4L2_PIX_FMT_Y16_BE;
    const double scale = 1.0 / config_.units_per_m;
    for (int v = 0; v < h; ++v) {
        const uint8_t* row = depth + static_cast<size_t>(bytes_per_line_) * v;
        for (int u = 0; u < w; ++u) {
            const uint8_t lo = row[2 * u + (big_endian ? 1 : 0)];
            const uint8_t hi = row[2 * u + (big_endian ? 0 : 1)];
            const uint16_t raw = static_cast<uint16_t>(lo | (hi << 8));
            frame.depth(u, v) = static_cast<float>(raw * scale);
        }
    }
    if (fourcc_ == V4L2_PIX_FMT_INZI) {  // the 10-bit IR plane as 8-bit grey
        frame.gray = GrayImage(w, h);
        for (int v = 0; v < h; ++v) {
            const uint8_t* row = data + static_cast<size_t>(bytes_per_line_) * v;
            for (int u = 0; u < w; ++u) {
                const int ir = row[2 * u] | (row[2 * u + 1] << 8);
                frame.gray(u, v) = static_cast<uint8_t>(std::min(ir >> 2, 255));
            }
        }
    }
    frame.timestamp_s = clock_.toHost(timestamp_us, hostNowSeconds());
    frame.name = fmt::format("{} frame {}", config_.device, sequence);
    last_sequence_ = sequence;
    return frame;
}

void V4l2Source::cameraArrived() {
    {
        std::lock_guard lock(arrival_mutex_);
        arrived_ = true;
    }
    arrival_.notify_all();
}

Result<Frame> V4l2Source::next() {
    if (config_.max_frames > 0 && returned_ >= config_.max_frames) {
        return outOfRange(fmt::format("stopped after {} frames (max_frames)", returned_));
    }
    if (lost_) {
        {
            std::unique_lock lock(arrival_mutex_);
            arrival_.wait_for(lock, std::chrono::milliseconds(config_.reconnect_wait_ms),
                              [this] { return arrived_; });
            arrived_ = false;
        }
        Status s = start();
        if (!s.isOk()) {
            stop();
            return unavailable("V4L2 device '" + config_.device + "' " + lost_reason_ +
                               "; not back yet (" + s.message() + ")");
        }
        ++reconnects_;
        clock_.reset();
        if (!config_.colour_device.empty()) {
            stopColour();
            if (Status c = startColour(); !c.isOk()) {
                log::warn("V4L2 colour node '{}' did not come back ({}); depth without colour",
                          config_.colour_device, c.message());
            }
        }
    }
    const auto lose = [this](const std::string& why) -> Status {
        stopColour();
        stop();
        lost_ = true;
        lost_reason_ = why;
        return unavailable("V4L2 device '" + config_.device + "' " + why +
                           "; waiting for it to return");
    };
    while (true) {
        const int ready = io_->poll(fd_.get(), config_.timeout_ms);
        if (ready == 0) return lose(fmt::format("sent no frame in {} ms", config_.timeout_ms));
        if (ready < 0) return lose("unplugged (" + errnoText(ready) + ")");
        v4l2_buffer buf{};
        buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        buf.memory = V4L2_MEMORY_MMAP;
        const int r = io_->ioctl(fd_.get(), VIDIOC_DQBUF, &buf);
        if (r == -EAGAIN) continue;
        if (r < 0) {
            if (isGone(r)) return lose("unplugged (" + errnoText(r) + ")");
            return ioError("VIDIOC_DQBUF on '" + config_.device + "' failed: " + errnoText(r));
        }
        if (buf.index >= buffers_.size()) {
            return lose(fmt::format("returned buffer index {} of {}", buf.index, buffers_.size()));
        }
        Result<Frame> frame = corrupt("unset");
        if ((buf.flags & V4L2_BUF_FLAG_ERROR) != 0) {
            frame =
                corrupt(fmt::format("V4L2 frame {} from '{}' is flagged as damaged by the "
                                    "driver",
                                    buf.sequence, config_.device));
        } else {
            const uint64_t ts_us = static_cast<uint64_t>(buf.timestamp.tv_sec) * 1000000ULL +
                                   static_cast<uint64_t>(buf.timestamp.tv_usec);
            const uint32_t used = std::min<uint32_t>(
                buf.bytesused, static_cast<uint32_t>(buffers_[buf.index].length()));
            frame = decode(buffers_[buf.index].data(), used, buf.sequence, ts_us);
            if (frame.isOk() && !config_.colour_device.empty()) attachColour(ts_us, &*frame);
        }
        if (Status s = queue(buf.index); !s.isOk()) {
            // The frame is intact; the next call notices the unplug.
            if (s.code() == StatusCode::kUnavailable) {
                stopColour();
                stop();
                lost_ = true;
                lost_reason_ = "unplugged (VIDIOC_QBUF: no such device)";
            } else if (frame.isOk()) {
                return s;
            }
        }
        if (frame.isOk()) ++returned_;
        return frame;
    }
}

std::string V4l2Source::description() const {
    std::string colour;
    if (hasColour()) {
        colour = fmt::format(
            ", colour from '{}' ({} {}x{}{}, not registered to depth)", config_.colour_device,
            fourccName(colour_fourcc_), colour_width_, colour_height_,
            colour_width_ != config_.width || colour_height_ != config_.height ? " resized to depth"
                                                                               : "");
    } else if (!config_.colour_device.empty()) {
        colour = fmt::format(", colour node '{}' not streaming", config_.colour_device);
    }
    return fmt::format("V4L2 '{}' ({}, {} {}x{}@{}, {} units/m{})", config_.device, card_,
                       fourccName(fourcc_), config_.width, config_.height, config_.fps,
                       config_.units_per_m, colour);
}

}  // namespace plumb::v4l2
