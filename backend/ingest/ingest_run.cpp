// SPDX-License-Identifier: Apache-2.0
#include "backend/ingest/ingest_run.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <vector>

#include "common/core/logging.hpp"
#include "common/core/timing.hpp"
#include "messages/files.hpp"
#include "messages/lcm_log.hpp"

namespace plumb::backend {
namespace {

Status writeMetrics(const std::filesystem::path& out_dir, const nlohmann::json& metrics) {
    if (out_dir.empty()) return Status::ok();
    const std::string text = metrics.dump(2) + "\n";
    return messages::writeFileAtomic(
        out_dir / "metrics.json",
        std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

Status makeDirs(const IngestRunOptions& options) {
    for (const auto& dir : {options.out_dir, options.fragments_dir}) {
        if (dir.empty()) continue;
        std::error_code ec;
        std::filesystem::create_directories(dir, ec);
        if (ec) return ioError(fmt::format("cannot create {}: {}", dir.string(), ec.message()));
    }
    return Status::ok();
}

// Publishes nowhere (a log cannot answer) and dispatches what the log holds.
class LogFeed final : public messages::Transport {
  public:
    Status publish(const std::string&, std::span<const uint8_t>) override { return Status::ok(); }
    Status subscribe(const std::string& channel, Handler handler) override {
        handlers_[channel].push_back(std::move(handler));
        return Status::ok();
    }
    void feed(const std::string& channel, std::span<const uint8_t> bytes) {
        auto it = handlers_.find(channel);
        if (it == handlers_.end()) return;
        for (auto& h : it->second) h(channel, bytes);
    }

  private:
    std::map<std::string, std::vector<Handler>> handlers_;
};

/// Why a session is not finished, or empty when it is.
std::string unfinishedReason(const SessionReport& r, const IngestRunOptions& options, double now) {
    if (!options.sessions.empty() && options.sessions.count(r.session_id) == 0) {
        return "not waited for: not named by --session";
    }
    if (options.sessions.empty() && !r.heard) {
        return "not waited for: no heartbeat, only fragments (resent from a spool of an earlier "
               "run?)";
    }
    if (r.complete) return {};
    if (!r.fragments_announced) {
        return r.heard ? fmt::format(
                             "incomplete: no end of scan announced (last heartbeat {:.0f} "
                             "s before the end)",
                             now - r.last_heard_s)
                       : "incomplete: nothing received";
    }
    return fmt::format("incomplete: {} of {} fragment(s) stored", r.fragments_stored,
                       *r.fragments_announced);
}

/// One line per session: what was stored, and whether it is finished (a warning if not).
void logSessions(const Ingestor& ingestor, const IngestRunOptions& options, double now) {
    std::vector<SessionReport> sessions = ingestor.sessions();
    for (int64_t wanted : options.sessions) {  // named but never heard of
        if (std::none_of(sessions.begin(), sessions.end(),
                         [&](const SessionReport& r) { return r.session_id == wanted; })) {
            SessionReport never_heard;
            never_heard.session_id = wanted;
            sessions.push_back(never_heard);
        }
    }
    for (const SessionReport& r : sessions) {
        const std::string reason = unfinishedReason(r, options, now);
        const std::string what =
            fmt::format("session {}: {} fragment(s) stored", r.session_id, r.fragments_stored);
        if (reason.empty()) {
            log::info("{}, complete", what);
        } else {
            log::warn("{}; {}", what, reason);
        }
    }
}

}  // namespace

Result<IngestRunResult> runLiveIngest(messages::LcmLink& link, const IngestRunOptions& options,
                                      const std::atomic<int>& stop_requests) {
    PLUMB_RETURN_IF_ERROR(makeDirs(options));
    auto opened =
        Ingestor::open(options.fragments_dir, options.out_dir, options.ingest, link.transport());
    if (!opened.isOk()) return opened.status();
    Ingestor& ingestor = **opened;
    double now = wallClockSeconds();
    for (const std::string& channel : Ingestor::channels()) {
        PLUMB_RETURN_IF_ERROR(link.transport().subscribe(
            channel, [&](const std::string& ch, std::span<const uint8_t> bytes) {
                ingestor.onMessage(ch, bytes, now);
            }));
    }
    if (ingestor.counters().fragments_resumed > 0) {
        log::info("resuming: {} fragment(s) already in {}", ingestor.counters().fragments_resumed,
                  options.fragments_dir.string());
    }
    IngestRunResult result;
    const double start = now;
    double done_at = -1.0, last_metrics = now;
    uint64_t last_received = 0;
    while (true) {
        PLUMB_RETURN_IF_ERROR(link.pump(20));
        now = wallClockSeconds();
        ingestor.poll(now);
        if (ingestor.counters().fragments_received != last_received) {
            last_received = ingestor.counters().fragments_received;
            log::info("fragments: {} in store ({} received now)", ingestor.fragmentsInStore(),
                      last_received);
        }
        if (now - last_metrics > 2.0) {
            const Status s = writeMetrics(options.out_dir, ingestor.metrics(link.authStats()));
            if (!s.isOk()) log::warn("{}", s.toString());
            last_metrics = now;
        }
        if (stop_requests.load() > 0) break;
        const bool done = (options.until_end && ingestor.scanComplete(options.sessions, now,
                                                                      options.session_silence_s)) ||
                          (options.expect > 0 &&
                           static_cast<int64_t>(ingestor.fragmentsInStore()) >= options.expect);
        if (done && done_at < 0) {
            done_at = now;
            result.complete = true;
            log::info("scan complete: {} fragment(s) in store", ingestor.fragmentsInStore());
        }
        if (done_at >= 0 && now - done_at >= options.linger_s) break;
        if (done_at < 0 && options.timeout_s > 0 && now - start >= options.timeout_s) {
            result.timed_out = true;
            break;
        }
    }
    logSessions(ingestor, options, now);
    result.metrics = ingestor.metrics(link.authStats());
    result.fragments_in_store = ingestor.fragmentsInStore();
    PLUMB_RETURN_IF_ERROR(writeMetrics(options.out_dir, result.metrics));
    return result;
}

Result<IngestRunResult> runLogIngest(const std::filesystem::path& log_path,
                                     const IngestRunOptions& options,
                                     const messages::AuthConfig& auth) {
    auto reader = messages::LcmLogReader::open(log_path);
    if (!reader.isOk()) return reader.status();
    PLUMB_RETURN_IF_ERROR(makeDirs(options));
    LogFeed feed;
    messages::AuthenticatedTransport transport(feed, auth);
    auto opened = Ingestor::open(options.fragments_dir, options.out_dir, options.ingest, transport);
    if (!opened.isOk()) return opened.status();
    Ingestor& ingestor = **opened;
    double now = 0.0;
    for (const std::string& channel : Ingestor::channels()) {
        PLUMB_RETURN_IF_ERROR(transport.subscribe(
            channel, [&](const std::string& ch, std::span<const uint8_t> bytes) {
                ingestor.onMessage(ch, bytes, now);
            }));
    }
    while (const std::optional<messages::LcmLogEvent> event = (*reader)->next()) {
        now = static_cast<double>(event->timestamp_us) * 1e-6;
        transport.setTime(event->timestamp_us);
        feed.feed(event->channel, event->data);
        ingestor.poll(now);
    }
    ingestor.poll(now);
    IngestRunResult result;
    result.complete = true;
    result.metrics = ingestor.metrics(transport.stats());
    const messages::LcmLogStats& log_stats = (*reader)->stats();
    result.metrics["log_events"] = log_stats.events;
    result.metrics["log"] = {{"bytes", log_stats.file_bytes},
                             {"events", log_stats.events},
                             {"events_lost", log_stats.events_lost},
                             {"damaged_events", log_stats.damaged_events},
                             {"skipped_bytes", log_stats.skipped_bytes},
                             {"truncated", log_stats.truncated}};
    result.fragments_in_store = ingestor.fragmentsInStore();
    result.log_damage = (*reader)->verdict();
    const IngestCounters& c = ingestor.counters();
    if (result.log_damage.isOk() && c.fragments_received + c.fragments_duplicate == 0) {
        result.log_damage =
            corrupt(fmt::format("LCM log {} holds {} intact event(s) but not one complete fragment",
                                log_path.string(), log_stats.events));
    }
    PLUMB_RETURN_IF_ERROR(writeMetrics(options.out_dir, result.metrics));
    return result;
}

}  // namespace plumb::backend
