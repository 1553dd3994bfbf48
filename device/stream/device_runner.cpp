// SPDX-License-Identifier: Apache-2.0
#include "device/stream/device_runner.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <deque>
#include <fstream>
#include <mutex>
#include <thread>

#include "common/core/logging.hpp"
#include "common/core/timing.hpp"
#include "device/stream/bounded_queue.hpp"
#include "device/stream/fragment_publisher.hpp"
#include "messages/channels.hpp"
#include "messages/conversions.hpp"
#include "messages/files.hpp"
#include "messages/fragment_codec.hpp"
#include "messages/wire.hpp"

namespace plumb::device {
namespace {

using Clock = std::chrono::steady_clock;

struct EncodedFragment {
    uint32_t id = 0;
    std::vector<uint8_t> bytes;
};

// Counters shared by the threads.
struct Shared {
    std::atomic<int64_t> captured{0};
    std::atomic<int64_t> processed{0};
    std::atomic<int64_t> dropped{0};
    std::atomic<int64_t> cut{0};
    std::atomic<int64_t> raw_published{0};
    std::atomic<int64_t> raw_dropped{0};  ///< raw frames a live sensor had to drop
    std::atomic<int> tracking{static_cast<int>(messages::TrackingState::kInitializing)};
    std::atomic<bool> fusion_done{false};
    std::atomic<bool> camera_gone{false};  ///< the source reports kUnavailable (unplugged)
    std::mutex error_mutex;
    std::string source_error;
    std::string fusion_error;
};

/// Raw frames for the network thread: every `every`-th captured frame (0 = none).
struct RawFrameTap {
    int every = 0;
    BoundedQueue<Frame>* queue = nullptr;
};

void captureLoop(FrameSource& source, const CaptureConfig& config, BoundedQueue<Frame>& frames,
                 RawFrameTap raw, Shared& shared, const std::atomic<int>& stop) {
    const bool live = !source.size().has_value();
    const bool drop_when_full = live || config.realtime;
    const auto start = Clock::now();
    std::optional<double> first_timestamp;
    while (stop.load() == 0) {
        auto frame = source.next();
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            if (frame.status().code() == StatusCode::kUnavailable) {
                // The camera vanished (drivers reconnect on later next() calls): close the open
                // fragment once per outage; an empty frame tells the fusion thread to do so.
                if (!shared.camera_gone.exchange(true)) {
                    log::warn("capture: {}; closing the open fragment until it returns",
                              frame.status().message());
                    (void)frames.push(Frame{});
                }
                continue;
            }
            if (source.canSkipErrors()) {
                log::warn("capture: skipping a frame: {}", frame.status().toString());
                continue;
            }
            std::lock_guard<std::mutex> lock(shared.error_mutex);
            shared.source_error = frame.status().toString();
            break;
        }
        if (shared.camera_gone.exchange(false)) log::info("capture: the camera is back");
        ++shared.captured;
        if (config.realtime && !live) {
            // Emulate a sensor: frame k is available at its timestamp after the first one.
            if (!first_timestamp) first_timestamp = frame->timestamp_s;
            const double offset = std::max(0.0, frame->timestamp_s - *first_timestamp);
            std::this_thread::sleep_until(start + std::chrono::duration_cast<Clock::duration>(
                                                      std::chrono::duration<double>(offset)));
        }
        if (raw.every > 0 && (shared.captured.load() - 1) % raw.every == 0) {
            Frame copy = *frame;
            if (drop_when_full ? !raw.queue->tryPush(copy) : !raw.queue->push(std::move(copy))) {
                ++shared.raw_dropped;
            }
        }
        if (drop_when_full) {
            Frame f = std::move(frame).value();
            if (!frames.tryPush(f)) ++shared.dropped;
        } else if (!frames.push(std::move(frame).value())) {
            break;
        }
    }
    frames.close();
    if (raw.queue != nullptr) raw.queue->close();
}

/// A raw frame's message and the channel it goes out on.
struct RawFrameMessage {
    const char* channel = messages::kChannelRgbdSession;
    messages::Bytes bytes;
};

/// A captured frame of session `session_id` as stream.raw_frame_type says: a depth_frame3_t on
/// PLUMB_RGBD3, or a depth_frame2_t without the session on PLUMB_RGBD (depth in millimetres,
/// delta-varint; colour DELTA_RICE unless stream.raw_frame_colour is false).
Result<RawFrameMessage> encodeRawFrame(const Frame& frame, const StreamConfig& config,
                                       int64_t session_id, int64_t seq) {
    messages::RawRgbdFrame raw;
    raw.utime = messages::toUtime(frame.timestamp_s);
    raw.frame_index = frame.index;
    raw.depth_scale = 1000.0;
    raw.depth = toRaw(frame.depth, raw.depth_scale);
    if (config.raw_frame_colour) raw.colour = frame.colour;
    constexpr auto kDepth = messages::DepthEncoding::kDeltaVarint;
    constexpr auto kColour = messages::ColourEncoding::kDeltaRice;
    if (config.raw_frame_type == 2) {
        auto msg = messages::toMessage(raw, kDepth, kColour, seq);
        if (!msg.isOk()) return msg.status();
        return RawFrameMessage{messages::kChannelRgbd, messages::encodeMessage(*msg)};
    }
    auto msg = messages::toSessionMessage(raw, session_id, kDepth, kColour, seq);
    if (!msg.isOk()) return msg.status();
    return RawFrameMessage{messages::kChannelRgbdSession, messages::encodeMessage(*msg)};
}

void fusionLoop(const PinholeCamera& camera, const DeviceConfig& config,
                BoundedQueue<Frame>& frames, BoundedQueue<EncodedFragment>& out, Shared& shared) {
    FragmentBuilder builder(camera, toFusionConfig(config.fusion));
    messages::FragmentCodecConfig codec;
    codec.include_colors = config.stream.include_colors;
    // Frames tracked with a translation the depth in view left free, not yet in a closed fragment.
    std::deque<int64_t> unconstrained;
    auto emit = [&](const Fragment& fragment) {
        if (!fragment.frames.empty()) {
            const int64_t first = fragment.frames.front().frame_index;
            const int64_t last = fragment.frames.back().frame_index;
            size_t marked = 0;
            while (!unconstrained.empty() && unconstrained.front() <= last) {
                marked += unconstrained.front() >= first ? 1 : 0;
                unconstrained.pop_front();
            }
            if (5 * marked >= fragment.frames.size() && marked > 0) {
                log::warn(
                    "fusion: fragment {}: {} of {} frames tracked with a translation the depth "
                    "does not constrain (a plain wall, a corridor); along it the pose follows "
                    "the constant-velocity prediction and may drift: keep more structure in view",
                    fragment.id, marked, fragment.frames.size());
            }
        }
        auto bytes = messages::encodeFragment(fragment, codec);
        if (!bytes.isOk()) {
            // A fragment the codec refuses (e.g. NaN points) is a fusion bug; say so loudly.
            log::error("fusion: fragment {} cannot be encoded: {}", fragment.id,
                       bytes.status().toString());
            std::lock_guard<std::mutex> lock(shared.error_mutex);
            shared.fusion_error = bytes.status().toString();
            return;
        }
        ++shared.cut;
        (void)out.push(EncodedFragment{fragment.id, std::move(bytes).value()});
    };
    while (true) {
        auto frame = frames.pop(std::chrono::milliseconds(50));
        if (!frame) {
            if (frames.drained()) break;
            continue;
        }
        if (frame->depth.empty()) {  // capture's marker: the camera vanished
            if (auto closed = builder.finish()) emit(*closed);
            shared.tracking = static_cast<int>(messages::TrackingState::kLost);
            continue;
        }
        auto report = builder.process(*frame);
        ++shared.processed;
        if (!report.isOk()) {
            log::warn("fusion: frame {}: {}", frame->index, report.status().toString());
            continue;
        }
        shared.tracking = static_cast<int>(report->tracked ? messages::TrackingState::kOk
                                                           : messages::TrackingState::kLost);
        if (report->tracked && report->icp.num_degenerate_directions > 0) {
            unconstrained.push_back(report->frame_index);
        }
        if (!report->message.empty())
            log::debug("fusion: frame {}: {}", frame->index, report->message);
        for (const Fragment& f : report->closed) emit(f);
    }
    if (auto last = builder.finish()) emit(*last);
    shared.fusion_done = true;
    out.close();
}

/// Fragments on their way from fusion into the spool. A fragment counts as kept once the
/// publisher's spool took it (only then is it written to the dump folder); one the spool never
/// takes is lost at exit. While kMaxWaiting fragments wait for room, no more are taken from
/// fusion, which then waits (and capture drops or waits), so a full spool costs frames, not memory.
class SpoolFeeder {
  public:
    static constexpr size_t kMaxWaiting = 2;

    SpoolFeeder(FragmentPublisher& publisher, const DeviceRunOptions& options)
        : publisher_(publisher), options_(options) {}

    /// Takes fragments from `fragments` (all of them when `take_all`, else while fewer than
    /// kMaxWaiting wait) and submits them in order.
    void feed(BoundedQueue<EncodedFragment>& fragments, bool take_all, double now_s) {
        while (take_all || waiting_.size() < kMaxWaiting) {
            auto f = fragments.tryPop();
            if (!f) break;
            waiting_.push_back(std::move(*f));
            submitWaiting(now_s);
        }
        submitWaiting(now_s);
    }
    void add(EncodedFragment f) { waiting_.push_back(std::move(f)); }
    /// Fragments cut but not (yet) in the spool.
    size_t waiting() const { return waiting_.size(); }
    /// Submits what still waits one last time; what the spool refuses is lost.
    void finish(double now_s) {
        submitWaiting(now_s);
        for (const EncodedFragment& f : waiting_) lost_.push_back(f.id);
        waiting_.clear();
    }
    const std::vector<uint32_t>& lost() const { return lost_; }
    /// Why the spool last refused a fragment (empty: it never did).
    const std::string& spoolError() const { return spool_error_; }

  private:
    void submitWaiting(double now_s) {
        while (!waiting_.empty()) {
            EncodedFragment& f = waiting_.front();
            const Status s = publisher_.submit(f.id, f.bytes, now_s);
            if (s.code() == StatusCode::kIoError) {  // no room: retried on the next call
                if (!stalled_) {
                    log::warn(
                        "device: fragment {} waits for room in the spool ({}); fusion is held "
                        "back until the backend acknowledges",
                        f.id, s.message());
                }
                stalled_ = true;
                spool_error_ = s.message();
                return;
            }
            if (stalled_) log::info("device: the spool has room again");
            stalled_ = false;
            if (s.isOk()) {
                dump(f);
            } else {
                log::error("device: fragment {}: {}", f.id, s.toString());
                spool_error_ = s.message();
                lost_.push_back(f.id);
            }
            waiting_.pop_front();
        }
    }
    void dump(const EncodedFragment& f) const {
        if (options_.dump_dir.empty()) return;
        const auto path = options_.dump_dir / messages::fragmentFileName(options_.session_id, f.id);
        const Status s = messages::writeFileAtomic(path, f.bytes);
        if (!s.isOk()) log::warn("device: dump: {}", s.toString());
    }

    FragmentPublisher& publisher_;
    const DeviceRunOptions& options_;
    std::deque<EncodedFragment> waiting_;
    std::vector<uint32_t> lost_;
    std::string spool_error_;
    bool stalled_ = false;
};

/// Logs the backend's "cannot store" answers: the first one, then at most one line a minute.
class BackoffLog {
  public:
    void note(const FragmentPublisher& publisher, double now_s) {
        const uint64_t n = publisher.senderStats().backoffs_received;
        if (n == seen_) return;
        if (seen_ == 0 || now_s - logged_s_ >= 60.0) {
            log::warn(
                "device: the backend cannot store fragments ({}); re-sending only after its "
                "back-off ({} answer(s) so far)",
                publisher.lastBackoffMessage(), n);
            logged_s_ = now_s;
        }
        seen_ = n;
    }

  private:
    uint64_t seen_ = 0;
    double logged_s_ = 0.0;
};

/// The publisher of this run, resuming what earlier runs left in the spool directory; creates
/// the dump folder.
Result<std::unique_ptr<FragmentPublisher>> openPublisher(const DeviceRunOptions& options,
                                                         messages::Transport& transport) {
    const StreamConfig& sc = options.config.stream;
    PublisherConfig pc;
    pc.session_id = options.session_id;
    pc.sender.chunk_payload_bytes = sc.chunk_payload_bytes;
    pc.sender.retransmit_timeout_s = sc.retransmit_timeout_s;
    pc.sender.max_retransmit_timeout_s = sc.max_retransmit_timeout_s;
    pc.max_in_flight = sc.max_in_flight;
    pc.spool.memory_budget_bytes = sc.spool_memory_bytes;
    pc.spool.disk_budget_bytes = sc.spool_disk_bytes;
    pc.spool.disk_dir = options.spool_dir;
    auto created = FragmentPublisher::create(pc, transport);
    if (!created.isOk()) return created.status();
    if ((*created)->unacknowledged() > 0) {
        log::info("device: {} unacknowledged fragment(s) of earlier runs found in {}; resending",
                  (*created)->unacknowledged(), options.spool_dir.string());
    }
    if (!options.dump_dir.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(options.dump_dir, ec);
        if (ec) {
            return ioError(fmt::format("device: cannot create dump dir {}: {}",
                                       options.dump_dir.string(), ec.message()));
        }
    }
    return created;
}

/// What the network thread publishes besides fragments: camera info and the configuration
/// snapshot, the status heartbeat, raw frames. Owns the sequence number of these messages.
class Announcer {
  public:
    Announcer(const DeviceRunOptions& options, messages::Transport& transport,
              const FrameSource& source, const Shared& shared)
        : options_(options), transport_(transport), shared_(shared) {
        info_.camera = source.camera();
        info_.depth_scale = 1000.0;
        info_.source = source.description();
        last_fps_time_ = wallClockSeconds();
    }

    void config(double now) {
        const int64_t utime = messages::toUtime(now);
        publish(messages::kChannelCameraInfo,
                messages::encodeMessage(messages::toMessage(info_, utime, ++seq_)));
        publish(messages::kChannelConfig,
                messages::encodeMessage(messages::toMessage("plumb-device", options_.version,
                                                            options_.config_toml, utime, ++seq_)));
    }

    /// The heartbeat; `stopped`: the end of the scan (TRACKING_STOPPED, final fragment count).
    void status(double now, bool stopped, const FragmentPublisher& publisher, size_t waiting) {
        const int64_t processed = shared_.processed.load();
        if (now > last_fps_time_) fps_ = (processed - last_processed_) / (now - last_fps_time_);
        last_processed_ = processed;
        last_fps_time_ = now;
        messages::DeviceStatus st;
        st.session_id = options_.session_id;
        st.fps = fps_;
        // While the camera is gone the heartbeat says so (tracking resumes when it returns).
        st.tracking = stopped ? messages::TrackingState::kStopped
                      : shared_.camera_gone.load()
                          ? messages::TrackingState::kNoCamera
                          : static_cast<messages::TrackingState>(shared_.tracking.load());
        st.frames_processed = processed;
        st.frames_dropped = shared_.dropped.load();
        st.fragments_cut = static_cast<int32_t>(shared_.cut.load());
        st.fragments_acked = static_cast<int32_t>(publisher.stats().fragments_acked);
        st.spool_fragments = static_cast<int32_t>(publisher.unacknowledged() + waiting);
        st.spool_bytes = publisher.spoolBytes();
        st.memory_bytes = residentMemoryBytes();
        publish(messages::kChannelStatus,
                messages::encodeMessage(messages::toMessage(st, messages::toUtime(now), ++seq_)));
    }

    /// Publishes the raw frames captured since the last call; returns how many.
    int64_t rawFrames(BoundedQueue<Frame>& raw_frames) {
        int64_t n = 0;
        const StreamConfig& sc = options_.config.stream;
        while (auto raw = raw_frames.tryPop()) {
            auto msg = encodeRawFrame(*raw, sc, options_.session_id, ++seq_);
            if (!msg.isOk()) {
                log::warn("device: raw frame {}: {}", raw->index, msg.status().toString());
                continue;
            }
            publish(msg->channel, msg->bytes);
            ++n;
        }
        return n;
    }

  private:
    void publish(const char* channel, const messages::Bytes& bytes) {
        const Status s = transport_.publish(channel, bytes);
        if (!s.isOk()) log::warn("device: {}", s.toString());
    }

    const DeviceRunOptions& options_;
    messages::Transport& transport_;
    const Shared& shared_;
    messages::CameraInfo info_;
    int64_t seq_ = 0;
    int64_t last_processed_ = 0;
    double last_fps_time_ = 0.0;
    double fps_ = 0.0;
};

/// The counters and errors of a finished run.
void fillReport(Shared& shared, const FragmentPublisher& publisher, const SpoolFeeder& feeder,
                DeviceRunReport& report) {
    report.frames_captured = shared.captured.load();
    report.frames_processed = shared.processed.load();
    report.frames_dropped = shared.dropped.load();
    report.fragments_cut = shared.cut.load();
    report.raw_frames_published = shared.raw_published.load();
    report.raw_frames_dropped = shared.raw_dropped.load();
    if (report.raw_frames_dropped > 0) {
        log::info("device: {} raw frames published, {} dropped (the network thread lagged)",
                  report.raw_frames_published, report.raw_frames_dropped);
    }
    report.fragments_acked = static_cast<int64_t>(publisher.stats().fragments_acked);
    report.unacknowledged = publisher.unacknowledgedKeys();
    report.lost = feeder.lost();
    report.spool_error = feeder.spoolError();
    report.quarantined = publisher.quarantined();
    report.quarantine_dir = publisher.quarantineDir();
    std::lock_guard<std::mutex> lock(shared.error_mutex);
    report.source_error = !shared.source_error.empty();
    report.source_message = shared.source_error;
    if (!shared.fusion_error.empty()) {
        report.source_error = true;
        report.source_message = "fusion: " + shared.fusion_error;
    }
}

}  // namespace

int64_t residentMemoryBytes() {
    std::ifstream statm("/proc/self/statm");
    int64_t size = 0, resident = 0;
    if (!(statm >> size >> resident)) return 0;
    return resident * static_cast<int64_t>(sysconf(_SC_PAGESIZE));
}

Result<DeviceRunReport> runDevice(FrameSource& source, const DeviceRunOptions& options,
                                  DeviceLink link, const std::atomic<int>& stop_requests) {
    if (link.transport == nullptr || !link.pump) return invalidArgument("device: no transport");
    PLUMB_RETURN_IF_ERROR(toFusionConfig(options.config.fusion).validate());
    const StreamConfig& sc = options.config.stream;
    messages::Transport& transport = *link.transport;
    auto opened = openPublisher(options, transport);
    if (!opened.isOk()) return opened.status();
    std::unique_ptr<FragmentPublisher> publisher = std::move(opened).value();
    for (const char* channel : {messages::kChannelFragmentAck, messages::kChannelRetransmit,
                                messages::kChannelFragmentBackoff}) {
        PLUMB_RETURN_IF_ERROR(transport.subscribe(
            channel, [&](const std::string& ch, std::span<const uint8_t> bytes) {
                publisher->onMessage(ch, bytes, wallClockSeconds());
            }));
    }

    Shared shared;
    BoundedQueue<Frame> frames(static_cast<size_t>(options.config.capture.queue_frames));
    BoundedQueue<EncodedFragment> fragments(4);
    BoundedQueue<Frame> raw_frames(2);
    const RawFrameTap raw_tap{sc.raw_frame_every, sc.raw_frame_every > 0 ? &raw_frames : nullptr};
    std::atomic<int> capture_stop{0};
    std::thread capture([&] {
        captureLoop(source, options.config.capture, frames, raw_tap, shared, capture_stop);
    });
    std::thread fusion(
        [&] { fusionLoop(source.camera(), options.config, frames, fragments, shared); });

    Announcer announce(options, transport, source, shared);
    SpoolFeeder feeder(*publisher, options);
    BackoffLog backoffs;
    DeviceRunReport report;
    double last_status = -1e300, last_config = -1e300, wait_start = -1.0;
    Status failure;
    // The network loop. A stop request ends capture; once fusion is done the device waits up
    // to ack_wait_s for acknowledgements (and for room in the spool); a second request ends it.
    while (true) {
        failure = link.pump(10);
        if (!failure.isOk()) break;
        const double now = wallClockSeconds();
        if (stop_requests.load() > 0 && !report.stopped_by_signal) {
            report.stopped_by_signal = true;
            log::info("device: stop requested; closing the open fragment and flushing");
            capture_stop = 1;
        }
        shared.raw_published += announce.rawFrames(raw_frames);
        const bool fusion_done = shared.fusion_done.load();
        feeder.feed(fragments, report.stopped_by_signal || fusion_done, now);
        publisher->poll(now);
        backoffs.note(*publisher, now);
        const bool scan_done = fusion_done && fragments.drained();
        if (now - last_config >= sc.config_period_s) {
            announce.config(now);
            last_config = now;
        }
        if (now - last_status >= sc.status_period_s) {
            announce.status(now, scan_done, *publisher, feeder.waiting());
            last_status = now;
        }
        if (!scan_done) continue;
        if (wait_start < 0) {
            wait_start = now;
            announce.status(now, true, *publisher, feeder.waiting());  // the final count
            log::info(
                "device: capture finished ({} frames, {} dropped, {} fragments); waiting up to "
                "{} s for {} acknowledgement(s){}",
                shared.processed.load(), shared.dropped.load(), shared.cut.load(), sc.ack_wait_s,
                publisher->unacknowledged(),
                feeder.waiting() > 0
                    ? fmt::format(" and for room in the spool for {} fragment(s)", feeder.waiting())
                    : "");
        }
        if (publisher->unacknowledged() == 0 && feeder.waiting() == 0) break;
        if (now - wait_start >= sc.ack_wait_s || stop_requests.load() > 1) break;
    }
    capture_stop = 1;
    frames.close();
    raw_frames.close();  // capture may wait on it (recorded sources)
    // Fusion finishes the frames it holds; what it still emits goes to the spool if it can.
    while (!shared.fusion_done.load()) {
        if (auto f = fragments.pop(std::chrono::milliseconds(20))) feeder.add(std::move(*f));
    }
    capture.join();
    fusion.join();
    while (auto f = fragments.tryPop()) feeder.add(std::move(*f));
    feeder.finish(wallClockSeconds());
    if (!failure.isOk()) return failure;
    shared.raw_published += announce.rawFrames(raw_frames);  // the last ones captured
    fillReport(shared, *publisher, feeder, report);
    return report;
}

}  // namespace plumb::device
