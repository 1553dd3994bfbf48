// SPDX-License-Identifier: Apache-2.0
// plumb-monitor-fixture OUT [--fragments N] [--interval S]
// Writes a scan for the monitor's browser test: OUT/session.lcm (heartbeats and fragments of the
// test room, S seconds apart in log time) and OUT/backend/ (pose_graph.json with odometry edges
// and two loops, layout.json of the room).

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/layout/layout_json.hpp"
#include "tests/monitor/monitor_fixtures.hpp"
#include "tests/monitor/session_log.hpp"

int main(int argc, char** argv) {
    namespace fs = std::filesystem;
    using namespace plumb::monitor::testing;
    if (argc < 2) {
        std::fprintf(stderr, "usage: plumb-monitor-fixture OUT [--fragments N] [--interval S]\n");
        return 2;
    }
    const fs::path out = argv[1];
    int n = 8;
    double interval_s = 0.4;
    for (int i = 2; i + 1 < argc; i += 2) {
        const std::string flag = argv[i];
        if (flag == "--fragments") {
            n = std::atoi(argv[i + 1]);
        } else if (flag == "--interval") {
            interval_s = std::atof(argv[i + 1]);
        } else {
            std::fprintf(stderr, "plumb-monitor-fixture: unknown flag %s\n", flag.c_str());
            return 2;
        }
    }
    if (n < 1 || n > 8 || !(interval_s >= 0.0)) {
        std::fprintf(stderr, "plumb-monitor-fixture: need 1..8 fragments and interval >= 0\n");
        return 2;
    }
    std::error_code ec;
    fs::create_directories(out / "backend", ec);
    if (ec) {
        std::fprintf(stderr, "plumb-monitor-fixture: %s: %s\n", out.c_str(), ec.message().c_str());
        return 1;
    }
    std::vector<plumb::Fragment> fragments;
    for (int k = 0; k < n; ++k) fragments.push_back(roomFragment(k));
    auto msgs = sessionMessages(fragments, 77, interval_s);
    if (!msgs.isOk()) {
        std::fprintf(stderr, "plumb-monitor-fixture: %s\n", msgs.status().message().c_str());
        return 1;
    }
    if (auto s = writeLcmLog(out / "session.lcm", *msgs); !s.isOk()) {
        std::fprintf(stderr, "plumb-monitor-fixture: %s\n", s.message().c_str());
        return 1;
    }
    std::ofstream(out / "backend" / "pose_graph.json") << poseGraphJsonText(n);
    if (auto s = plumb::io::writeLayoutJson(out / "backend" / "layout.json", roomLayout());
        !s.isOk()) {
        std::fprintf(stderr, "plumb-monitor-fixture: %s\n", s.message().c_str());
        return 1;
    }
    std::printf("%d fragments, %zu messages -> %s\n", n, msgs->size(), out.c_str());
    return 0;
}
