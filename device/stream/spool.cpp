// SPDX-License-Identifier: Apache-2.0
#include "device/stream/spool.hpp"

#include <fmt/format.h>

#include <cstdio>
#include <system_error>

#include "messages/crc32.hpp"
#include "messages/files.hpp"

namespace plumb::device {

using messages::crc32;
using messages::fragmentFileName;
using messages::FragmentKey;
using messages::kTempSuffix;
using messages::moveFile;
using messages::parseFragmentFileName;
using messages::readFile;
using messages::removeFile;
using messages::writeFileAtomic;

Result<std::unique_ptr<Spool>> Spool::open(SpoolConfig config) {
    if (config.memory_budget_bytes < 0 || config.disk_budget_bytes < 0) {
        return invalidArgument("spool: negative budget");
    }
    std::unique_ptr<Spool> spool(new Spool(std::move(config)));
    const std::filesystem::path& dir = spool->config_.disk_dir;
    if (dir.empty()) return spool;
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return ioError(fmt::format("spool: cannot create {}: {}", dir.string(), ec.message()));
    for (const auto& item : std::filesystem::directory_iterator(dir, ec)) {
        const std::string name = item.path().filename().string();
        if (name.ends_with(kTempSuffix)) {
            PLUMB_RETURN_IF_ERROR(removeFile(item.path()));  // an interrupted write
            continue;
        }
        FragmentKey key;
        if (!parseFragmentFileName(name, key.session_id, key.fragment_id)) continue;
        auto bytes = readFile(item.path(), int64_t{1} << 32);
        if (!bytes.isOk()) return bytes.status();
        Entry e;
        e.on_disk = true;
        e.size = static_cast<int64_t>(bytes->size());
        e.crc = crc32(*bytes);
        spool->disk_bytes_ += e.size;
        spool->entries_.emplace(key, std::move(e));
    }
    if (ec) return ioError(fmt::format("spool: cannot list {}: {}", dir.string(), ec.message()));
    return spool;
}

std::filesystem::path Spool::pathOf(const FragmentKey& key) const {
    return config_.disk_dir / fragmentFileName(key.session_id, key.fragment_id);
}

Status Spool::put(const FragmentKey& key, std::vector<uint8_t> bytes) {
    if (bytes.empty()) return invalidArgument("spool: empty fragment");
    const uint32_t crc = crc32(bytes);
    const auto size = static_cast<int64_t>(bytes.size());
    if (auto it = entries_.find(key); it != entries_.end()) {
        if (it->second.crc == crc && it->second.size == size) return Status::ok();
        return invalidArgument(
            fmt::format("spool: fragment {} of session {} already held with "
                        "other content",
                        key.fragment_id, key.session_id));
    }
    Entry e;
    e.size = size;
    e.crc = crc;
    const bool fits_memory = memory_bytes_ + size <= config_.memory_budget_bytes;
    if (config_.disk_dir.empty()) {
        if (!fits_memory) {
            return ioError(fmt::format(
                "spool full: fragment {} ({} bytes) does not fit the memory budget ({} of {} "
                "bytes used; no spool directory)",
                key.fragment_id, size, memory_bytes_, config_.memory_budget_bytes));
        }
    } else {
        if (disk_bytes_ + size > config_.disk_budget_bytes) {
            return ioError(fmt::format(
                "spool full: fragment {} ({} bytes) does not fit the disk budget of {} ({} of {} "
                "bytes used)",
                key.fragment_id, size, config_.disk_dir.string(), disk_bytes_,
                config_.disk_budget_bytes));
        }
        // Durable before it counts: written, fsynced, renamed, directory fsynced.
        Status written = writeFileAtomic(pathOf(key), bytes);
        if (!written.isOk()) return ioError("spool: " + written.message());
        e.on_disk = true;
        disk_bytes_ += size;
    }
    if (fits_memory) {  // the only copy without a directory, else a cache for resending
        e.bytes = std::move(bytes);
        memory_bytes_ += size;
    }
    entries_.emplace(key, std::move(e));
    return Status::ok();
}

Result<std::vector<uint8_t>> Spool::get(const FragmentKey& key) const {
    auto it = entries_.find(key);
    if (it == entries_.end()) {
        return notFound(
            fmt::format("spool: no fragment {} of session {}", key.fragment_id, key.session_id));
    }
    if (!it->second.bytes.empty()) return it->second.bytes;
    auto bytes = readFile(pathOf(key), it->second.size);
    if (!bytes.isOk()) return bytes.status();
    if (static_cast<int64_t>(bytes->size()) != it->second.size || crc32(*bytes) != it->second.crc) {
        return corrupt(fmt::format("spool: {} changed on disk", pathOf(key).string()));
    }
    return bytes;
}

Status Spool::erase(const FragmentKey& key) {
    auto it = entries_.find(key);
    if (it == entries_.end()) return Status::ok();
    if (it->second.on_disk) {
        PLUMB_RETURN_IF_ERROR(removeFile(pathOf(key)));
        disk_bytes_ -= it->second.size;
    }
    if (!it->second.bytes.empty()) memory_bytes_ -= it->second.size;
    entries_.erase(it);
    return Status::ok();
}

std::filesystem::path Spool::quarantineDir() const {
    return config_.disk_dir.empty() ? std::filesystem::path() : config_.disk_dir / "quarantine";
}

Status Spool::quarantine(const FragmentKey& key, const std::string& reason) {
    auto it = entries_.find(key);
    if (it == entries_.end()) return Status::ok();
    if (it->second.on_disk) {
        const std::filesystem::path dir = quarantineDir();
        std::error_code ec;
        std::filesystem::create_directories(dir, ec);
        if (ec) {
            return ioError(fmt::format("spool: cannot create {}: {}", dir.string(), ec.message()));
        }
        const std::string name = fragmentFileName(key.session_id, key.fragment_id);
        const std::string text = reason + "\n";
        PLUMB_RETURN_IF_ERROR(
            writeFileAtomic(dir / (name + ".reason"),
                            std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size())));
        PLUMB_RETURN_IF_ERROR(moveFile(pathOf(key), dir / name));
        disk_bytes_ -= it->second.size;
    }
    if (!it->second.bytes.empty()) memory_bytes_ -= it->second.size;
    entries_.erase(it);
    return Status::ok();
}

std::vector<FragmentKey> Spool::keys() const {
    std::vector<FragmentKey> out;
    out.reserve(entries_.size());
    for (const auto& [k, e] : entries_) out.push_back(k);
    return out;
}

}  // namespace plumb::device
