// SPDX-License-Identifier: Apache-2.0
// `plumb replay LOG`: processes an LCM log recorded with lcm-logger exactly like
// `plumb-backend --log LOG` (deterministic, full speed; docs/streaming.md).

#include <cstdio>
#include <string>
#include <vector>

#include "tools/plumb/command.hpp"

#ifdef PLUMB_HAVE_BACKEND
#include "backend/app/backend_cli.hpp"
#endif
#ifdef PLUMB_HAVE_DEVICE_STREAM
#include "common/config/registry.hpp"
#include "device/stream/device_config.hpp"
#endif

namespace plumb::tools {
namespace {

constexpr const char* kCommand = "replay";

constexpr const char* kUsage =
    "usage: plumb replay LOG --out DIR [options]\n"
    "\n"
    "Processes an LCM log of a scan recorded with lcm-logger exactly as plumb-backend --log LOG\n"
    "does, deterministically and at full speed: reassembles and verifies every fragment, stores\n"
    "them in the fragment store, then reconstructs (registration, pose graph, layout, final\n"
    "model) and writes the output contract into DIR (docs/streaming.md).\n"
    "\n"
    "options:\n"
    "  --out DIR          output folder (required): trajectory.txt, mesh.ply, metrics.json,\n"
    "                     report.html, ...\n"
    "  --fragments DIR    the fragment store (default DIR/fragments)\n"
    "  --no-finalise      stop once the fragments are stored (default: reconstruct)\n"
    "  --gt DIR           ground truth to score against: groundtruth.txt or trajectory.log,\n"
    "                     gt_points.ply, layout.json (default: none, nothing is scored)\n"
    "  --key-file FILE    shared key (hex): only messages authenticated with it are accepted\n"
    "                     (default: none, messages are not authenticated)\n"
    "  --key-id N         identifier of that key (default 1)\n"
    "  --config FILE      pipeline configuration, TOML: the keys of the [pipeline] section of\n"
    "                     `plumb config doc reconstruct` (default: none, every key's default)\n"
    "  --set KEY=VALUE    override one configuration key (repeatable)\n"
    "  --log-level L      trace|debug|info|warn|error|off (default info)\n"
    "  -h, --help         this text\n"
    "\n"
    "exit status: 0 done, 1 the log or a stage failed (the message says which), 2 bad command\n"
    "line or configuration.\n";

int runReplay(const std::vector<std::string>& args) {
    for (const std::string& a : args) {
        if (a == "--help" || a == "-h") {
            std::fputs(kUsage, stdout);
            return kExitOk;
        }
    }
    if (args.empty() || args[0].rfind("-", 0) == 0) {
        return usageError(kCommand, "the first argument is the LCM log to replay");
    }
#ifdef PLUMB_HAVE_BACKEND
    std::vector<std::string> backend_args = {"--log", args[0]};
    backend_args.insert(backend_args.end(), args.begin() + 1, args.end());
    return backend::runBackendCommand(std::move(backend_args), "plumb replay");
#else
    return failure(kCommand, unsupported("this build has no backend (PLUMB_BUILD_BACKEND=OFF)"));
#endif
}

}  // namespace

#ifdef PLUMB_HAVE_DEVICE_STREAM
// plumb-device's configuration, documented by `plumb config doc device`.
PLUMB_PROGRAM_CONFIG(device, "device", plumb::device::DeviceConfig,
                     "plumb-device: capture, fusion options, fragment stream over LCM");
#endif

PLUMB_COMMAND(replay, "replay", "process an LCM log of a scan like plumb-backend --log", runReplay);

}  // namespace plumb::tools
