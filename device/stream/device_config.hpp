// SPDX-License-Identifier: Apache-2.0
#pragma once

// The configuration of plumb-device (`--config device.toml`, `--set key=value`): capture, the
// fusion parameters a deployment tunes, and the fragment stream (chunking, retransmission,
// spool, heartbeat). The device publishes the effective configuration on PLUMB_CONFIG so LCM logs
// carry it.
//
// Thread-safety: plain configuration structs; describe() and validate() touch only their
// argument.

#include <charconv>
#include <cstdint>
#include <string>

#include "device/fusion/fragment_builder.hpp"
#include "device/fusion/live_rate.hpp"

namespace plumb::config {
class Schema;
}

namespace plumb::device {

struct CaptureConfig {
    /// Frames waiting between capture and fusion. Capture never blocks on a live sensor: a frame
    /// that finds the queue full is dropped and counted.
    int queue_frames = kDefaultCaptureQueueFrames;
    /// Pace recorded and simulated sources at their frame timestamps like a live sensor (frames
    /// fusion cannot keep up with are then dropped). false: recorded sources wait for fusion and
    /// lose nothing. Live sensors always drop.
    bool realtime = false;
    /// Intrinsics preset or file for the source (see `plumb sim --intrinsics`); empty = default.
    std::string intrinsics;
    /// Seed of sources with randomness (the simulator).
    uint64_t seed = 1;
    /// Watch the USB bus (libusb hot-plug) while reading a live camera: log depth cameras that
    /// arrive or leave, and reopen an unplugged camera as soon as one arrives instead of at the
    /// source's next periodic attempt. Without hot-plug support (containers) the source still
    /// retries on its own.
    bool usb_hotplug = true;
    /// A live camera that is not plugged in when plumb-device starts: wait this long for it,
    /// seconds (0 = fail at once, negative = until interrupted). Attempts are repeated every
    /// second, and at once when USB hot-plug reports a depth camera arriving.
    double wait_for_camera_s = 0.0;
};

namespace detail {

/// The double of `value`'s shortest decimal form: 0.04F gives 0.04, not 0.039999999105930328,
/// so an option defaulting to a float parameter reads and prints as that parameter is written.
inline double shortestDecimal(float value) {
    char text[32];
    const char* end = std::to_chars(text, text + sizeof(text), value).ptr;
    double out = 0.0;
    std::from_chars(text, end, out);
    return out;
}

}  // namespace detail

/// The fusion parameters exposed to users (the rest keep FusionConfig's defaults). FusionConfig
/// holds the defaults: toFusionConfig(FusionOptions{}) has FusionConfig{}'s values.
struct FusionOptions {
    /// Frames per fragment (FusionConfig::frames_per_fragment).
    int frames_per_fragment = FusionConfig{}.frames_per_fragment;
    /// TSDF voxel edge length, metres.
    double voxel_size_m = detail::shortestDecimal(FusionConfig{}.tsdf.voxel_size_m);
    /// TSDF truncation distance, metres.
    double truncation_m = detail::shortestDecimal(FusionConfig{}.tsdf.truncation_m);
    /// Depth beyond this is ignored (by preprocessing and integration), metres.
    double max_depth_m = detail::shortestDecimal(FusionConfig{}.tsdf.max_depth_m);
};

struct StreamConfig {
    /// Payload bytes per chunk (every LCM message stays below 64 KiB).
    int chunk_payload_bytes = 60000;
    /// First re-announcement of an unacknowledged fragment, seconds.
    double retransmit_timeout_s = 0.5;
    /// Longest interval between re-announcements (exponential back-off), seconds.
    double max_retransmit_timeout_s = 4.0;
    /// Fragments on the wire at once; the rest wait in the spool.
    int max_in_flight = 8;
    /// Encoded fragments kept in memory until acknowledged, bytes: without --spool-dir the
    /// spool's capacity; with it a cache (every fragment is written to the directory first).
    int64_t spool_memory_bytes = int64_t{64} << 20;
    /// Bytes allowed in the disk spool; when full, fusion waits (and capture drops frames).
    int64_t spool_disk_bytes = int64_t{4} << 30;
    /// Interval of the device_status_t heartbeat, seconds.
    double status_period_s = 1.0;
    /// Interval at which camera info and the configuration snapshot are repeated, seconds.
    double config_period_s = 5.0;
    /// At the end of a finite source, how long to wait for the last acknowledgements, seconds.
    double ack_wait_s = 30.0;
    /// Keep per-point colours in encoded fragments when the cloud has them.
    bool include_colors = true;
    /// Publish every this many captured frames raw on PLUMB_RGBD3 (depth_frame3_t: depth in
    /// millimetres, delta-varint), for logs, monitoring and plumb-backend, which keeps them for
    /// its final model and for `plumb reconstruct store:DIR` (1 = every frame); 0 = no raw
    /// frames. Recorded sources wait for the network thread; live sensors drop raw frames it
    /// cannot keep up with.
    int raw_frame_every = 0;
    /// Send the frame's colour in raw frames when it has one (lossless DELTA_RICE, about half
    /// of 3 bytes a pixel, and CPU the tracking competes for); false = depth only, and the
    /// backend's mesh takes the colour of the fragments' points instead.
    bool raw_frame_colour = true;
    /// The LCM type raw frames are published as: 3 = depth_frame3_t on PLUMB_RGBD3, naming the
    /// device session; 2 = depth_frame2_t on PLUMB_RGBD, without it, for a plumb-backend of a
    /// release before depth_frame3_t, which does not hear PLUMB_RGBD3 (it then fuses the fragment
    /// surfaces). A backend of this release reads both.
    int raw_frame_type = 3;
};

struct DeviceConfig {
    CaptureConfig capture;
    FusionOptions fusion;
    StreamConfig stream;
};

void describe(config::Schema& s, CaptureConfig& c);
void describe(config::Schema& s, FusionOptions& c);
void describe(config::Schema& s, StreamConfig& c);
void describe(config::Schema& s, DeviceConfig& c);

/// FusionConfig defaults with the user-facing options applied.
FusionConfig toFusionConfig(const FusionOptions& options);

}  // namespace plumb::device
