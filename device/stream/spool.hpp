// SPDX-License-Identifier: Apache-2.0
#pragma once

// Device-side spool of encoded fragments that the backend has not acknowledged yet. With a disk
// directory every fragment is on disk (written, fsynced, renamed, directory fsynced:
// messages/files.hpp) before put() returns, whatever the memory budget, so a crash, SIGKILL or
// power loss loses nothing the spool took; memory then only caches fragments for resending.
// Without a directory fragments live in memory up to the budget. Disk entries survive a device
// restart and are found again by open(); quarantined ones (disk_dir/quarantine/) are not.
// Entries are keyed by (session, fragment id) and named on disk as the fragment store names them
// (messages/fragment_files.hpp).
// Not thread-safe.

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/core/status.hpp"
#include "messages/fragment_files.hpp"
#include "messages/wire.hpp"

namespace plumb::device {

struct SpoolConfig {
    /// Bytes of fragments held in memory: without disk_dir the spool's capacity, with it a
    /// cache of fragments that are on disk anyway.
    int64_t memory_budget_bytes = int64_t{64} << 20;
    /// Directory every fragment is written to before put() returns; empty = memory only.
    std::filesystem::path disk_dir;
    /// Bytes allowed on disk; put() fails with IoError beyond it (the caller must stop cutting
    /// fragments or make room), never silently dropping one.
    int64_t disk_budget_bytes = int64_t{4} << 30;
};

class Spool {
  public:
    /// Creates `disk_dir` if needed, removes temporary files of interrupted writes and indexes the
    /// fragments already spooled there.
    static Result<std::unique_ptr<Spool>> open(SpoolConfig config);

    /// Adds a fragment: with disk_dir durably on disk (and cached in memory if it fits), else in
    /// memory. InvalidArgument for an empty fragment or a key already present with other bytes
    /// (same bytes: no-op); IoError when full or on disk errors such as a full disk (nothing is
    /// lost: the fragment simply is not in the spool, the message says why).
    Status put(const messages::FragmentKey& key, std::vector<uint8_t> bytes);
    /// NotFound when absent; IoError/Corrupt when the disk copy cannot be read back intact.
    Result<std::vector<uint8_t>> get(const messages::FragmentKey& key) const;
    /// Removes an acknowledged fragment (absent: no-op).
    Status erase(const messages::FragmentKey& key);
    /// Takes a fragment the backend refused for good out of the spool: with disk_dir its file
    /// moves to disk_dir/quarantine/ beside "<name>.reason" holding `reason`; without, it is
    /// dropped. Absent: no-op. IoError when the move fails (the fragment stays in the spool).
    Status quarantine(const messages::FragmentKey& key, const std::string& reason);
    /// Where quarantine() puts fragments (empty without disk_dir).
    std::filesystem::path quarantineDir() const;

    bool contains(const messages::FragmentKey& key) const { return entries_.count(key) > 0; }
    /// Keys in ascending order (oldest session and fragment first).
    std::vector<messages::FragmentKey> keys() const;
    size_t size() const { return entries_.size(); }
    int64_t memoryBytes() const { return memory_bytes_; }
    int64_t diskBytes() const { return disk_bytes_; }

  private:
    struct Entry {
        std::vector<uint8_t> bytes;  ///< in memory (empty: on disk only)
        bool on_disk = false;        ///< a file in disk_dir holds it
        int64_t size = 0;
        uint32_t crc = 0;
    };
    explicit Spool(SpoolConfig config) : config_(std::move(config)) {}
    std::filesystem::path pathOf(const messages::FragmentKey& key) const;

    SpoolConfig config_;
    std::map<messages::FragmentKey, Entry> entries_;
    int64_t memory_bytes_ = 0;
    int64_t disk_bytes_ = 0;
};

}  // namespace plumb::device
