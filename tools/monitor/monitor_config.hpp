// SPDX-License-Identifier: Apache-2.0
#pragma once

// The configuration of `plumb monitor` (schema "monitor"; see `plumb config doc monitor`).

#include <string>

#include "common/config/schema.hpp"
#include "messages/channels.hpp"
#include "tools/monitor/monitor_state.hpp"
#include "tools/monitor/server.hpp"
#include "tools/monitor/sources.hpp"

namespace plumb::monitor {

struct MonitorConfig {
    /// The HTTP server.
    ServerConfig server;
    /// What is kept and shown.
    MonitorStateConfig state;
    /// Watching an output directory.
    DirectoryWatcherConfig directory;
    /// LCM URL for --live (ttl=0 keeps traffic on this machine).
    std::string lcm_url = messages::kDefaultLcmUrl;
    /// Replay speed for --log: 1 = real time, 0 = as fast as possible.
    double replay_speed = 1.0;
};
void describe(config::Schema& s, MonitorConfig& c);

}  // namespace plumb::monitor
