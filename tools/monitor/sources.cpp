// SPDX-License-Identifier: Apache-2.0
#include "tools/monitor/sources.hpp"

#include <fmt/format.h>
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <chrono>
#include <nlohmann/json.hpp>
#include <system_error>
#include <vector>

#include "common/io/trajectory.hpp"
#include "common/layout/layout_json.hpp"
#include "messages/channels.hpp"
#include "messages/conversions.hpp"
#include "messages/files.hpp"
#include "messages/fragment_codec.hpp"
#include "messages/fragment_files.hpp"
#include "messages/fragment_store.hpp"
#include "messages/lcm_transport.hpp"
#include "messages/wire.hpp"

namespace plumb::monitor {

namespace fs = std::filesystem;

namespace {

constexpr int64_t kMaxFragmentFileBytes = int64_t{1} << 30;
constexpr int64_t kMaxJsonFileBytes = int64_t{256} << 20;
constexpr uint64_t kMaxReportedErrors = 200;

double steadySeconds() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// MessageIngest

MessageIngest::MessageIngest(MonitorState& state)
    : state_(state), assembler_(messages::FragmentAssemblerConfig{}, transport_) {}

const std::vector<std::string>& MessageIngest::channels() {
    static const std::vector<std::string> kChannels = {
        messages::kChannelStatus, messages::kChannelFragmentHeader, messages::kChannelFragmentChunk,
        messages::kChannelFragmentAck};
    return kChannels;
}

void MessageIngest::report(const std::string& message) {
    // A flood of bad packets must not flood the page: the first ones are enough to diagnose.
    if (++errors_reported_ <= kMaxReportedErrors) state_.addError(message);
}

void MessageIngest::onMessage(const std::string& channel, std::span<const uint8_t> bytes,
                              double now_s) {
    ++messages_;
    if (channel == messages::kChannelStatus) {
        auto msg = messages::decodeMessage<plumb::device_status_t>(bytes);
        if (!msg.isOk()) {
            ++malformed_;
            report(msg.status().message());
            return;
        }
        auto status = messages::fromMessage(*msg);
        if (!status.isOk()) {
            ++malformed_;
            report(status.status().message());
            return;
        }
        state_.setDevice(*status, msg->utime, msg->seq);
        return;
    }
    if (channel == messages::kChannelFragmentAck) {
        auto msg = messages::decodeMessage<plumb::fragment_ack_t>(bytes);
        if (!msg.isOk() || msg->fragment_id < 0) {
            ++malformed_;
            return;
        }
        state_.setFragmentAck(msg->session_id, static_cast<uint32_t>(msg->fragment_id),
                              msg->status == plumb::fragment_ack_t::STATUS_PERSISTED);
        return;
    }
    if (channel != messages::kChannelFragmentHeader && channel != messages::kChannelFragmentChunk) {
        return;
    }
    const uint64_t before = assembler_.stats().malformed_messages +
                            assembler_.stats().chunk_crc_failures +
                            assembler_.stats().fragment_crc_failures;
    Status s = assembler_.onMessage(channel, bytes, now_s);
    if (!s.isOk()) report(fmt::format("{}: {}", channel, s.message()));
    bool changed = assembler_.stats().malformed_messages + assembler_.stats().chunk_crc_failures +
                       assembler_.stats().fragment_crc_failures !=
                   before;
    for (messages::CompletedFragment& done : assembler_.takeCompleted()) {
        auto fragment = messages::decodeFragment(done.bytes);
        if (!fragment.isOk()) {
            report(fmt::format("fragment {} of session {}: {}", done.fragment_id, done.session_id,
                               fragment.status().message()));
            assembler_.reject(done.session_id, done.fragment_id, now_s);  // publishes nothing
            changed = true;
            continue;
        }
        assembler_.acknowledge(done.session_id, done.fragment_id, now_s);  // publishes nothing
        state_.addFragment(*fragment, done.session_id, "lcm");
        ++fragments_decoded_;
        changed = true;
    }
    if (changed || messages_ % 64 == 0) flushStats();
}

void MessageIngest::flushStats() { state_.setLinkStats(assembler_.stats(), messages_, malformed_); }

// ---------------------------------------------------------------------------------------------
// DirectoryWatcher

void describe(config::Schema& s, DirectoryWatcherConfig& c) {
    s.field("poll_interval_s", c.poll_interval_s, "interval between two scans of the directory",
            "s")
        .positive()
        .max(60.0);
    s.field("max_fragments_per_scan", c.max_fragments_per_scan,
            "fragment files decoded per scan at most", "files")
        .min(1);
}

DirectoryWatcher::DirectoryWatcher(fs::path dir, MonitorState& state, DirectoryWatcherConfig config)
    : dir_(std::move(dir)), state_(state), config_(config) {}

DirectoryWatcher::~DirectoryWatcher() { stop(); }

bool DirectoryWatcher::changed(const fs::path& path, Stamp* stamp) {
    std::error_code ec;
    const auto status = fs::status(path, ec);
    if (ec || !fs::is_regular_file(status)) return false;
    stamp->mtime = fs::last_write_time(path, ec);
    if (ec) return false;
    stamp->size = fs::file_size(path, ec);
    if (ec) return false;
    auto it = seen_.find(path);
    return it == seen_.end() || !(it->second == *stamp);
}

void DirectoryWatcher::failed(const fs::path& path, const Stamp& stamp, const std::string& why) {
    auto& [failed_stamp, count] = failures_[path];
    if (!(failed_stamp == stamp)) {
        failed_stamp = stamp;
        count = 0;
    }
    if (++count == 3) {
        state_.addError(why);
        seen_[path] = stamp;  // give up on this version of the file; a rewrite is read again
    }
}

std::optional<nlohmann::json> DirectoryWatcher::readJson(const fs::path& path, const Stamp& stamp) {
    auto bytes = messages::readFile(path, kMaxJsonFileBytes);
    if (!bytes.isOk()) {
        failed(path, stamp, bytes.status().message());
        return std::nullopt;
    }
    nlohmann::json j = nlohmann::json::parse(bytes->begin(), bytes->end(), nullptr, false);
    if (j.is_discarded()) {
        failed(path, stamp, path.string() + ": invalid JSON");
        return std::nullopt;
    }
    return j;
}

int DirectoryWatcher::scanFragments() {
    fs::path store = dir_ / "fragments";
    std::error_code ec;
    if (!fs::is_directory(store, ec)) store = dir_;
    std::vector<fs::path> files;
    for (const auto& item : fs::directory_iterator(store, ec)) {
        int64_t session = 0;
        uint32_t id = 0;
        if (messages::parseFragmentFileName(item.path().filename().string(), session, id)) {
            files.push_back(item.path());
        }
    }
    std::sort(files.begin(), files.end());
    int updates = 0;
    int decoded = 0;
    for (const fs::path& path : files) {
        if (decoded >= config_.max_fragments_per_scan) break;
        Stamp stamp;
        if (!changed(path, &stamp)) continue;
        ++decoded;
        int64_t session = 0;
        uint32_t id = 0;
        messages::parseFragmentFileName(path.filename().string(), session, id);
        auto bytes = messages::readFile(path, kMaxFragmentFileBytes);
        if (!bytes.isOk()) {
            failed(path, stamp, bytes.status().message());
            continue;
        }
        // The store renames complete files into place, so a bad trailer is damage, not a write
        // in progress; still, allow for a store written in place by someone else.
        if (!messages::hasValidCrcTrailer(*bytes)) {
            failed(path, stamp, path.string() + ": fails its CRC-32 trailer");
            continue;
        }
        auto fragment = messages::decodeFragment(*bytes);
        if (!fragment.isOk()) {
            failed(path, stamp, path.string() + ": " + fragment.status().message());
            continue;
        }
        seen_[path] = stamp;
        state_.addFragment(*fragment, session, "store");
        ++updates;
    }
    return updates;
}

int DirectoryWatcher::scanPoseGraph() {
    const fs::path path = dir_ / "pose_graph.json";
    Stamp stamp;
    if (!changed(path, &stamp)) return 0;
    const std::optional<nlohmann::json> j = readJson(path, stamp);
    if (!j) return 0;
    auto graph = poseGraphFromJson(*j, path.string());
    if (!graph.isOk()) {
        failed(path, stamp, graph.status().message());
        return 0;
    }
    seen_[path] = stamp;
    state_.setPoseGraph(std::move(*graph));
    return 1;
}

int DirectoryWatcher::scanLayout() {
    const fs::path path = dir_ / "layout.json";
    Stamp stamp;
    if (!changed(path, &stamp)) return 0;
    auto layout = io::readLayoutJson(path);
    if (!layout.isOk()) {
        failed(path, stamp, layout.status().message());
        return 0;
    }
    seen_[path] = stamp;
    state_.setLayout(std::move(*layout));
    return 1;
}

int DirectoryWatcher::scanTrajectory() {
    const fs::path path = dir_ / "trajectory.txt";
    Stamp stamp;
    if (!changed(path, &stamp)) return 0;
    auto trajectory = io::readTumTrajectory(path);
    if (!trajectory.isOk()) {
        failed(path, stamp, trajectory.status().message());
        return 0;
    }
    seen_[path] = stamp;
    std::vector<Eigen::Vector3d> positions;
    positions.reserve(trajectory->size());
    for (const io::StampedPose& p : *trajectory) positions.push_back(p.T_W_C.translation());
    state_.setTrajectory(std::move(positions));
    return 1;
}

int DirectoryWatcher::scanMetrics() {
    // metrics.json is written last, when the run has ended ("status": "complete" or
    // "interrupted"); a run started again in the folder may remove it.
    const fs::path path = dir_ / "metrics.json";
    std::error_code ec;
    if (!fs::exists(path, ec)) {
        if (seen_.erase(path) == 0) return 0;
        state_.setRunStatus(std::nullopt);
        return 1;
    }
    Stamp stamp;
    if (!changed(path, &stamp)) return 0;
    const std::optional<nlohmann::json> j = readJson(path, stamp);
    if (!j) return 0;
    if (!j->is_object() || !j->contains("status") || !(*j)["status"].is_string()) {
        failed(path, stamp, path.string() + ": no \"status\" string");
        return 0;
    }
    seen_[path] = stamp;
    state_.setRunStatus((*j)["status"].get<std::string>());
    return 1;
}

int DirectoryWatcher::scanOnce() {
    std::error_code ec;
    if (!fs::is_directory(dir_, ec)) return 0;
    return scanFragments() + scanPoseGraph() + scanLayout() + scanTrajectory() + scanMetrics();
}

void DirectoryWatcher::start() {
    if (thread_.joinable()) return;
    thread_ = std::thread([this] {
        const auto interval = std::chrono::duration<double>(config_.poll_interval_s);
        std::unique_lock lock(mutex_);
        while (!stop_) {
            lock.unlock();
            scanOnce();
            lock.lock();
            wake_.wait_for(lock, interval, [this] { return stop_; });
        }
    });
}

void DirectoryWatcher::stop() {
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
}

// ---------------------------------------------------------------------------------------------
// LiveSource

struct LiveSource::Impl {
    std::unique_ptr<messages::LcmTransport> lcm;
    std::unique_ptr<MessageIngest> ingest;
    std::thread thread;
    std::atomic<bool> stop{false};
};

LiveSource::LiveSource(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Result<std::unique_ptr<LiveSource>> LiveSource::start(const std::string& url, MonitorState& state) {
    auto impl = std::make_unique<Impl>();
    auto lcm = messages::LcmTransport::create(url);
    if (!lcm.isOk()) return lcm.status();
    impl->lcm = std::move(*lcm);
    impl->ingest = std::make_unique<MessageIngest>(state);
    for (const std::string& channel : MessageIngest::channels()) {
        MessageIngest* ingest = impl->ingest.get();
        PLUMB_RETURN_IF_ERROR(impl->lcm->subscribe(
            channel, [ingest](const std::string& ch, std::span<const uint8_t> bytes) {
                ingest->onMessage(ch, bytes, steadySeconds());
            }));
    }
    Impl* raw = impl.get();
    raw->thread = std::thread([raw, &state] {
        while (!raw->stop.load()) {
            auto handled = raw->lcm->handle(100);
            if (!handled.isOk()) {
                state.addError("live LCM: " + handled.status().message());
                std::this_thread::sleep_for(std::chrono::milliseconds(500));
            }
        }
    });
    return std::unique_ptr<LiveSource>(new LiveSource(std::move(impl)));
}

LiveSource::~LiveSource() { stop(); }

void LiveSource::stop() {
    if (!impl_) return;
    impl_->stop = true;
    if (impl_->thread.joinable()) impl_->thread.join();
}

// ---------------------------------------------------------------------------------------------
// LogReplaySource

Result<std::unique_ptr<LogReplaySource>> LogReplaySource::start(const fs::path& log, double speed,
                                                                MonitorState& state) {
    if (!(speed >= 0.0) || !std::isfinite(speed)) {
        return invalidArgument(
            fmt::format("replay speed {} must be >= 0 (0: as fast as possible)", speed));
    }
    std::error_code ec;
    if (!fs::is_regular_file(log, ec)) return notFound(log.string() + ": no such LCM log");
    {
        lcm::LogFile probe(log.string(), "r");
        if (!probe.good()) return ioError(log.string() + ": cannot open as an LCM log");
    }
    std::unique_ptr<LogReplaySource> source(new LogReplaySource());
    LogReplaySource* raw = source.get();
    raw->thread_ = std::thread([raw, log, speed, &state] { raw->run(log, speed, state); });
    return source;
}

void LogReplaySource::run(fs::path log, double speed, MonitorState& state) {
    lcm::LogFile file(log.string(), "r");
    MessageIngest ingest(state);
    const auto wall_start = std::chrono::steady_clock::now();
    int64_t first_utime = -1;
    uint64_t count = 0;
    state.setReplayProgress(0, false);
    for (const lcm::LogEvent* ev = file.readNextEvent(); ev != nullptr; ev = file.readNextEvent()) {
        if (first_utime < 0) first_utime = ev->timestamp;
        double log_s = static_cast<double>(ev->timestamp - first_utime) * 1e-6;
        if (speed > 0.0) {
            const auto due =
                wall_start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                 std::chrono::duration<double>(std::max(0.0, log_s) / speed));
            std::unique_lock lock(mutex_);
            wake_.wait_until(lock, due, [this] { return stop_; });
            if (stop_) break;
        } else {
            std::lock_guard lock(mutex_);
            if (stop_) break;
        }
        if (ev->datalen < 0) continue;
        ingest.onMessage(ev->channel,
                         std::span<const uint8_t>(static_cast<const uint8_t*>(ev->data),
                                                  static_cast<size_t>(ev->datalen)),
                         log_s);
        ++count;
        if (count % 16 == 0) state.setReplayProgress(count, false);
    }
    ingest.flushStats();
    state.setReplayProgress(count, true);
    finished_ = true;
}

LogReplaySource::~LogReplaySource() { stop(); }

void LogReplaySource::stop() {
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
}

}  // namespace plumb::monitor
