// SPDX-License-Identifier: Apache-2.0
// `plumb config`: documents the configuration of every registered program and checks files.

#include <cstdio>
#include <string>
#include <vector>

#include "common/config/config.hpp"
#include "common/config/registry.hpp"
#include "tools/plumb/command.hpp"

namespace plumb::tools {
namespace {

constexpr const char* kUsage =
    "usage: plumb config list\n"
    "       plumb config doc <schema>\n"
    "       plumb config defaults <schema>\n"
    "       plumb config check [FILE.toml] --schema <schema> [--set section.key=value]...\n"
    "\n"
    "Documents the configuration of plumb's programs and checks configuration files.\n"
    "\n"
    "  list       the registered configuration schemas\n"
    "  doc        a markdown table of every key: key, type, default, unit, meaning (and range)\n"
    "  defaults   the default configuration as TOML, every key commented\n"
    "  check      loads FILE (if given) and the --set overrides exactly as the program would;\n"
    "             prints the effective configuration, or every error and exits with 1\n"
    "\n"
    "How configuration works (the same in every program):\n"
    "  * One TOML file per program, given with --config FILE. Every key is optional: a missing\n"
    "    key keeps its default. Nested structs are TOML sections ([tsdf], [grid.volume]).\n"
    "  * An unknown or misspelled key is an error that names the key, the file and the line,\n"
    "    with a suggestion when a known key is close:\n"
    "      fusion.toml:5:1: unknown key 'tsdf.voxel_sise_m' (did you mean 'tsdf.voxel_size_m'?)\n"
    "  * Values are type-checked (boolean, integer, float, string, arrays, names of choices)\n"
    "    and range-checked where a key declares a range; errors name key, file, line and what\n"
    "    was expected. TOML syntax errors give file:line:column and the parser's reason.\n"
    "  * --set section.key=value overrides a value after the file (repeatable, applied in\n"
    "    order). The value is TOML (0.01, true, [1, 2, 3], \"text\"); strings and choice names\n"
    "    need no quotes. Overrides are validated like the file; errors name the flag.\n"
    "  * The effective configuration is written to every output directory as config.toml, each\n"
    "    key with its meaning, type, unit, range and default as comments; loading that file\n"
    "    gives back exactly the same configuration.\n"
    "  * A program given a configuration that does not load exits with 2, like a bad command\n"
    "    line, before doing any work.\n"
    "\n"
    "exit status: 0 done, 1 check found errors, 2 bad command line.\n";

constexpr const char* kCommand = "config";

void printSchemas(FILE* out) {
    const std::vector<config::ProgramConfig> configs = config::programConfigs();
    std::fprintf(out, "registered configuration schemas:\n");
    if (configs.empty()) {
        std::fprintf(out, "  (none registered in this build)\n");
        return;
    }
    for (const config::ProgramConfig& p : configs) {
        std::fprintf(out, "  %-12s %s\n", p.name.c_str(), p.summary.c_str());
    }
}

// The schema named by the single argument of `doc` / `defaults`.
Result<config::ProgramConfig> schemaArgument(const std::vector<std::string>& args) {
    if (args.size() != 2) return invalidArgument(args[0] + " takes exactly one schema name");
    return config::findProgramConfig(args[1]);
}

int runCheck(std::vector<std::string> args) {
    args.erase(args.begin());  // "check"
    const Result<config::ConfigArgs> flags = config::extractConfigArgs(args);
    if (!flags.isOk()) return usageError(kCommand, flags.status().message());
    config::ConfigArgs config_args = flags.value();
    std::string schema;
    for (size_t i = 0; i < args.size(); ++i) {
        if (args[i] == "--schema") {
            if (i + 1 >= args.size()) return usageError(kCommand, "--schema needs a name");
            schema = args[++i];
        } else if (args[i].rfind("--schema=", 0) == 0) {
            schema = args[i].substr(9);
        } else if (!args[i].empty() && args[i][0] == '-') {
            return usageError(kCommand, "unknown option '" + args[i] + "'");
        } else if (config_args.file.empty()) {
            config_args.file = args[i];
        } else {
            return usageError(kCommand, "check takes one configuration file");
        }
    }
    if (schema.empty()) return usageError(kCommand, "check needs --schema <name>");
    const Result<config::ProgramConfig> p = config::findProgramConfig(schema);
    if (!p.isOk()) return usageError(kCommand, p.status().message());
    const Result<std::string> effective = p->check(config_args);
    if (!effective.isOk()) {
        std::fprintf(stderr, "plumb config check: %s\n", effective.status().message().c_str());
        return kExitFailure;
    }
    std::fputs(effective->c_str(), stdout);
    return kExitOk;
}

int runConfig(const std::vector<std::string>& args) {
    if (args.empty() || args[0] == "--help" || args[0] == "-h" || args[0] == "help") {
        std::fputs(kUsage, stdout);
        std::fputs("\n", stdout);
        printSchemas(stdout);
        return kExitOk;
    }
    const std::string& what = args[0];
    if (what == "list") {
        if (args.size() != 1) return usageError(kCommand, "list takes no arguments");
        printSchemas(stdout);
        return kExitOk;
    }
    if (what == "doc" || what == "defaults") {
        const Result<config::ProgramConfig> p = schemaArgument(args);
        if (!p.isOk()) return usageError(kCommand, p.status().message());
        const std::string text = what == "doc" ? p->markdown() : p->defaults_toml();
        std::fputs(text.c_str(), stdout);
        return kExitOk;
    }
    if (what == "check") return runCheck(args);
    return usageError(kCommand, "unknown sub-command '" + what + "'");
}

}  // namespace

PLUMB_COMMAND(config, "config", "documents configuration keys and checks configuration files",
              runConfig);

}  // namespace plumb::tools
