// SPDX-License-Identifier: Apache-2.0
#pragma once

// Backend-side fragment store: one file per received fragment (the encoded bytes, exactly as
// sent), written atomically (temp file, fsync, rename, fsync of the directory) before the
// fragment is acknowledged. open() resumes from what is on disk: it removes temporary files of
// interrupted writes, checks every file's CRC-32 trailer (messages/fragment_codec.hpp) and moves
// damaged files aside (".corrupt"). Storing a fragment that is already present is ignored.
// openReadOnly() indexes a store another process may be writing and changes nothing.
// Not thread-safe.

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/core/status.hpp"
#include "messages/fragment_files.hpp"

namespace plumb::messages {

struct StoredFragment {
    int64_t session_id = 0;
    uint32_t fragment_id = 0;
    uint32_t crc32 = 0;  ///< CRC-32 of the whole file (the transport's fragment checksum)
    int64_t size_bytes = 0;
    std::filesystem::path path;
};

class FragmentStore {
  public:
    /// Opens (creating if needed) the store in `dir` and indexes it.
    static Result<std::unique_ptr<FragmentStore>> open(const std::filesystem::path& dir);
    /// Indexes the existing store in `dir` without changing it, for readers beside a backend
    /// that may be writing it: temporary files are skipped rather than removed, damaged files
    /// left where they are (listed in quarantined()), and put() is refused. NotFound when `dir`
    /// is not a directory.
    static Result<std::unique_ptr<FragmentStore>> openReadOnly(const std::filesystem::path& dir);

    /// Persists a fragment. Returns true when written, false when the identical fragment was
    /// already stored (duplicate ignored). FailedPrecondition when the key holds other bytes,
    /// Corrupt when `bytes` fails its own CRC trailer, IoError on disk errors (nothing stored).
    Result<bool> put(int64_t session_id, uint32_t fragment_id, std::span<const uint8_t> bytes);

    /// The stored bytes, re-verified against the index CRC.
    Result<std::vector<uint8_t>> get(int64_t session_id, uint32_t fragment_id) const;

    bool contains(int64_t session_id, uint32_t fragment_id) const;
    /// Every stored fragment, ordered by (session, fragment id).
    std::vector<StoredFragment> fragments() const;
    /// Files that failed verification when the store was opened: renamed to "<name>.corrupt"
    /// by open(), left in place by openReadOnly().
    const std::vector<std::filesystem::path>& quarantined() const { return quarantined_; }
    const std::filesystem::path& dir() const { return dir_; }

  private:
    FragmentStore(std::filesystem::path dir, bool read_only)
        : dir_(std::move(dir)), read_only_(read_only) {}
    /// Indexes dir_'s fragment files (open's and openReadOnly's shared walk).
    Status indexFiles();

    std::filesystem::path dir_;
    bool read_only_ = false;
    std::map<FragmentKey, StoredFragment> index_;
    std::vector<std::filesystem::path> quarantined_;
};

/// True when `bytes` ends with the CRC-32 of everything before it (the fragment codec trailer).
bool hasValidCrcTrailer(std::span<const uint8_t> bytes);

}  // namespace plumb::messages
