// SPDX-License-Identifier: Apache-2.0
// `plumb`: the command-line entry point. Each sub-command lives in its own cmd_*.cpp file.

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/core/logging.hpp"
#include "tools/plumb/command.hpp"

namespace plumb::tools {
namespace {

std::vector<Command>& registry() {
    static std::vector<Command> commands;
    return commands;
}

/// `list` in the order of the command names.
std::vector<Command> sortedByName(std::vector<Command> list) {
    std::sort(list.begin(), list.end(),
              [](const Command& a, const Command& b) { return std::strcmp(a.name, b.name) < 0; });
    return list;
}

void printUsage(FILE* out) {
    std::fprintf(out,
                 "usage: plumb <command> [options]\n"
                 "       plumb <command> --help\n"
                 "       plumb --version\n\n"
                 "Turns depth scans of rooms into registered models with their layout.\n\n"
                 "commands:\n");
    for (const Command& c : sortedByName(registry())) {
        std::fprintf(out, "  %-12s %s\n", c.name, c.summary);
    }
    std::fprintf(out,
                 "\noptions:\n"
                 "  -h, --help      this text\n"
                 "  --version       the version of plumb\n"
                 "  --log-level L   trace|debug|info|warn|error|off (default info); before or\n"
                 "                  after the command, for every command\n"
                 "\nexit status: 0 done, 1 the work failed (the message says why), 2 bad command\n"
                 "line or configuration.\n");
}

/// Removes every `--log-level L` and `--log-level=L` from `args` (before or after the command)
/// into `*level`, the last one winning; false for a missing or bad level.
bool extractLogLevel(std::vector<std::string>& args, log::Level* level) {
    constexpr std::string_view kFlag = "--log-level";
    std::vector<std::string> kept;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        std::optional<std::string> text;
        if (a == kFlag) {
            if (i + 1 < args.size()) text = args[++i];
        } else if (a.rfind(std::string(kFlag) + "=", 0) == 0) {
            text = a.substr(kFlag.size() + 1);
        } else {
            kept.push_back(a);
            continue;
        }
        if (!text || !log::parseLevel(*text, level)) return false;
    }
    args = std::move(kept);
    return true;
}

/// `plumb <group> ...` where no command matched, e.g. "plumb eval" or "plumb eval --help":
/// lists the group's commands (to stdout with exit 0 for --help). -1 when `word` is no group.
int runGroup(const std::vector<std::string>& args) {
    const std::string& word = args[0];
    std::vector<Command> members;
    for (const Command& c : commands()) {
        if (std::string(c.name).rfind(word + " ", 0) == 0) members.push_back(c);
    }
    if (members.empty()) return -1;
    const bool help = args.size() >= 2 && (args[1] == "--help" || args[1] == "-h");
    if (!help && args.size() >= 2) {
        return usageError(word, "unknown command '" + args[1] + "'");
    }
    FILE* out = help ? stdout : stderr;
    std::fprintf(out, "usage: plumb %s <what> [options]\n\ncommands:\n", word.c_str());
    for (const Command& c : sortedByName(members)) {
        std::fprintf(out, "  %-12s %s\n", c.name, c.summary);
    }
    std::fprintf(out, "\nSee plumb %s <what> --help for the options of each.\n", word.c_str());
    return help ? kExitOk : kExitUsage;
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
    if (!extractLogLevel(args, &level)) {
        return plumb::usageError("plumb", "--log-level takes trace|debug|info|warn|error|off");
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
    if (const int group = runGroup(args); group >= 0) return group;
    return plumb::usageError("plumb", "unknown command '" + args[0] + "'");
}
