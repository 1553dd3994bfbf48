// SPDX-License-Identifier: Apache-2.0
// `plumb`: the command-line entry point. Each sub-command lives in its own cmd_*.cpp file.

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "common/core/logging.hpp"
#include "tools/plumb/command.hpp"

namespace plumb::tools {
namespace {

std::vector<Command>& registry() {
    static std::vector<Command> commands;
    return commands;
}

void printUsage(FILE* out) {
    std::fprintf(out,
                 "usage: plumb <command> [options]\n"
                 "       plumb <command> --help\n\n"
                 "Turns depth scans of rooms into registered models with their layout.\n\n"
                 "commands:\n");
    std::vector<Command> sorted = registry();
    std::sort(sorted.begin(), sorted.end(),
              [](const Command& a, const Command& b) { return std::strcmp(a.name, b.name) < 0; });
    for (const Command& c : sorted) std::fprintf(out, "  %-12s %s\n", c.name, c.summary);
    std::fprintf(out,
                 "\nglobal options (before the command):\n"
                 "  --log-level L   trace|debug|info|warn|error|off (default info)\n");
}

}  // namespace

bool registerCommand(const Command& command) {
    registry().push_back(command);
    return true;
}

const std::vector<Command>& commands() { return registry(); }

}  // namespace plumb::tools

int main(int argc, char** argv) {
    using namespace plumb::tools;
    std::vector<std::string> args(argv + 1, argv + argc);
    plumb::log::Level level = plumb::log::Level::kInfo;
    while (!args.empty() && args[0] == "--log-level") {
        if (args.size() < 2 || !plumb::log::parseLevel(args[1], &level)) {
            std::fprintf(stderr, "plumb: --log-level takes trace|debug|info|warn|error|off\n");
            return kExitUsage;
        }
        args.erase(args.begin(), args.begin() + 2);
    }
    plumb::log::setupLogging("plumb", level);
    if (args.empty() || args[0] == "--help" || args[0] == "-h" || args[0] == "help") {
        printUsage(args.empty() ? stderr : stdout);
        return args.empty() ? kExitUsage : kExitOk;
    }
    if (args[0] == "--version") {
        std::printf("plumb 0.1.0\n");
        return kExitOk;
    }
    // Two-word commands ("eval traj") take precedence over one-word ones.
    if (args.size() >= 2) {
        const std::string two = args[0] + " " + args[1];
        for (const Command& c : commands()) {
            if (two == c.name) return c.run(std::vector<std::string>(args.begin() + 2, args.end()));
        }
    }
    for (const Command& c : commands()) {
        if (args[0] == c.name) {
            return c.run(std::vector<std::string>(args.begin() + 1, args.end()));
        }
    }
    // A group word alone ("plumb eval") lists its commands.
    bool any = false;
    for (const Command& c : commands()) {
        if (std::string(c.name).rfind(args[0] + " ", 0) == 0) {
            if (!any) std::fprintf(stderr, "usage: plumb %s <what> [options]\n", args[0].c_str());
            std::fprintf(stderr, "  %-12s %s\n", c.name, c.summary);
            any = true;
        }
    }
    if (any) return kExitUsage;
    std::fprintf(stderr, "plumb: unknown command '%s' (see plumb --help)\n", args[0].c_str());
    return kExitUsage;
}
