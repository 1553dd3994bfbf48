// SPDX-License-Identifier: Apache-2.0
#pragma once

// Progress of a long loop, for programs (algorithms report nothing; their callers do).
//
//   plumb::Progress progress("integrating frames", frames.size());
//   tbb::parallel_for(..., [&](size_t i) { integrate(i); progress.advance(); });
//   progress.finish();
//
// On a terminal (isatty of the output fd) a single live line is redrawn at most every
// `live_interval_s` seconds:
//
//   integrating frames [##########..........] 120/240  50% 23.9/s ETA 5s
//
// Elsewhere (CI logs, files) plain lines are printed every `plain_interval_s` seconds and once at
// the end, so logs stay readable:
//
//   integrating frames: 120/240 (50%) 23.9/s ETA 5s
//   integrating frames: 240/240 (100%) 24.0/s, done in 10.0s
//
// With an unknown total (0) there is no bar, percent or ETA: just the count and the rate.
// Rate = items counted / seconds since construction; ETA = remaining items / rate.

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <ostream>
#include <string>

#include "common/core/progress_callback.hpp"

namespace plumb {

struct ProgressOptions {
    enum class Mode {
        kAuto,   ///< live on a terminal, plain otherwise; nothing when the process logs only
                 ///< warnings or less (log::currentLevel() above info: `--log-level warn`)
        kLive,   ///< always the redrawn single line
        kPlain,  ///< always periodic plain lines
        kQuiet,  ///< no output at all
    };
    /// How to report; kQuiet disables all output.
    Mode mode = Mode::kAuto;
    /// File descriptor written to when `stream` is null (2 = stderr); kAuto checks isatty on it.
    int fd = 2;
    /// When set, output goes to this stream instead of `fd` (kAuto then means plain).
    std::ostream* stream = nullptr;
    /// Minimum time between two redraws of the live line, in seconds.
    double live_interval_s = 0.1;
    /// Time between two plain lines, in seconds.
    double plain_interval_s = 5.0;
    /// Width of the live bar in characters.
    int bar_width = 20;
    /// Unit of the counted items in the rate ("frames" gives "23.9 frames/s"); empty gives
    /// "23.9/s".
    std::string unit;
    /// Monotonic clock in seconds; steady_clock when empty. Called from any thread that advances.
    std::function<double()> clock;
};

/// Counts items from any number of threads and reports on the configured output.
/// Thread-safety: advance() and count() may be called concurrently from any thread; finish() and
/// the destructor from one thread once the workers are done.
class Progress {
  public:
    /// `total` = number of items expected, 0 when unknown.
    Progress(std::string label, uint64_t total, ProgressOptions options = {});
    /// Calls finish() if it was not called.
    ~Progress();
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    /// Adds `n` items (lock-free count; redraws when the interval has elapsed and no other thread
    /// is drawing).
    void advance(uint64_t n = 1);

    /// Prints the final state (live mode ends its line). Further calls do nothing.
    void finish();

    /// Items counted so far.
    uint64_t count() const { return count_.load(std::memory_order_relaxed); }

    /// The live line for `done` items after `elapsed_s` seconds (no carriage return).
    std::string liveLine(uint64_t done, double elapsed_s) const;
    /// The plain line for `done` items after `elapsed_s` seconds (no newline); `final` adds the
    /// total duration.
    std::string plainLine(uint64_t done, double elapsed_s, bool final) const;

  private:
    double now() const;
    std::string unitSuffix() const;
    std::string eta(uint64_t done, double rate) const;
    void render(bool final);
    void write(const std::string& text);

    std::string label_;
    uint64_t total_;
    ProgressOptions options_;
    bool live_ = false;
    bool quiet_ = false;
    double start_s_ = 0.0;
    std::atomic<uint64_t> count_{0};
    /// Clock time after which the next report is due.
    std::atomic<double> next_report_s_{0.0};
    std::mutex mutex_;  ///< serialises drawing
    size_t last_width_ = 0;
    bool finished_ = false;
};

/// "23.9" style rate text: 3 significant digits below 100, whole numbers above.
std::string formatRate(double items_per_s);
/// "42s", "3m07s", "2h05m" (seconds rounded up to whole seconds).
std::string formatDuration(double seconds);

/// The callback that advances `progress` (which must outlive it): what a program hands to an
/// algorithm that reports through a ProgressCallback.
inline ProgressCallback advanceOf(Progress& progress) {
    return [&progress](uint64_t n) { progress.advance(n); };
}

}  // namespace plumb
