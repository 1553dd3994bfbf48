// SPDX-License-Identifier: Apache-2.0
#pragma once

// Crash-safe file helpers for the spool and the fragment store.
//
// Thread-safety: the functions keep no state; concurrent calls on different paths are safe.

#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

#include "common/core/status.hpp"

namespace plumb::messages {

/// Writes `bytes` to `path` atomically: a temporary file beside it (`<path>.tmp`) is written,
/// fsync'ed and renamed over `path`, then the directory is fsync'ed. After a crash `path` holds
/// either the old or the new content, never a mix. IoError names the path and the OS error.
Status writeFileAtomic(const std::filesystem::path& path, std::span<const uint8_t> bytes);

/// Reads a whole file of at most `max_bytes`. NotFound, IoError or OutOfRange (too large).
Result<std::vector<uint8_t>> readFile(const std::filesystem::path& path, int64_t max_bytes);

/// Deletes `path` and fsyncs its directory; a missing file is not an error.
Status removeFile(const std::filesystem::path& path);

/// Renames `from` to `to` (same file system) and fsyncs both directories. IoError names both.
Status moveFile(const std::filesystem::path& from, const std::filesystem::path& to);

/// Suffix of temporary files left by an interrupted writeFileAtomic.
inline constexpr const char* kTempSuffix = ".tmp";

}  // namespace plumb::messages
