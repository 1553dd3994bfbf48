// SPDX-License-Identifier: Apache-2.0
#pragma once

// Logging for programs and drivers (algorithms return results and do not log). Messages go to
// stderr with a level and time; programs call setupLogging once from main.
//
//   plumb::log::info("loaded {} frames from {}", n, dir);

#include <spdlog/spdlog.h>

#include <string>

namespace plumb::log {

using spdlog::debug;
using spdlog::error;
using spdlog::info;
using spdlog::trace;
using spdlog::warn;

enum class Level { kTrace, kDebug, kInfo, kWarn, kError, kOff };

/// Installs the stderr logger. `program` prefixes every line; colour only on a terminal.
void setupLogging(const std::string& program, Level level = Level::kInfo);

/// Parses "trace|debug|info|warn|error|off"; false (level unchanged) for anything else.
bool parseLevel(const std::string& text, Level* level);

}  // namespace plumb::log
