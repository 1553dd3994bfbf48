// SPDX-License-Identifier: Apache-2.0
#pragma once

// The plumb-device pipeline with its threads: capture -> (bounded frame queue) -> tracking and
// fusion (device/fusion/fragment_builder.hpp) -> (bounded fragment queue) -> the network thread
// (the caller's), which spools, chunks, sends and retransmits fragments
// (device/stream/fragment_publisher.hpp), publishes the status heartbeat, camera info and the
// configuration snapshot, and dispatches acknowledgements. With stream.raw_frame_every = N, every
// N-th captured frame also goes to the network thread, which publishes it raw (depth and colour)
// with the session id as a depth_frame3_t on PLUMB_RGBD3. LCM is used from the network thread
// only.
//
// Capture never blocks on a live sensor (or with capture.realtime): when fusion lags, frames are
// dropped, counted and reported in the heartbeat. When the camera vanishes (the source reports
// kUnavailable), the open fragment is closed, the heartbeat says TRACKING_NO_CAMERA, and the scan
// resumes with the next fragment when the camera returns. At the end of the source, or on a stop
// request (SIGINT/SIGTERM), the open fragment is closed and sent, a final heartbeat says
// TRACKING_STOPPED with the final fragment count (the backend's end-of-scan signal), and the
// device waits up to stream.ack_wait_s for the remaining acknowledgements. A second stop request
// ends the wait at once. Unacknowledged fragments are left in the spool directory, where each
// one was written (and fsynced) when it was cut, so even SIGKILL loses none of them.
//
// A fragment counts as kept once the spool took it. When the spool is full (no backend answers
// and the memory or disk budget is used up), the next fragments wait for room and fusion is held
// back (capture drops frames, or waits for a recorded source); stop requests are honoured all
// the same, and at exit the fragments that never got into the spool are reported as lost.
//
// Thread-safety: runDevice starts and joins its own capture and fusion threads and uses the
// calling thread as the network thread; run one at a time per source. residentMemoryBytes is
// thread-safe.

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "common/frame/frame_source.hpp"
#include "device/stream/device_config.hpp"
#include "device/stream/spool.hpp"
#include "messages/transport.hpp"

namespace plumb::device {

struct DeviceRunOptions {
    DeviceConfig config;
    /// The effective configuration as TOML (published on PLUMB_CONFIG).
    std::string config_toml;
    /// Program version for the configuration snapshot.
    std::string version = "0";
    /// Identifies this run; fragment ids restart per session.
    int64_t session_id = 0;
    /// Disk spool of unacknowledged fragments (kept across runs); empty = memory only.
    std::filesystem::path spool_dir;
    /// When set, every encoded fragment is also written here as sent (the device's own record).
    std::filesystem::path dump_dir;
};

/// The network seam: where to publish and subscribe, and how to dispatch received messages.
struct DeviceLink {
    messages::Transport* transport = nullptr;
    /// Dispatches received messages for up to `timeout_ms`; errors end the run.
    std::function<Status(int timeout_ms)> pump;
};

struct DeviceRunReport {
    int64_t frames_captured = 0;
    int64_t frames_processed = 0;
    int64_t frames_dropped = 0;
    int64_t fragments_cut = 0;
    int64_t fragments_acked = 0;
    int64_t raw_frames_published = 0;  ///< depth_frame3_t on PLUMB_RGBD3 (stream.raw_frame_every)
    int64_t raw_frames_dropped = 0;    ///< raw frames a live sensor could not wait for
    bool stopped_by_signal = false;
    bool source_error = false;   ///< the source failed (not a normal end)
    std::string source_message;  ///< its error
    /// Fragments still unacknowledged at exit: kept (in the spool directory when there is one,
    /// else lost with the process).
    std::vector<messages::FragmentKey> unacknowledged;
    /// Fragments of this session that were cut but never entered the spool (it stayed full
    /// until the end, or refused them): lost.
    std::vector<uint32_t> lost;
    /// Why the spool last refused a fragment (empty: never).
    std::string spool_error;
    /// Fragments the backend rejected for good in this run, moved to `quarantine_dir` (each with
    /// a .reason file; empty dir: no spool directory, dropped).
    std::vector<messages::FragmentKey> quarantined;
    std::filesystem::path quarantine_dir;
};

/// Runs the pipeline until the source ends or `stop_requests` becomes non-zero, then flushes.
/// Errors: unusable configuration, spool or transport failures.
Result<DeviceRunReport> runDevice(FrameSource& source, const DeviceRunOptions& options,
                                  DeviceLink link, const std::atomic<int>& stop_requests);

/// Resident memory of this process in bytes (0 when unknown).
int64_t residentMemoryBytes();

}  // namespace plumb::device
