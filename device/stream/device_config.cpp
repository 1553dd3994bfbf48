// SPDX-License-Identifier: Apache-2.0
#include "device/stream/device_config.hpp"

#include "common/config/schema.hpp"

namespace plumb::device {

void describe(config::Schema& s, CaptureConfig& c) {
    s.field("queue_frames", c.queue_frames,
            "frames waiting between capture and fusion (a full queue drops frames on live "
            "sensors)",
            "frames")
        .range(1, 1024);
    s.field("realtime", c.realtime,
            "pace recorded/simulated sources at their timestamps and drop frames fusion cannot "
            "keep up with");
    s.field("intrinsics", c.intrinsics,
            "intrinsics preset or file for the source (empty: default)");
    s.field("seed", c.seed, "seed of sources with randomness (simulator)");
    s.field("usb_hotplug", c.usb_hotplug,
            "live cameras: watch USB hot-plug, log cameras arriving and leaving, reopen an "
            "unplugged camera as soon as it returns");
    s.field("wait_for_camera_s", c.wait_for_camera_s,
            "live cameras absent at start: wait this long for one to be plugged in (0: fail at "
            "once; negative: until interrupted)",
            "s");
}

void describe(config::Schema& s, FusionOptions& c) {
    s.field("frames_per_fragment", c.frames_per_fragment, "frames fused into one fragment",
            "frames")
        .min(1);
    s.field("voxel_size_m", c.voxel_size_m, "TSDF voxel edge length", "m").positive().max(1.0);
    s.field("truncation_m", c.truncation_m, "TSDF truncation distance", "m").positive().max(1.0);
    s.field("max_depth_m", c.max_depth_m, "depth beyond this is ignored", "m").positive();
}

void describe(config::Schema& s, StreamConfig& c) {
    s.field("chunk_payload_bytes", c.chunk_payload_bytes, "payload bytes per fragment chunk",
            "bytes")
        .range(256, 65000);
    s.field("retransmit_timeout_s", c.retransmit_timeout_s,
            "first re-announcement of an unacknowledged fragment", "s")
        .positive();
    s.field("max_retransmit_timeout_s", c.max_retransmit_timeout_s,
            "longest interval between re-announcements (back-off)", "s")
        .positive();
    s.field("max_in_flight", c.max_in_flight, "fragments on the wire at once", "fragments")
        .range(1, 1024);
    s.field("spool_memory_bytes", c.spool_memory_bytes,
            "unacknowledged fragments kept in memory (without --spool-dir: the spool's "
            "capacity; with it: a cache, every fragment is on disk first)",
            "bytes")
        .min(0);
    s.field("spool_disk_bytes", c.spool_disk_bytes, "bytes allowed in the disk spool", "bytes")
        .min(0);
    s.field("status_period_s", c.status_period_s, "interval of the status heartbeat", "s")
        .positive();
    s.field("config_period_s", c.config_period_s,
            "interval at which camera info and the configuration are repeated", "s")
        .positive();
    s.field("ack_wait_s", c.ack_wait_s,
            "at the end of a finite source, wait this long for the last acknowledgements", "s")
        .min(0);
    s.field("include_colors", c.include_colors, "keep per-point colours in encoded fragments");
    s.field("raw_frame_every", c.raw_frame_every,
            "publish every N-th captured frame raw (as stream.raw_frame_type says); 0: none. "
            "plumb-backend keeps them: its final model re-integrates them, and `plumb "
            "reconstruct store:DIR` tracks them again (1: every frame)",
            "frames")
        .min(0);
    s.field("raw_frame_colour", c.raw_frame_colour,
            "send the frame's colour in raw frames when it has one (lossless, about 12 ms of "
            "device CPU a VGA frame; false: depth only, about 0.3 MB a frame, and the "
            "backend's mesh takes the colour of the fragments)");
    s.field("raw_frame_type", c.raw_frame_type,
            "LCM type of the raw frames: 3 = depth_frame3_t on PLUMB_RGBD3, naming the session; "
            "2 = depth_frame2_t on PLUMB_RGBD, for a plumb-backend older than depth_frame3_t, "
            "which does not hear PLUMB_RGBD3 (without the session, two scans whose capture "
            "clocks overlap can replace each other's raw frames in one store)")
        .range(2, 3);
}

void describe(config::Schema& s, DeviceConfig& c) {
    s.section("capture", c.capture, "frame capture");
    s.section("fusion", c.fusion, "tracking and fusion into fragments");
    s.section("stream", c.stream, "fragment transfer over LCM");
}

FusionConfig toFusionConfig(const FusionOptions& options) {
    FusionConfig c;
    c.frames_per_fragment = options.frames_per_fragment;
    c.tsdf.voxel_size_m = static_cast<float>(options.voxel_size_m);
    c.tsdf.truncation_m = static_cast<float>(options.truncation_m);
    c.tsdf.max_depth_m = static_cast<float>(options.max_depth_m);
    c.preprocess.max_depth_m = static_cast<float>(options.max_depth_m);
    return c;
}

}  // namespace plumb::device
