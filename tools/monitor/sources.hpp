// SPDX-License-Identifier: Apache-2.0
#pragma once

// The monitor's three feeds, each filling a MonitorState:
//  - DirectoryWatcher: an output directory (fragment store files, pose_graph.json, layout.json,
//    trajectory.txt, and metrics.json, whose "status" says the run has ended), polled for
//    changes. It only reads: it never renames, deletes or writes (the
//    backend may be writing the same directory).
//  - LiveSource: LCM (device_status_t heartbeats, fragment headers and chunks, acks).
//  - LogReplaySource: an LCM log file (lcm-logger format) played back at a chosen speed.
// The monitor is a passive listener: it reassembles fragments with FragmentAssembler over a
// transport that publishes nothing, so it never acknowledges a fragment or asks for a
// retransmission on behalf of the real backend.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>

#include "common/config/schema.hpp"
#include "common/core/status.hpp"
#include "messages/fragment_assembler.hpp"
#include "messages/transport.hpp"
#include "tools/monitor/monitor_state.hpp"

namespace plumb::monitor {

/// A transport that drops everything it is asked to publish (keeps the monitor passive).
class ListenOnlyTransport final : public messages::Transport {
  public:
    Status publish(const std::string&, std::span<const uint8_t>) override {
        ++dropped_;
        return Status::ok();
    }
    Status subscribe(const std::string&, Handler) override {
        return failedPrecondition("ListenOnlyTransport: no subscriptions");
    }
    uint64_t dropped() const { return dropped_; }

  private:
    uint64_t dropped_ = 0;
};

/// Routes plumb's LCM messages into a MonitorState: heartbeats, fragments (reassembled from
/// chunks, CRC-checked and decoded) and acks. Not thread-safe: one thread calls onMessage().
class MessageIngest {
  public:
    explicit MessageIngest(MonitorState& state);

    /// Handles one message of any plumb channel (others are ignored). Malformed messages are
    /// counted and reported on the page, never fatal.
    void onMessage(const std::string& channel, std::span<const uint8_t> bytes, double now_s);

    /// Publishes the link counters to the state (done every 64 messages and on every fragment).
    void flushStats();

    uint64_t messages() const { return messages_; }
    uint64_t fragmentsDecoded() const { return fragments_decoded_; }
    uint64_t malformed() const { return malformed_; }
    /// Messages the assembler asked to publish (acks, retransmission requests) that were dropped.
    uint64_t suppressedPublications() const { return transport_.dropped(); }
    /// Channels this ingest understands.
    static const std::vector<std::string>& channels();

  private:
    void report(const std::string& message);

    MonitorState& state_;
    ListenOnlyTransport transport_;
    messages::FragmentAssembler assembler_;
    uint64_t messages_ = 0;
    uint64_t fragments_decoded_ = 0;
    uint64_t malformed_ = 0;
    uint64_t errors_reported_ = 0;
};

struct DirectoryWatcherConfig {
    /// Interval between two scans of the directory, seconds.
    double poll_interval_s = 0.25;
    /// Fragment files decoded per scan at most (the rest follow on the next scans).
    int max_fragments_per_scan = 64;
};
void describe(config::Schema& s, DirectoryWatcherConfig& c);

class DirectoryWatcher {
  public:
    /// Fragments are read from `dir`/fragments (the fragment store) when it exists, else from
    /// files named like the store's ("s<session>_f<id>.plf") in `dir` itself.
    DirectoryWatcher(std::filesystem::path dir, MonitorState& state,
                     DirectoryWatcherConfig config = {});
    ~DirectoryWatcher();

    /// One scan: new or changed files are read into the state. Returns the number of files that
    /// changed the state. Errors (unreadable, corrupt files) are reported to the state.
    int scanOnce();
    /// Scans every poll_interval_s on a thread until stop() (or destruction).
    void start();
    void stop();

  private:
    struct Stamp {
        std::filesystem::file_time_type mtime{};
        uintmax_t size = 0;
        bool operator==(const Stamp&) const = default;
    };
    bool changed(const std::filesystem::path& path, Stamp* stamp);
    int scanFragments();
    int scanPoseGraph();
    int scanLayout();
    int scanTrajectory();
    int scanMetrics();
    /// The JSON document at `path`; nullopt after reporting it to failed() when it cannot be
    /// read or parsed.
    std::optional<nlohmann::json> readJson(const std::filesystem::path& path, const Stamp& stamp);
    /// Records a failure for `path` at `stamp`; reported once per stamp after three attempts
    /// (a file being rewritten in place may be read half-written once).
    void failed(const std::filesystem::path& path, const Stamp& stamp, const std::string& why);

    std::filesystem::path dir_;
    MonitorState& state_;
    DirectoryWatcherConfig config_;
    std::map<std::filesystem::path, Stamp> seen_;
    std::map<std::filesystem::path, std::pair<Stamp, int>> failures_;
    std::thread thread_;
    std::mutex mutex_;
    std::condition_variable wake_;
    bool stop_ = false;
};

/// Live LCM: subscribes to plumb's channels at `url` and feeds a MessageIngest on a thread.
class LiveSource {
  public:
    /// Opens LCM (IoError / NotFound when it cannot) and starts the thread.
    static Result<std::unique_ptr<LiveSource>> start(const std::string& url, MonitorState& state);
    ~LiveSource();
    void stop();

  private:
    struct Impl;
    explicit LiveSource(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

/// Plays an LCM log into a MessageIngest on a thread. speed = 1 plays in real time, 2 twice as
/// fast, 0 as fast as possible.
class LogReplaySource {
  public:
    /// NotFound / IoError when the log cannot be opened; InvalidArgument for a negative speed.
    static Result<std::unique_ptr<LogReplaySource>> start(const std::filesystem::path& log,
                                                          double speed, MonitorState& state);
    ~LogReplaySource();
    void stop();
    /// True once the whole log was played (or stop() was called).
    bool finished() const { return finished_.load(); }

  private:
    LogReplaySource() = default;
    void run(std::filesystem::path log, double speed, MonitorState& state);

    std::thread thread_;
    std::mutex mutex_;
    std::condition_variable wake_;
    bool stop_ = false;
    std::atomic<bool> finished_{false};
};

}  // namespace plumb::monitor
