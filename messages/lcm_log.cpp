// SPDX-License-Identifier: Apache-2.0
#include "messages/lcm_log.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace plumb::messages {
namespace {

constexpr uint32_t kSync = 0xEDA1DA01u;
constexpr size_t kHeaderBytes = 4 + 8 + 8 + 4 + 4;
/// LCM's own reader refuses longer channel names (lcm-logger writes at most 63 bytes).
constexpr int32_t kMaxChannelBytes = 1000;
/// A jump in the event numbers larger than this is damage, not lost events.
constexpr int64_t kMaxPlausibleGap = int64_t{1} << 32;

uint64_t readBigEndian(const uint8_t* p, int bytes) {
    uint64_t v = 0;
    for (int i = 0; i < bytes; ++i) v = (v << 8) | p[i];
    return v;
}

bool printable(std::span<const uint8_t> text) {
    return std::all_of(text.begin(), text.end(), [](uint8_t c) { return c >= 0x20 && c < 0x7f; });
}

}  // namespace

Result<std::unique_ptr<LcmLogReader>> LcmLogReader::open(const std::filesystem::path& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) {
        return notFound(fmt::format("LCM log {} does not exist or is not a file", path.string()));
    }
    std::unique_ptr<LcmLogReader> r(new LcmLogReader(path));
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        return ioError(
            fmt::format("cannot open LCM log {}: {}", path.string(), std::strerror(errno)));
    }
    struct stat st {};
    if (::fstat(fd, &st) != 0) {
        const int err = errno;
        ::close(fd);
        return ioError(
            fmt::format("cannot stat LCM log {}: {}", path.string(), std::strerror(err)));
    }
    r->size_ = static_cast<size_t>(st.st_size);
    r->stats_.file_bytes = r->size_;
    if (r->size_ > 0) {
        void* map = ::mmap(nullptr, r->size_, PROT_READ, MAP_PRIVATE, fd, 0);
        const int err = errno;
        ::close(fd);
        if (map == MAP_FAILED) {
            return ioError(
                fmt::format("cannot map LCM log {}: {}", path.string(), std::strerror(err)));
        }
        r->bytes_ = static_cast<const uint8_t*>(map);
    } else {
        ::close(fd);
    }
    return r;
}

LcmLogReader::~LcmLogReader() {
    if (bytes_ != nullptr) ::munmap(const_cast<uint8_t*>(bytes_), size_);
}

size_t LcmLogReader::findSync(size_t from) const {
    for (size_t p = from; p + 4 <= size_; ++p) {
        if (readBigEndian(bytes_ + p, 4) == kSync) return p;
    }
    return size_;
}

void LcmLogReader::noteIntact(int64_t eventnum) {
    // Events between two intact ones are lost: as many as the numbering skips, and at least
    // as many as the damaged headers seen in between.
    const int64_t expected = last_eventnum_ ? *last_eventnum_ + 1 : 0;
    const int64_t gap = eventnum - expected;
    const uint64_t numbered = gap > 0 && gap < kMaxPlausibleGap ? static_cast<uint64_t>(gap) : 0;
    stats_.events_lost += std::max(numbered, damaged_since_intact_);
    damaged_since_intact_ = 0;
    last_eventnum_ = eventnum;
    ++stats_.events;
}

std::optional<LcmLogEvent> LcmLogReader::readEventAtSync() {
    const size_t start = pos_;
    if (size_ - start < kHeaderBytes) {  // cut inside the header
        stats_.truncated = true;
        return std::nullopt;
    }
    const uint8_t* h = bytes_ + start;
    const auto channel_bytes = static_cast<int32_t>(readBigEndian(h + 20, 4));
    const auto data_bytes = static_cast<int32_t>(readBigEndian(h + 24, 4));
    if (channel_bytes <= 0 || channel_bytes > kMaxChannelBytes || data_bytes < 0) {
        return std::nullopt;
    }
    const size_t end =
        start + kHeaderBytes + static_cast<size_t>(channel_bytes) + static_cast<size_t>(data_bytes);
    if (end > size_) {
        stats_.truncated = findSync(start + 4) == size_;  // nothing after: the log was cut
        return std::nullopt;
    }
    const std::span<const uint8_t> channel(h + kHeaderBytes, static_cast<size_t>(channel_bytes));
    if (!printable(channel)) return std::nullopt;
    // The next event must start right after this one. If not, a sync word inside the event
    // means its lengths are wrong; without one, the event stands and garbage follows it.
    if (end != size_ && (end + 4 > size_ || readBigEndian(bytes_ + end, 4) != kSync) &&
        findSync(start + 4) < end) {
        return std::nullopt;
    }
    LcmLogEvent e;
    e.eventnum = static_cast<int64_t>(readBigEndian(h + 4, 8));
    e.timestamp_us = static_cast<int64_t>(readBigEndian(h + 12, 8));
    e.channel.assign(channel.begin(), channel.end());
    e.data = {h + kHeaderBytes + channel.size(), static_cast<size_t>(data_bytes)};
    pos_ = end;
    return e;
}

std::optional<LcmLogEvent> LcmLogReader::next() {
    while (pos_ < size_) {
        const size_t sync = findSync(pos_);
        stats_.skipped_bytes += sync - pos_;
        pos_ = sync;
        if (pos_ >= size_) break;
        if (auto e = readEventAtSync()) {
            noteIntact(e->eventnum);
            return e;
        }
        // A damaged event: resume at the next sync word after its own.
        ++stats_.damaged_events;
        ++damaged_since_intact_;
        const size_t resume = findSync(pos_ + 4);
        stats_.skipped_bytes += resume - pos_;
        pos_ = resume;
    }
    stats_.events_lost += damaged_since_intact_;
    damaged_since_intact_ = 0;
    return std::nullopt;
}

Status LcmLogReader::verdict() const {
    const std::string name = path_.string();
    if (stats_.file_bytes == 0) return corrupt(fmt::format("LCM log {} is empty", name));
    if (stats_.events == 0) {
        return corrupt(fmt::format(
            "{} is not an LCM log: no intact event in {} bytes ({} damaged event header(s))", name,
            stats_.file_bytes, stats_.damaged_events));
    }
    if (stats_.events_lost == 0 && stats_.skipped_bytes == 0 && !stats_.truncated) {
        return Status::ok();
    }
    return corrupt(fmt::format(
        "LCM log {} is damaged: {} event(s) read intact, {} lost ({} damaged event header(s)), "
        "{} of {} bytes skipped{}",
        name, stats_.events, stats_.events_lost, stats_.damaged_events, stats_.skipped_bytes,
        stats_.file_bytes, stats_.truncated ? "; the file ends inside an event (truncated)" : ""));
}

}  // namespace plumb::messages
