// SPDX-License-Identifier: Apache-2.0
// `plumb replay LOG`: processes an LCM log recorded with lcm-logger exactly like
// `plumb-backend --log LOG` (deterministic, full speed; docs/streaming.md).

#include <cstdio>
#include <string>
#include <vector>

#include "tools/plumb/command.hpp"

#ifdef PLUMB_HAVE_BACKEND
#include "backend/ingest/backend_cli.hpp"
#endif
#ifdef PLUMB_HAVE_DEVICE_STREAM
#include "common/config/registry.hpp"
#include "device/stream/device_config.hpp"
#endif

namespace plumb::tools {
namespace {

int runReplay(const std::vector<std::string>& args) {
    if (args.empty() || args[0] == "--help" || args[0] == "-h") {
        std::printf(
            "usage: plumb replay LOG --out DIR [plumb-backend options]\n"
            "\n"
            "Reassembles, verifies and stores the fragments of an LCM log recorded with\n"
            "lcm-logger into DIR/fragments (same result as plumb-backend --log LOG), then\n"
            "reconstructs unless --no-finalise. See plumb-backend --help for the options.\n");
        return args.empty() ? kExitUsage : kExitOk;
    }
#ifdef PLUMB_HAVE_BACKEND
    std::vector<std::string> backend_args = {"--log", args[0]};
    backend_args.insert(backend_args.end(), args.begin() + 1, args.end());
    return backend::runBackendCommand(std::move(backend_args), "plumb replay");
#else
    std::fprintf(stderr, "plumb replay: this build has no backend (PLUMB_BUILD_BACKEND=OFF)\n");
    return kExitFailure;
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
