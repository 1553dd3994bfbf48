// SPDX-License-Identifier: Apache-2.0
#include "messages/conversions.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstring>

#include "messages/colour_codec.hpp"

namespace plumb::messages {

plumb::device_status_t toMessage(const DeviceStatus& status, int64_t utime, int64_t seq) {
    plumb::device_status_t m{};
    m.utime = utime;
    m.seq = seq;
    m.session_id = status.session_id;
    m.fps = status.fps;
    m.tracking_state = static_cast<int8_t>(status.tracking);
    m.frames_processed = status.frames_processed;
    m.frames_dropped = status.frames_dropped;
    m.fragments_cut = status.fragments_cut;
    m.fragments_acked = status.fragments_acked;
    m.spool_fragments = status.spool_fragments;
    m.spool_bytes = status.spool_bytes;
    m.memory_bytes = status.memory_bytes;
    return m;
}

Result<DeviceStatus> fromMessage(const plumb::device_status_t& m) {
    if (!std::isfinite(m.fps) || m.fps < 0.0) {
        return corrupt(fmt::format("device_status_t: fps {}", m.fps));
    }
    if (m.tracking_state < plumb::device_status_t::TRACKING_INITIALIZING ||
        m.tracking_state > plumb::device_status_t::TRACKING_NO_CAMERA) {
        return corrupt(fmt::format("device_status_t: unknown tracking state {}", m.tracking_state));
    }
    if (m.frames_processed < 0 || m.frames_dropped < 0 || m.fragments_cut < 0 ||
        m.fragments_acked < 0 || m.spool_fragments < 0 || m.spool_bytes < 0 || m.memory_bytes < 0) {
        return corrupt("device_status_t: negative counter");
    }
    DeviceStatus s;
    s.session_id = m.session_id;
    s.fps = m.fps;
    s.tracking = static_cast<TrackingState>(m.tracking_state);
    s.frames_processed = m.frames_processed;
    s.frames_dropped = m.frames_dropped;
    s.fragments_cut = m.fragments_cut;
    s.fragments_acked = m.fragments_acked;
    s.spool_fragments = m.spool_fragments;
    s.spool_bytes = m.spool_bytes;
    s.memory_bytes = m.memory_bytes;
    return s;
}

plumb::camera_info_t toMessage(const CameraInfo& info, int64_t utime, int64_t seq) {
    plumb::camera_info_t m{};
    m.utime = utime;
    m.seq = seq;
    m.width = info.camera.width;
    m.height = info.camera.height;
    m.fx = info.camera.fx;
    m.fy = info.camera.fy;
    m.cx = info.camera.cx;
    m.cy = info.camera.cy;
    m.depth_scale = info.depth_scale;
    m.source = info.source;
    return m;
}

Result<CameraInfo> fromMessage(const plumb::camera_info_t& m) {
    CameraInfo info;
    info.camera = PinholeCamera{m.width, m.height, m.fx, m.fy, m.cx, m.cy};
    if (Status s = info.camera.validate(); !s.isOk()) {
        return corrupt("camera_info_t: " + s.message());
    }
    if (m.width > kMaxDepthSide || m.height > kMaxDepthSide || !std::isfinite(m.cx) ||
        !std::isfinite(m.cy)) {
        return corrupt(fmt::format("camera_info_t: absurd camera {}", info.camera.toString()));
    }
    if (!std::isfinite(m.depth_scale) || m.depth_scale <= 0.0) {
        return corrupt(fmt::format("camera_info_t: depth scale {}", m.depth_scale));
    }
    info.depth_scale = m.depth_scale;
    info.source = m.source;
    return info;
}

namespace {

/// Checks what every raw frame needs before encoding: a depth image of a sane size, a positive
/// depth scale, colour (when present) of the depth's size.
Status checkRawFrame(int64_t frame_index, const Depth16Image& d, double depth_scale,
                     const ColourImage* colour) {
    if (d.empty() || d.width() > kMaxDepthSide || d.height() > kMaxDepthSide) {
        return invalidArgument(
            fmt::format("depth frame {}: size {}x{}", frame_index, d.width(), d.height()));
    }
    if (!std::isfinite(depth_scale) || depth_scale <= 0.0) {
        return invalidArgument(
            fmt::format("depth frame {}: depth scale {}", frame_index, depth_scale));
    }
    if (colour != nullptr && !colour->empty() &&
        (colour->width() != d.width() || colour->height() != d.height())) {
        return invalidArgument(fmt::format("depth frame {}: {}x{} colour for {}x{} depth",
                                           frame_index, colour->width(), colour->height(),
                                           d.width(), d.height()));
    }
    return Status::ok();
}

/// Depth as the wire carries it (see depth_frame_t.lcm for the encodings).
std::vector<uint8_t> encodeDepth(const Depth16Image& d, DepthEncoding encoding) {
    std::vector<uint8_t> data;
    if (encoding == DepthEncoding::kRaw16) {
        data.reserve(d.size() * 2);
        for (const uint16_t v : d.pixels()) {
            data.push_back(static_cast<uint8_t>(v & 0xFF));
            data.push_back(static_cast<uint8_t>(v >> 8));
        }
        return data;
    }
    data.reserve(d.size() + d.size() / 4);
    for (int v = 0; v < d.height(); ++v) {
        int32_t prev = 0;
        for (int u = 0; u < d.width(); ++u) {
            const int32_t delta = static_cast<int32_t>(d(u, v)) - prev;
            prev = d(u, v);
            // Zig-zag: 0, -1, 1, -2, ... -> 0, 1, 2, 3, ...
            uint32_t z = (static_cast<uint32_t>(delta) << 1) ^ static_cast<uint32_t>(delta >> 31);
            while (z >= 0x80) {
                data.push_back(static_cast<uint8_t>(z | 0x80));
                z >>= 7;
            }
            data.push_back(static_cast<uint8_t>(z));
        }
    }
    return data;
}

/// The header fields both raw frame types share, as they came off the wire.
struct WireDepth {
    const char* type;  ///< "depth_frame_t", for errors
    int64_t frame_index;
    int32_t width;
    int32_t height;
    double depth_scale;
    int8_t encoding;
    int32_t size;
    const std::vector<uint8_t>* data;
};

/// Validates and decodes the depth part of a raw frame message.
Result<Depth16Image> decodeDepth(const WireDepth& m) {
    if (m.width <= 0 || m.height <= 0 || m.width > kMaxDepthSide || m.height > kMaxDepthSide) {
        return corrupt(fmt::format("{} {}: size {}x{}", m.type, m.frame_index, m.width, m.height));
    }
    if (!std::isfinite(m.depth_scale) || m.depth_scale <= 0.0) {
        return corrupt(fmt::format("{} {}: depth scale {}", m.type, m.frame_index, m.depth_scale));
    }
    const std::vector<uint8_t>& data = *m.data;
    if (m.size != static_cast<int32_t>(data.size())) {
        return corrupt(fmt::format("{} {}: size field {} but {} bytes", m.type, m.frame_index,
                                   m.size, data.size()));
    }
    Depth16Image depth(m.width, m.height);
    const size_t pixels = depth.size();
    if (m.encoding == plumb::depth_frame_t::ENCODING_RAW16_LE) {
        if (data.size() != pixels * 2) {
            return corrupt(fmt::format("{} {}: {} bytes for {} raw pixels", m.type, m.frame_index,
                                       data.size(), pixels));
        }
        for (size_t i = 0; i < pixels; ++i) {
            depth.pixels()[i] = static_cast<uint16_t>(data[2 * i] | (data[2 * i + 1] << 8));
        }
        return depth;
    }
    if (m.encoding != plumb::depth_frame_t::ENCODING_DELTA_VARINT) {
        return corrupt(
            fmt::format("{} {}: unknown encoding {}", m.type, m.frame_index, m.encoding));
    }
    size_t pos = 0;
    for (int v = 0; v < m.height; ++v) {
        int32_t prev = 0;
        for (int u = 0; u < m.width; ++u) {
            uint32_t z = 0;
            int shift = 0;
            while (true) {
                if (pos >= data.size() || shift > 14) {
                    return corrupt(
                        fmt::format("{} {}: truncated or overlong varint at pixel ({}, {})", m.type,
                                    m.frame_index, u, v));
                }
                const uint8_t b = data[pos++];
                z |= static_cast<uint32_t>(b & 0x7F) << shift;
                if (!(b & 0x80)) break;
                shift += 7;
            }
            const int32_t delta = static_cast<int32_t>(z >> 1) ^ -static_cast<int32_t>(z & 1);
            const int32_t value = prev + delta;
            if (value < 0 || value > 65535) {
                return corrupt(fmt::format("{} {}: pixel ({}, {}) decodes to {}", m.type,
                                           m.frame_index, u, v, value));
            }
            depth(u, v) = static_cast<uint16_t>(value);
            prev = value;
        }
    }
    if (pos != data.size()) {
        return corrupt(
            fmt::format("{} {}: {} trailing bytes", m.type, m.frame_index, data.size() - pos));
    }
    return depth;
}

/// Validates and decodes the colour part of a depth_frame2_t (empty image for COLOUR_NONE).
Result<ColourImage> decodeColour(const plumb::depth_frame2_t& m) {
    if (m.colour_size != static_cast<int32_t>(m.colour_data.size())) {
        return corrupt(fmt::format("depth_frame2_t {}: colour size field {} but {} bytes",
                                   m.frame_index, m.colour_size, m.colour_data.size()));
    }
    const size_t pixels = static_cast<size_t>(m.width) * static_cast<size_t>(m.height);
    switch (m.colour_encoding) {
        case plumb::depth_frame2_t::COLOUR_NONE:
            if (!m.colour_data.empty()) {
                return corrupt(fmt::format("depth_frame2_t {}: {} colour bytes without colour",
                                           m.frame_index, m.colour_data.size()));
            }
            return ColourImage();
        case plumb::depth_frame2_t::COLOUR_RGB8: {
            if (m.colour_data.size() != pixels * 3) {
                return corrupt(fmt::format("depth_frame2_t {}: {} colour bytes for {} RGB pixels",
                                           m.frame_index, m.colour_data.size(), pixels));
            }
            ColourImage colour(m.width, m.height);
            std::memcpy(colour.data(), m.colour_data.data(), pixels * 3);
            return colour;
        }
        case plumb::depth_frame2_t::COLOUR_DELTA_RICE: {
            auto colour = decodeColourRice(m.colour_data, m.width, m.height);
            if (!colour.isOk()) {
                return corrupt(
                    fmt::format("depth_frame2_t {}: {}", m.frame_index, colour.status().message()));
            }
            return colour;
        }
        default:
            return corrupt(fmt::format("depth_frame2_t {}: unknown colour encoding {}",
                                       m.frame_index, m.colour_encoding));
    }
}

}  // namespace

Result<plumb::depth_frame_t> toMessage(const RawDepthFrame& frame, DepthEncoding encoding,
                                       int64_t seq) {
    PLUMB_RETURN_IF_ERROR(
        checkRawFrame(frame.frame_index, frame.depth, frame.depth_scale, nullptr));
    plumb::depth_frame_t m{};
    m.utime = frame.utime;
    m.seq = seq;
    m.frame_index = frame.frame_index;
    m.width = frame.depth.width();
    m.height = frame.depth.height();
    m.depth_scale = frame.depth_scale;
    m.encoding = static_cast<int8_t>(encoding);
    m.data = encodeDepth(frame.depth, encoding);
    m.size = static_cast<int32_t>(m.data.size());
    return m;
}

Result<RawDepthFrame> fromMessage(const plumb::depth_frame_t& m) {
    auto depth = decodeDepth({"depth_frame_t", m.frame_index, m.width, m.height, m.depth_scale,
                              m.encoding, m.size, &m.data});
    if (!depth.isOk()) return depth.status();
    RawDepthFrame f;
    f.utime = m.utime;
    f.frame_index = m.frame_index;
    f.depth_scale = m.depth_scale;
    f.depth = std::move(depth).value();
    return f;
}

Result<plumb::depth_frame2_t> toMessage(const RawRgbdFrame& frame, DepthEncoding encoding,
                                        ColourEncoding colour_encoding, int64_t seq) {
    PLUMB_RETURN_IF_ERROR(
        checkRawFrame(frame.frame_index, frame.depth, frame.depth_scale, &frame.colour));
    plumb::depth_frame2_t m{};
    m.utime = frame.utime;
    m.seq = seq;
    m.frame_index = frame.frame_index;
    m.width = frame.depth.width();
    m.height = frame.depth.height();
    m.depth_scale = frame.depth_scale;
    m.encoding = static_cast<int8_t>(encoding);
    m.data = encodeDepth(frame.depth, encoding);
    m.size = static_cast<int32_t>(m.data.size());
    const ColourEncoding used = frame.colour.empty() ? ColourEncoding::kNone : colour_encoding;
    m.colour_encoding = static_cast<int8_t>(used);
    if (used == ColourEncoding::kRgb8) {
        const auto* bytes = reinterpret_cast<const uint8_t*>(frame.colour.data());
        m.colour_data.assign(bytes, bytes + frame.colour.size() * 3);
    } else if (used == ColourEncoding::kDeltaRice) {
        m.colour_data = encodeColourRice(frame.colour);
    }
    m.colour_size = static_cast<int32_t>(m.colour_data.size());
    return m;
}

Result<RawRgbdFrame> fromMessage(const plumb::depth_frame2_t& m) {
    auto depth = decodeDepth({"depth_frame2_t", m.frame_index, m.width, m.height, m.depth_scale,
                              m.encoding, m.size, &m.data});
    if (!depth.isOk()) return depth.status();
    auto colour = decodeColour(m);
    if (!colour.isOk()) return colour.status();
    RawRgbdFrame f;
    f.utime = m.utime;
    f.frame_index = m.frame_index;
    f.depth_scale = m.depth_scale;
    f.depth = std::move(depth).value();
    f.colour = std::move(colour).value();
    return f;
}

Result<plumb::depth_frame3_t> toSessionMessage(const RawRgbdFrame& frame, int64_t session_id,
                                               DepthEncoding encoding,
                                               ColourEncoding colour_encoding, int64_t seq) {
    auto inner = toMessage(frame, encoding, colour_encoding, seq);
    if (!inner.isOk()) return inner.status();
    plumb::depth_frame3_t m{};
    m.session_id = session_id;
    m.frame = std::move(inner).value();
    return m;
}

Result<RawRgbdFrame> fromMessage(const plumb::depth_frame3_t& m) {
    auto frame = fromMessage(m.frame);
    if (!frame.isOk()) return frame.status();
    frame->session_id = m.session_id;
    return frame;
}

Result<RawRgbdFrame> decodeRawFrame(std::span<const uint8_t> bytes) {
    if (hasFingerprint<plumb::depth_frame3_t>(bytes)) {
        auto msg = decodeMessage<plumb::depth_frame3_t>(bytes);
        if (!msg.isOk()) return msg.status();
        return fromMessage(*msg);
    }
    if (hasFingerprint<plumb::depth_frame_t>(bytes)) {
        auto msg = decodeMessage<plumb::depth_frame_t>(bytes);
        if (!msg.isOk()) return msg.status();
        auto frame = fromMessage(*msg);
        if (!frame.isOk()) return frame.status();
        RawRgbdFrame f;
        f.utime = frame->utime;
        f.frame_index = frame->frame_index;
        f.depth_scale = frame->depth_scale;
        f.depth = std::move(frame->depth);
        return f;
    }
    auto msg = decodeMessage<plumb::depth_frame2_t>(bytes);
    if (!msg.isOk()) return msg.status();
    return fromMessage(*msg);
}

plumb::config_snapshot_t toMessage(const std::string& program, const std::string& version,
                                   const std::string& toml, int64_t utime, int64_t seq) {
    plumb::config_snapshot_t m{};
    m.utime = utime;
    m.seq = seq;
    m.program = program;
    m.version = version;
    m.toml = toml;
    return m;
}

}  // namespace plumb::messages
