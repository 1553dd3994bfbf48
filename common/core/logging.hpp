// SPDX-License-Identifier: Apache-2.0
#pragma once

// Logging for programs and drivers (algorithms return results and do not log). Messages go to
// stderr with a level and time; programs call setupLogging from main (again with their own
// name when a sub-command runs: the level chosen first is kept).
//
//   plumb::log::info("loaded {} frames from {}", n, dir);

#include <spdlog/spdlog.h>

#include <optional>
#include <string>

namespace plumb::log {

using spdlog::debug;
using spdlog::error;
using spdlog::info;
using spdlog::trace;
using spdlog::warn;

enum class Level { kTrace, kDebug, kInfo, kWarn, kError, kOff };

/// Installs the stderr logger. `program` prefixes every line; colour only on a terminal. The
/// level is `level` when given and otherwise the process's current one (currentLevel()), so a
/// program can choose it once (`plumb --log-level error fuse ...`) and the parts it runs that
/// install their own logger keep it. Calling it again with the same `program` replaces the logger.
/// Not thread-safe: call it before other threads log.
void setupLogging(const std::string& program, std::optional<Level> level = std::nullopt);

/// The level of the process: the last one given to setupLogging, kInfo before any.
Level currentLevel();

/// Parses "trace|debug|info|warn|error|off"; false (level unchanged) for anything else.
bool parseLevel(const std::string& text, Level* level);

/// The name parseLevel reads back ("info" for Level::kInfo).
const char* levelName(Level level);

}  // namespace plumb::log
