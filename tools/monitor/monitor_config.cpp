// SPDX-License-Identifier: Apache-2.0
#include "tools/monitor/monitor_config.hpp"

namespace plumb::monitor {

void describe(config::Schema& s, MonitorConfig& c) {
    s.section("server", c.server, "the HTTP server");
    s.section("state", c.state, "what is kept and shown");
    s.section("directory", c.directory, "watching an output directory");
    s.field("lcm_url", c.lcm_url, "LCM URL for --live (ttl=0 keeps traffic on this machine)");
    s.field("replay_speed", c.replay_speed,
            "replay speed for --log: 1 = real time, 0 = as fast as possible")
        .min(0.0)
        .max(1000.0);
}

}  // namespace plumb::monitor
