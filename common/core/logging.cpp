// SPDX-License-Identifier: Apache-2.0
#include "common/core/logging.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>

namespace plumb::log {
namespace {

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

void setupLogging(const std::string& program, Level level) {
    auto logger = spdlog::stderr_color_mt(program);
    logger->set_pattern("%H:%M:%S.%e %n %^%l%$: %v");
    logger->set_level(toSpd(level));
    spdlog::set_default_logger(logger);
}

bool parseLevel(const std::string& text, Level* level) {
    static const std::pair<const char*, Level> kNames[] = {
        {"trace", Level::kTrace}, {"debug", Level::kDebug}, {"info", Level::kInfo},
        {"warn", Level::kWarn},   {"error", Level::kError}, {"off", Level::kOff}};
    for (const auto& [name, value] : kNames) {
        if (text == name) {
            *level = value;
            return true;
        }
    }
    return false;
}

}  // namespace plumb::log
