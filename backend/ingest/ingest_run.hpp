// SPDX-License-Identifier: Apache-2.0
#pragma once

// The two ways the backend ingests fragments, shared by plumb-backend and `plumb replay`:
//  - live: subscribe on an LcmLink, reassemble, persist, acknowledge, until the scan is complete
//    (`until_end`: the end-of-scan heartbeat of every session being finished and all their
//    fragments stored), `expect` fragments are in the store, a timeout, or a stop request; at the
//    end every session is listed with what was stored, and those not finished are warned about;
//  - log: read an LCM log (lcm-logger) and feed every event through the same code at full speed,
//    time taken from the log, so the resulting store depends on the log alone.
// Both write metrics.json (atomically) into the output directory.
//
// Thread-safety: each run uses the calling thread only (the live run dispatches LCM on it);
// runs on different links and output directories may proceed concurrently.

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <set>
#include <string>

#include "backend/ingest/ingestor.hpp"
#include "messages/auth.hpp"
#include "messages/lcm_link.hpp"

namespace plumb::backend {

struct IngestRunOptions {
    /// Fragment store directory.
    std::filesystem::path fragments_dir;
    /// Output directory: metrics.json, camera_info.json, device_config.toml.
    std::filesystem::path out_dir;
    IngestConfig ingest;
    /// Live: stop once the scans being finished are complete (Ingestor::scanComplete with
    /// `sessions`): every session named there, else every device heard from, announced its end
    /// and has all its fragments stored.
    bool until_end = false;
    /// Live: the device sessions to finish (empty: every session that sends heartbeats).
    std::set<int64_t> sessions;
    /// Live: a device whose heartbeats stopped this long ago is not waited for, seconds.
    double session_silence_s = 10.0;
    /// Live: stop once the store holds at least this many fragments (0 = off).
    int64_t expect = 0;
    /// Live: give up after this many seconds (0 = never); the exit is then an error.
    double timeout_s = 0.0;
    /// Live: keep answering for this long after the stop condition (lost final acks), seconds.
    double linger_s = 1.0;
};

struct IngestRunResult {
    nlohmann::json metrics;
    bool complete = false;   ///< the stop condition was met (live), or the log ended (log)
    bool timed_out = false;  ///< live: timeout_s passed first
    size_t fragments_in_store = 0;
    /// Log ingest: Ok, or Corrupt saying what the log lost (an empty file, no LCM event, damaged
    /// or cut events, garbage) or that it held no complete fragment. What was intact is ingested
    /// all the same; metrics.json counts it under "log".
    Status log_damage;
};

/// Live ingest on `link` until a stop condition or `stop_requests` > 0.
Result<IngestRunResult> runLiveIngest(messages::LcmLink& link, const IngestRunOptions& options,
                                      const std::atomic<int>& stop_requests);

/// Ingests an LCM log file (messages/lcm_log.hpp reads it strictly). With a key in `auth`,
/// envelopes are verified like live traffic. NotFound/IoError for an unreadable log; a damaged
/// one is ingested as far as it is intact and reported in IngestRunResult::log_damage.
Result<IngestRunResult> runLogIngest(const std::filesystem::path& log_path,
                                     const IngestRunOptions& options,
                                     const messages::AuthConfig& auth);

}  // namespace plumb::backend
