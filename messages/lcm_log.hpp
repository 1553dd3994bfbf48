// SPDX-License-Identifier: Apache-2.0
#pragma once

// A strict reader of LCM log files (lcm-logger; LCM 1.3.1 eventlog.c). Every event is
//   u32 sync 0xEDA1DA01 | i64 event number | i64 timestamp (us) | i32 channel length |
//   i32 data length | channel | data                                    (big-endian integers)
// and lcm-logger numbers events 0, 1, 2, ... LCM's own reader skips anything that is not a sync
// word without a word and stops at the first event whose lengths run past the end, so a damaged
// header silently ends the log. This reader instead accepts an event only when its lengths are
// plausible, its channel is printable and it is followed by the end of the file or the next sync
// word; anything else is counted (damaged headers, skipped bytes, gaps in the event numbers, a
// cut final event) and reading resumes at the next sync word. verdict() turns the counts into
// Ok or a Corrupt status that says what was lost.
//
// The file is mapped read-only; it must not shrink while being read. Not thread-safe.

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "common/core/status.hpp"

namespace plumb::messages {

/// One intact event; `data` points into the mapped file and is valid until the next call to
/// next() or the reader's destruction.
struct LcmLogEvent {
    int64_t eventnum = 0;
    int64_t timestamp_us = 0;
    std::string channel;
    std::span<const uint8_t> data;
};

struct LcmLogStats {
    uint64_t file_bytes = 0;
    uint64_t events = 0;          ///< intact events returned by next()
    uint64_t damaged_events = 0;  ///< sync words whose event could not be read intact
    uint64_t events_lost = 0;     ///< events missing: damaged ones and gaps in the numbering
    uint64_t skipped_bytes = 0;   ///< bytes outside intact events (garbage, damaged events)
    bool truncated = false;       ///< the file ends inside an event
};

class LcmLogReader {
  public:
    /// NotFound when `path` does not exist or is not a regular file, IoError when it cannot be
    /// read or mapped.
    static Result<std::unique_ptr<LcmLogReader>> open(const std::filesystem::path& path);
    ~LcmLogReader();
    LcmLogReader(const LcmLogReader&) = delete;
    LcmLogReader& operator=(const LcmLogReader&) = delete;

    /// The next intact event; nullopt at the end of the file.
    std::optional<LcmLogEvent> next();
    /// Counts so far (final once next() returned nullopt).
    const LcmLogStats& stats() const { return stats_; }
    /// After the last event: Ok for an intact log with at least one event; Corrupt naming the
    /// file for an empty file, a file without any LCM event, or one that lost events or bytes.
    Status verdict() const;

  private:
    explicit LcmLogReader(std::filesystem::path path) : path_(std::move(path)) {}
    /// Position of the next sync word at or after `from` (size_ when none).
    size_t findSync(size_t from) const;
    /// The event at pos_ (a sync word) when it is intact; advances pos_ past it.
    std::optional<LcmLogEvent> readEventAtSync();
    void noteIntact(int64_t eventnum);

    std::filesystem::path path_;
    const uint8_t* bytes_ = nullptr;
    size_t size_ = 0;
    size_t pos_ = 0;
    LcmLogStats stats_;
    std::optional<int64_t> last_eventnum_;
    uint64_t damaged_since_intact_ = 0;
};

}  // namespace plumb::messages
