// SPDX-License-Identifier: Apache-2.0
#include "common/core/progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <utility>

#include "common/core/logging.hpp"

namespace plumb {
namespace {

double steadySeconds() {
    using Clock = std::chrono::steady_clock;
    return std::chrono::duration<double>(Clock::now().time_since_epoch()).count();
}

std::string format(const char* fmt, double v) {
    char buf[64];
    std::snprintf(buf, sizeof(buf), fmt, v);
    return buf;
}

// The total time at the end: tenths of seconds below a minute, else like an ETA.
std::string formatElapsed(double seconds) {
    if (seconds < 59.95) return format("%.1fs", std::max(0.0, seconds));
    return formatDuration(seconds);
}

}  // namespace

std::string formatRate(double items_per_s) {
    if (!std::isfinite(items_per_s) || items_per_s < 0.0) return "-";
    if (items_per_s < 9.995) return format("%.2f", items_per_s);
    if (items_per_s < 99.95) return format("%.1f", items_per_s);
    return format("%.0f", items_per_s);
}

std::string formatDuration(double seconds) {
    if (!std::isfinite(seconds) || seconds < 0.0) return "?";
    const auto s = static_cast<int64_t>(std::ceil(seconds));
    char buf[64];
    if (s < 60) {
        std::snprintf(buf, sizeof(buf), "%llds", static_cast<long long>(s));
    } else if (s < 3600) {
        std::snprintf(buf, sizeof(buf), "%lldm%02llds", static_cast<long long>(s / 60),
                      static_cast<long long>(s % 60));
    } else {
        const int64_t minutes = (s + 59) / 60;  // rounded up like the seconds
        std::snprintf(buf, sizeof(buf), "%lldh%02lldm", static_cast<long long>(minutes / 60),
                      static_cast<long long>(minutes % 60));
    }
    return buf;
}

Progress::Progress(std::string label, uint64_t total, ProgressOptions options)
    : label_(std::move(label)), total_(total), options_(std::move(options)) {
    quiet_ =
        options_.mode == ProgressOptions::Mode::kQuiet ||
        (options_.mode == ProgressOptions::Mode::kAuto && log::currentLevel() > log::Level::kInfo);
    live_ = options_.mode == ProgressOptions::Mode::kLive ||
            (options_.mode == ProgressOptions::Mode::kAuto && options_.stream == nullptr &&
             ::isatty(options_.fd) == 1);
    start_s_ = now();
    next_report_s_.store(live_ ? start_s_ : start_s_ + options_.plain_interval_s);
}

Progress::~Progress() { finish(); }

double Progress::now() const { return options_.clock ? options_.clock() : steadySeconds(); }

void Progress::advance(uint64_t n) {
    count_.fetch_add(n, std::memory_order_relaxed);
    if (quiet_) return;
    const double t = now();
    if (t < next_report_s_.load(std::memory_order_relaxed)) return;
    // One thread draws; the others carry on counting.
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock() || finished_) return;
    if (t < next_report_s_.load(std::memory_order_relaxed)) return;
    next_report_s_.store(t + (live_ ? options_.live_interval_s : options_.plain_interval_s),
                         std::memory_order_relaxed);
    render(false);
}

void Progress::finish() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (finished_) return;
    finished_ = true;
    if (!quiet_) render(true);
}

std::string Progress::liveLine(uint64_t done, double elapsed_s) const {
    const double rate = elapsed_s > 0.0 ? static_cast<double>(done) / elapsed_s : -1.0;
    const std::string unit = unitSuffix();
    std::string line = label_;
    if (total_ > 0) {
        const double fraction =
            std::min(1.0, static_cast<double>(done) / static_cast<double>(total_));
        const int width = std::max(1, options_.bar_width);
        const int filled = static_cast<int>(std::floor(fraction * width));
        line += " [";
        line.append(static_cast<size_t>(filled), '#');
        line.append(static_cast<size_t>(width - filled), '.');
        line += "] ";
        line += std::to_string(done);
        line += '/';
        line += std::to_string(total_);
        line += ' ';
        line += format("%3.0f", std::floor(fraction * 100.0));
        line += "% ";
        line += formatRate(rate);
        line += unit;
        line += " ETA ";
        line += eta(done, rate);
    } else {
        line += ' ';
        line += std::to_string(done);
        line += ' ';
        line += formatRate(rate);
        line += unit;
    }
    return line;
}

std::string Progress::plainLine(uint64_t done, double elapsed_s, bool final) const {
    const double rate = elapsed_s > 0.0 ? static_cast<double>(done) / elapsed_s : -1.0;
    const std::string unit = unitSuffix();
    std::string line = label_;
    line += ": ";
    line += std::to_string(done);
    if (total_ > 0) {
        const double fraction =
            std::min(1.0, static_cast<double>(done) / static_cast<double>(total_));
        line += '/';
        line += std::to_string(total_);
        line += " (";
        line += format("%.0f", std::floor(fraction * 100.0));
        line += "%)";
    }
    line += ' ';
    line += formatRate(rate);
    line += unit;
    if (final) {
        line += ", done in ";
        line += formatElapsed(elapsed_s);
    } else if (total_ > 0) {
        line += " ETA ";
        line += eta(done, rate);
    }
    return line;
}

std::string Progress::unitSuffix() const {
    std::string suffix;
    if (!options_.unit.empty()) {
        suffix += ' ';
        suffix += options_.unit;
    }
    suffix += "/s";
    return suffix;
}

std::string Progress::eta(uint64_t done, double rate) const {
    const uint64_t remaining = total_ - std::min(done, total_);
    if (remaining == 0) return "0s";
    if (!(rate > 0.0)) return "?";
    return formatDuration(static_cast<double>(remaining) / rate);
}

void Progress::render(bool final) {
    const uint64_t done = count_.load(std::memory_order_relaxed);
    const double elapsed = now() - start_s_;
    if (!live_) {
        std::string line = plainLine(done, elapsed, final);
        line += '\n';
        write(line);
        return;
    }
    std::string line = liveLine(done, elapsed);
    if (final) {
        // Replace the ETA (or nothing, for an unknown total) with the total duration.
        const size_t eta = line.rfind(" ETA ");
        if (eta != std::string::npos) line.resize(eta);
        line += " done in ";
        line += formatElapsed(elapsed);
    }
    const size_t width = line.size();
    if (width < last_width_) line += std::string(last_width_ - width, ' ');
    last_width_ = width;
    line.insert(line.begin(), '\r');
    if (final) line += '\n';
    write(line);
}

void Progress::write(const std::string& text) {
    if (options_.stream != nullptr) {
        *options_.stream << text << std::flush;
        return;
    }
    const char* p = text.data();
    size_t left = text.size();
    while (left > 0) {
        const ssize_t n = ::write(options_.fd, p, left);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return;  // progress output is best effort
        p += n;
        left -= static_cast<size_t>(n);
    }
}

}  // namespace plumb
