// SPDX-License-Identifier: Apache-2.0
#pragma once

// LCM channel names and the default URL. Channel names are plain words: LCM treats a subscription
// channel as a regular expression, so they must not contain regex metacharacters.
//
// Thread-safety: constants only.

namespace plumb::messages {

/// Multicast on the loopback host only: ttl=0 keeps every packet on this machine.
inline constexpr const char* kDefaultLcmUrl = "udpm://239.255.76.67:7667?ttl=0";

inline constexpr const char* kChannelStatus = "PLUMB_STATUS";  ///< device_status_t
inline constexpr const char* kChannelFragmentHeader =
    "PLUMB_FRAGMENT_HEADER";                                                  ///< fragment_header_t
inline constexpr const char* kChannelFragmentChunk = "PLUMB_FRAGMENT_CHUNK";  ///< fragment_chunk_t
inline constexpr const char* kChannelFragmentAck = "PLUMB_FRAGMENT_ACK";      ///< fragment_ack_t
inline constexpr const char* kChannelRetransmit = "PLUMB_RETRANSMIT";  ///< retransmit_request_t
inline constexpr const char* kChannelFragmentBackoff =
    "PLUMB_FRAGMENT_BACKOFF";                                           ///< fragment_backoff_t
inline constexpr const char* kChannelCameraInfo = "PLUMB_CAMERA_INFO";  ///< camera_info_t
inline constexpr const char* kChannelDepth = "PLUMB_DEPTH";             ///< depth_frame_t
inline constexpr const char* kChannelRgbd = "PLUMB_RGBD";               ///< depth_frame2_t
inline constexpr const char* kChannelRgbdSession = "PLUMB_RGBD3";       ///< depth_frame3_t
inline constexpr const char* kChannelConfig = "PLUMB_CONFIG";           ///< config_snapshot_t

}  // namespace plumb::messages
