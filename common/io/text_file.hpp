// SPDX-License-Identifier: Apache-2.0
#pragma once

// Writing whole text files (JSON, TOML, TUM, HTML outputs). Thread-safe for different paths.

#include <filesystem>
#include <string>

#include "common/core/status.hpp"

namespace plumb::io {

/// Writes `text` to `path` (created or truncated), byte for byte. IoError names the path: cannot
/// open (with the OS reason) or write failed (disk full).
Status writeText(const std::filesystem::path& path, const std::string& text);

/// Writes `text` to `<path>.tmp` and renames it over `path`, so a reader never sees a partly
/// written file. Not crash-safe (no fsync; see messages/files.hpp for that). IoError names the
/// file that failed.
Status writeTextReplacing(const std::filesystem::path& path, const std::string& text);

}  // namespace plumb::io
