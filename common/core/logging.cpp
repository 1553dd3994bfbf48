// SPDX-License-Identifier: Apache-2.0
#include "common/core/logging.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>

#include <utility>

namespace plumb::log {
namespace {

Level g_level = Level::kInfo;  // the process's level (setupLogging)

constexpr std::pair<const char*, Level> kLevelNames[] = {
    {"trace", Level::kTrace}, {"debug", Level::kDebug}, {"info", Level::kInfo},
    {"warn", Level::kWarn},   {"error", Level::kError}, {"off", Level::kOff}};

spdlog::level::level_enum toSpd(Level level) {
    switch (level) {
        case Level::kTrace:
            return spdlog::level::trace;
        case Level::kDebug:
            return spdlog::level::debug;
        case Level::kInfo:
            return spdlog::level::info;
        case Level::kWarn:
            return spdlog::level::warn;
        case Level::kError:
            return spdlog::level::err;
        case Level::kOff:
            return spdlog::level::off;
    }
    return spdlog::level::info;
}

}  // namespace

void setupLogging(const std::string& program, std::optional<Level> level) {
    if (level) g_level = *level;
    spdlog::drop(program);
    auto logger = spdlog::stderr_color_mt(program);
    logger->set_pattern("%H:%M:%S.%e %n %^%l%$: %v");
    logger->set_level(toSpd(g_level));
    spdlog::set_default_logger(logger);
}

Level currentLevel() { return g_level; }

bool parseLevel(const std::string& text, Level* level) {
    for (const auto& [name, value] : kLevelNames) {
        if (text == name) {
            *level = value;
            return true;
        }
    }
    return false;
}

const char* levelName(Level level) {
    for (const auto& [name, value] : kLevelNames) {
        if (value == level) return name;
    }
    return "info";
}

}  // namespace plumb::log
