// SPDX-License-Identifier: Apache-2.0
#include "messages/conversions.hpp"

#include <fmt/format.h>

#include <cmath>

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

Result<plumb::depth_frame_t> toMessage(const RawDepthFrame& frame, DepthEncoding encoding,
                                       int64_t seq) {
    const Depth16Image& d = frame.depth;
    if (d.empty() || d.width() > kMaxDepthSide || d.height() > kMaxDepthSide) {
        return invalidArgument(
            fmt::format("depth frame {}: size {}x{}", frame.frame_index, d.width(), d.height()));
    }
    if (!std::isfinite(frame.depth_scale) || frame.depth_scale <= 0.0) {
        return invalidArgument(
            fmt::format("depth frame {}: depth scale {}", frame.frame_index, frame.depth_scale));
    }
    plumb::depth_frame_t m{};
    m.utime = frame.utime;
    m.seq = seq;
    m.frame_index = frame.frame_index;
    m.width = d.width();
    m.height = d.height();
    m.depth_scale = frame.depth_scale;
    m.encoding = static_cast<int8_t>(encoding);
    if (encoding == DepthEncoding::kRaw16) {
        m.data.reserve(d.size() * 2);
        for (const uint16_t v : d.pixels()) {
            m.data.push_back(static_cast<uint8_t>(v & 0xFF));
            m.data.push_back(static_cast<uint8_t>(v >> 8));
        }
    } else {
        m.data.reserve(d.size() + d.size() / 4);
        for (int v = 0; v < d.height(); ++v) {
            int32_t prev = 0;
            for (int u = 0; u < d.width(); ++u) {
                const int32_t delta = static_cast<int32_t>(d(u, v)) - prev;
                prev = d(u, v);
                // Zig-zag: 0, -1, 1, -2, ... -> 0, 1, 2, 3, ...
                uint32_t z =
                    (static_cast<uint32_t>(delta) << 1) ^ static_cast<uint32_t>(delta >> 31);
                while (z >= 0x80) {
                    m.data.push_back(static_cast<uint8_t>(z | 0x80));
                    z >>= 7;
                }
                m.data.push_back(static_cast<uint8_t>(z));
            }
        }
    }
    m.size = static_cast<int32_t>(m.data.size());
    return m;
}

Result<RawDepthFrame> fromMessage(const plumb::depth_frame_t& m) {
    if (m.width <= 0 || m.height <= 0 || m.width > kMaxDepthSide || m.height > kMaxDepthSide) {
        return corrupt(
            fmt::format("depth_frame_t {}: size {}x{}", m.frame_index, m.width, m.height));
    }
    if (!std::isfinite(m.depth_scale) || m.depth_scale <= 0.0) {
        return corrupt(
            fmt::format("depth_frame_t {}: depth scale {}", m.frame_index, m.depth_scale));
    }
    if (m.size != static_cast<int32_t>(m.data.size())) {
        return corrupt(fmt::format("depth_frame_t {}: size field {} but {} bytes", m.frame_index,
                                   m.size, m.data.size()));
    }
    RawDepthFrame f;
    f.utime = m.utime;
    f.frame_index = m.frame_index;
    f.depth_scale = m.depth_scale;
    f.depth = Depth16Image(m.width, m.height);
    const size_t pixels = f.depth.size();
    if (m.encoding == plumb::depth_frame_t::ENCODING_RAW16_LE) {
        if (m.data.size() != pixels * 2) {
            return corrupt(fmt::format("depth_frame_t {}: {} bytes for {} raw pixels",
                                       m.frame_index, m.data.size(), pixels));
        }
        for (size_t i = 0; i < pixels; ++i) {
            f.depth.pixels()[i] = static_cast<uint16_t>(m.data[2 * i] | (m.data[2 * i + 1] << 8));
        }
        return f;
    }
    if (m.encoding != plumb::depth_frame_t::ENCODING_DELTA_VARINT) {
        return corrupt(
            fmt::format("depth_frame_t {}: unknown encoding {}", m.frame_index, m.encoding));
    }
    size_t pos = 0;
    for (int v = 0; v < m.height; ++v) {
        int32_t prev = 0;
        for (int u = 0; u < m.width; ++u) {
            uint32_t z = 0;
            int shift = 0;
            while (true) {
                if (pos >= m.data.size() || shift > 14) {
                    return corrupt(
                        fmt::format("depth_frame_t {}: truncated or overlong varint at "
                                    "pixel ({}, {})",
                                    m.frame_index, u, v));
                }
                const uint8_t b = m.data[pos++];
                z |= static_cast<uint32_t>(b & 0x7F) << shift;
                if (!(b & 0x80)) break;
                shift += 7;
            }
            const int32_t delta = static_cast<int32_t>(z >> 1) ^ -static_cast<int32_t>(z & 1);
            const int32_t value = prev + delta;
            if (value < 0 || value > 65535) {
                return corrupt(fmt::format("depth_frame_t {}: pixel ({}, {}) decodes to {}",
                                           m.frame_index, u, v, value));
            }
            f.depth(u, v) = static_cast<uint16_t>(value);
            prev = value;
        }
    }
    if (pos != m.data.size()) {
        return corrupt(
            fmt::format("depth_frame_t {}: {} trailing bytes", m.frame_index, m.data.size() - pos));
    }
    return f;
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
