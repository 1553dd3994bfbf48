// SPDX-License-Identifier: Apache-2.0
// `plumb monitor`: a local web page showing fragments, the pose graph, the layout and the
// device's health as they arrive (live LCM, a replayed LCM log, or an output directory).

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "common/config/config.hpp"
#include "common/config/registry.hpp"
#include "tools/plumb/command.hpp"

#if defined(PLUMB_HAVE_MONITOR)
#include "messages/lcm_transport.hpp"
#include "messages/lcm_url.hpp"
#include "tools/monitor/monitor_config.hpp"
#include "tools/monitor/monitor_state.hpp"
#include "tools/monitor/server.hpp"
#include "tools/monitor/sources.hpp"

PLUMB_PROGRAM_CONFIG(monitor, "monitor", plumb::monitor::MonitorConfig,
                     "plumb monitor: the live web monitor (server, state, sources)");
#endif

namespace plumb::tools {
namespace {

constexpr const char* kUsage =
    "usage: plumb monitor (--dir OUT | --live [--lcm-url U] | --log LOG [--speed X]) [options]\n"
    "\n"
    "Serves a local web page with the device status (fps, tracking, dropped frames, spool),\n"
    "the fragment list, a top view of the fragments in the current global frame, the pose-graph\n"
    "edges coloured by kind and line-process weight, the layout and floor plan, and the coverage\n"
    "gaps. The page updates within a second of a fragment arriving (server-sent events).\n"
    "The monitor only listens: it never acknowledges fragments or asks for retransmissions.\n"
    "\n"
    "sources (--dir may be combined with --live or --log: the backend's output beside the wire):\n"
    "  --dir OUT       an output directory of plumb-backend or plumb reconstruct (default:\n"
    "                  none; must exist): fragments/ (fragment store), pose_graph.json,\n"
    "                  layout.json, trajectory.txt, metrics.json (the page reads 'finished'\n"
    "                  once it says the run has ended); watched for changes\n"
    "  --live          LCM heartbeats and fragments as they are sent\n"
    "  --lcm-url U     LCM URL for --live (default udpm://239.255.76.67:7667?ttl=0)\n"
    "  --log LOG       replay an LCM log (lcm-logger format; default: none)\n"
    "  --speed X       replay speed: 1 real time (default), 0 as fast as possible\n"
    "\n"
    "options:\n"
    "  --port P        TCP port (default 8765; 0 picks a free one)\n"
    "  --bind A        address to listen on (default 127.0.0.1: this machine only)\n"
    "  --token T       require T on every request, the page, its files and /api/... (open\n"
    "                  the page as <url>?token=T; or send 'Authorization: Bearer T'); without\n"
    "                  it, or with a wrong one, the page says 'token required'. Also read\n"
    "                  from PLUMB_MONITOR_TOKEN (default: none). Required when --bind is not\n"
    "                  loopback. The token is never printed\n"
    "  --config FILE   configuration (schema 'monitor', see plumb config doc monitor; default:\n"
    "                  none, every key at its default)\n"
    "  --set K=V       override one configuration key (repeatable)\n"
    "  -h, --help      this text\n"
    "\n"
    "The first line on stdout is 'plumb monitor: serving <url>'. Stop with Ctrl-C (SIGINT) or\n"
    "SIGTERM; exit status 0 after a clean stop, 1 when a source or the server cannot start,\n"
    "2 for a bad command line.\n";

constexpr const char* kCommand = "monitor";

#if defined(PLUMB_HAVE_MONITOR)

int runMonitor(const std::vector<std::string>& raw_args) {
    std::vector<std::string> args = raw_args;
    for (const std::string& a : args) {
        if (a == "--help" || a == "-h") {
            std::fputs(kUsage, stdout);
            return kExitOk;
        }
    }
    auto config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(kCommand, config_args.status().message());
    monitor::MonitorConfig cfg;
    if (Status s = config::load(*config_args, cfg); !s.isOk()) {
        return usageError(kCommand, s.message());
    }
    if (const char* env = std::getenv("PLUMB_MONITOR_TOKEN"); env != nullptr && *env != '\0') {
        cfg.server.token = env;
    }

    std::string dir, log;
    bool live = false;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&](std::string& out) -> bool {
            if (i + 1 >= args.size()) return false;
            out = args[++i];
            return true;
        };
        std::string v;
        if (a == "--dir") {
            if (!value(dir)) return usageError(kCommand, "--dir needs a directory");
        } else if (a == "--log") {
            if (!value(log)) return usageError(kCommand, "--log needs a file");
        } else if (a == "--live") {
            live = true;
        } else if (a == "--lcm-url") {
            if (!value(cfg.lcm_url)) return usageError(kCommand, "--lcm-url needs a URL");
        } else if (a == "--speed") {
            if (!value(v) || !parseNumber(v, &cfg.replay_speed) || !(cfg.replay_speed >= 0.0)) {
                return usageError(kCommand, "--speed needs a number >= 0");
            }
        } else if (a == "--port") {
            if (!value(v) || !parseNumber(v, &cfg.server.port) || cfg.server.port < 0 ||
                cfg.server.port > 65535) {
                return usageError(kCommand, "--port needs an integer in [0, 65535]");
            }
        } else if (a == "--bind") {
            if (!value(cfg.server.bind)) return usageError(kCommand, "--bind needs an address");
        } else if (a == "--token") {
            if (!value(cfg.server.token) || cfg.server.token.empty()) {
                return usageError(kCommand, "--token needs a non-empty value");
            }
        } else {
            return usageError(kCommand, "unknown argument '" + a + "'");
        }
    }
    if (live && !log.empty()) return usageError(kCommand, "--live and --log exclude each other");
    if (!live && log.empty() && dir.empty()) {
        return usageError(kCommand, "name a source: --dir OUT, --live or --log LOG");
    }
    // A URL LCM would read differently from what it says (a repeated option, an option without
    // key or value) is refused, as plumb-device and plumb-backend refuse it. A monitor only
    // listens, so a URL that could reach other machines is a warning, not an error.
    if (live) {
        if (Result<messages::LcmUrl> url = messages::parseLcmUrl(cfg.lcm_url); !url.isOk())
            return usageError(kCommand, url.status().message());
    }
    if (live && !messages::keepsTrafficOnHost(cfg.lcm_url)) {
        std::fprintf(stderr,
                     "plumb monitor: warning: %s may receive traffic from other machines "
                     "(use ttl=0 or memq://)\n",
                     cfg.lcm_url.c_str());
    }
    if (!dir.empty()) {
        std::error_code ec;
        if (!std::filesystem::is_directory(dir, ec)) {
            std::fprintf(
                stderr, "plumb monitor: --dir %s: %s\n", dir.c_str(),
                std::filesystem::exists(dir, ec) ? "not a directory" : "no such directory");
            return kExitFailure;
        }
    }
    if (!monitor::isLoopbackAddress(cfg.server.bind) && cfg.server.token.empty()) {
        return usageError(kCommand,
                          "--bind " + cfg.server.bind +
                              " exposes the monitor beyond this machine: set --token as well");
    }

    // Signals go to sigwait() below: block them before any thread starts so every thread
    // inherits the mask.
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);

    monitor::MonitorState state(cfg.state);
    std::string mode = live ? "live" : (!log.empty() ? "replay" : "directory");
    std::string detail = live ? cfg.lcm_url : log;
    if (!dir.empty()) detail += (detail.empty() ? "" : " + ") + dir;
    state.setSource(mode, detail);

    std::unique_ptr<monitor::DirectoryWatcher> watcher;
    if (!dir.empty()) {
        watcher = std::make_unique<monitor::DirectoryWatcher>(dir, state, cfg.directory);
        watcher->scanOnce();  // the page starts with what is already there
        watcher->start();
    }
    std::unique_ptr<monitor::LiveSource> live_source;
    if (live) {
        auto s = monitor::LiveSource::start(cfg.lcm_url, state);
        if (!s.isOk()) return failure(kCommand, s.status());
        live_source = std::move(*s);
    }
    std::unique_ptr<monitor::LogReplaySource> replay;
    if (!log.empty()) {
        auto s = monitor::LogReplaySource::start(log, cfg.replay_speed, state);
        if (!s.isOk()) return failure(kCommand, s.status());
        replay = std::move(*s);
    }
    auto server = monitor::MonitorServer::start(cfg.server, state);
    if (!server.isOk()) return failure(kCommand, server.status());
    std::fprintf(stdout, "plumb monitor: serving %s\n", (*server)->url().c_str());
    std::fflush(stdout);
    if (!cfg.server.token.empty()) {
        std::fprintf(stderr,
                     "plumb monitor: open %s?token=<token> (the token given with --token or "
                     "PLUMB_MONITOR_TOKEN)\n",
                     (*server)->url().c_str());
    }

    int signal_number = 0;
    sigwait(&signals, &signal_number);
    std::fprintf(stderr, "plumb monitor: stopping (signal %d)\n", signal_number);
    (*server)->stop();
    if (replay) replay->stop();
    if (live_source) live_source->stop();
    if (watcher) watcher->stop();
    return kExitOk;
}

#else

int runMonitor(const std::vector<std::string>& args) {
    for (const std::string& a : args) {
        if (a == "--help" || a == "-h") {
            std::fputs(kUsage, stdout);
            return kExitOk;
        }
    }
    std::fprintf(stderr,
                 "plumb monitor: this build has no monitor (needs LCM and cpp-httplib: "
                 "run tools/setup.sh and reconfigure)\n");
    return kExitFailure;
}

#endif

}  // namespace

PLUMB_COMMAND(monitor, "monitor", "serve a live web page of fragments, pose graph, layout",
              runMonitor);

}  // namespace plumb::tools
