// SPDX-License-Identifier: Apache-2.0
#pragma once

// Conversions between the LCM types (package plumb) and plumb's own types. Every fromMessage()
// validates what came off the wire and returns a Status naming the bad field.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include "common/camera/pinhole.hpp"
#include "common/core/status.hpp"
#include "common/image/image.hpp"
#include "messages/wire.hpp"

namespace plumb::messages {

enum class TrackingState : int8_t {
    kInitializing = plumb::device_status_t::TRACKING_INITIALIZING,
    kOk = plumb::device_status_t::TRACKING_OK,
    kLost = plumb::device_status_t::TRACKING_LOST,
    kStopped = plumb::device_status_t::TRACKING_STOPPED,
    kNoCamera = plumb::device_status_t::TRACKING_NO_CAMERA,
};

/// The device's heartbeat in plumb terms (see device_status_t.lcm for the field meanings).
struct DeviceStatus {
    int64_t session_id = 0;
    double fps = 0.0;  ///< frames per second over the last interval
    TrackingState tracking = TrackingState::kInitializing;
    int64_t frames_processed = 0;
    int64_t frames_dropped = 0;
    int32_t fragments_cut = 0;
    int32_t fragments_acked = 0;
    int32_t spool_fragments = 0;
    int64_t spool_bytes = 0;
    int64_t memory_bytes = 0;
};

/// Share of the frames offered to the device's pipeline that it processed, processed /
/// (processed + dropped); 1 while none was offered.
inline double processedFraction(int64_t processed, int64_t dropped) {
    const int64_t offered = processed + dropped;
    return offered > 0 ? static_cast<double>(processed) / static_cast<double>(offered) : 1.0;
}

plumb::device_status_t toMessage(const DeviceStatus& status, int64_t utime, int64_t seq);
/// Corrupt for negative counters, non-finite or negative fps, unknown tracking state.
Result<DeviceStatus> fromMessage(const plumb::device_status_t& msg);

struct CameraInfo {
    PinholeCamera camera;
    double depth_scale = 1000.0;  ///< raw depth units per metre
    std::string source;           ///< description of the frame source
};

plumb::camera_info_t toMessage(const CameraInfo& info, int64_t utime, int64_t seq);
/// Corrupt when the intrinsics do not validate or the depth scale is not positive and finite.
Result<CameraInfo> fromMessage(const plumb::camera_info_t& msg);

enum class DepthEncoding : int8_t {
    kRaw16 = plumb::depth_frame_t::ENCODING_RAW16_LE,  ///< 2 bytes per pixel
    /// Row-wise differences, zig-zag mapped, LEB128 varints: 1 byte per pixel on smooth surfaces
    /// and on runs of invalid (0) pixels, lossless.
    kDeltaVarint = plumb::depth_frame_t::ENCODING_DELTA_VARINT,
};

struct RawDepthFrame {
    int64_t utime = 0;        ///< capture time, microseconds
    int64_t frame_index = 0;  ///< index in the capture stream
    double depth_scale = 1000.0;
    Depth16Image depth;
};

/// Largest depth image accepted from the wire, pixels per side.
inline constexpr int kMaxDepthSide = 8192;

/// InvalidArgument for an empty or oversized image or a bad depth scale.
Result<plumb::depth_frame_t> toMessage(const RawDepthFrame& frame, DepthEncoding encoding,
                                       int64_t seq);
/// Corrupt for bad sizes, unknown encodings, truncated or overlong data, out-of-range values.
Result<RawDepthFrame> fromMessage(const plumb::depth_frame_t& msg);

/// How depth_frame2_t carries the colour (see depth_frame2_t.lcm).
enum class ColourEncoding : int8_t {
    kNone = plumb::depth_frame2_t::COLOUR_NONE,  ///< leave the colour out
    kRgb8 = plumb::depth_frame2_t::COLOUR_RGB8,  ///< 3 bytes per pixel
    /// Lossless, about half the raw size on indoor images (messages/colour_codec.hpp); the
    /// companion of kDeltaVarint depth.
    kDeltaRice = plumb::depth_frame2_t::COLOUR_DELTA_RICE,
};

/// A raw frame with its colour (depth_frame2_t), and its session (depth_frame3_t).
struct RawRgbdFrame {
    int64_t utime = 0;        ///< capture time, microseconds
    int64_t frame_index = 0;  ///< index in the capture stream
    /// The device session, when the message names it (depth_frame3_t; older messages do not).
    std::optional<int64_t> session_id;
    double depth_scale = 1000.0;
    Depth16Image depth;
    ColourImage colour;  ///< 8-bit RGB registered to `depth` (same size), or empty
};

/// InvalidArgument for an empty or oversized depth image, a bad depth scale, or colour of
/// another size than the depth. A frame without colour is sent with COLOUR_NONE whatever
/// `colour_encoding` says.
Result<plumb::depth_frame2_t> toMessage(const RawRgbdFrame& frame, DepthEncoding encoding,
                                        ColourEncoding colour_encoding, int64_t seq);
/// Corrupt as for depth_frame_t, and for a colour size field that disagrees with the bytes, an
/// unknown colour encoding, RGB8 data of the wrong length, or a damaged DELTA_RICE stream.
Result<RawRgbdFrame> fromMessage(const plumb::depth_frame2_t& msg);

/// The frame as toMessage encodes it, inside a depth_frame3_t naming `session_id` (the
/// frame's own session_id is not used).
Result<plumb::depth_frame3_t> toSessionMessage(const RawRgbdFrame& frame, int64_t session_id,
                                               DepthEncoding encoding,
                                               ColourEncoding colour_encoding, int64_t seq);
/// As fromMessage(depth_frame2_t), with session_id set. Corrupt as it is.
Result<RawRgbdFrame> fromMessage(const plumb::depth_frame3_t& msg);

/// A raw frame off the wire: a depth_frame3_t, a depth_frame2_t (without a session), or a
/// depth_frame_t (logs from before colour; the colour stays empty), told apart by the type
/// fingerprint. Corrupt (naming the type) for anything that does not check and decode as one of
/// them.
Result<RawRgbdFrame> decodeRawFrame(std::span<const uint8_t> bytes);

plumb::config_snapshot_t toMessage(const std::string& program, const std::string& version,
                                   const std::string& toml, int64_t utime, int64_t seq);

}  // namespace plumb::messages
