// SPDX-License-Identifier: Apache-2.0
#pragma once

// The configurations of plumb's programs, by name, for `plumb config` (documentation, defaults,
// checking a file). A program's sources register its top-level Config struct once:
//
//   PLUMB_PROGRAM_CONFIG(device, "device", DeviceConfig, "plumb-device: capture, tracking,
//   fusion");
//
// Registration runs from a static initialiser, so it must sit in a source file linked directly
// into the executable that lists it (a translation unit of a static library that nothing else
// references is dropped by the linker).
//
// Thread-safety: registration runs during static initialisation; afterwards the registry is
// only read, from any thread.

#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "common/config/config.hpp"
#include "common/core/status.hpp"

namespace plumb::config {

struct ProgramConfig {
    std::string name;     ///< schema name, e.g. "device"
    std::string summary;  ///< one line shown by `plumb config list`
    /// The markdown reference table of every key.
    std::function<std::string()> markdown;
    /// The default configuration as commented TOML.
    std::function<std::string()> defaults_toml;
    /// Loads `file` (may be empty: defaults only) and the `--set` overrides, validates, and
    /// returns the effective configuration as commented TOML, or the error.
    std::function<Result<std::string>(const ConfigArgs&)> check;
};

/// Adds a program configuration; false (and nothing added) when the name is already taken.
bool registerProgramConfig(ProgramConfig config);

/// Registers the Config struct C (with `describe(Schema&, C&)`) under `name`.
template <typename C>
bool registerProgramConfig(std::string name, std::string summary) {
    ProgramConfig p;
    p.name = name;
    p.summary = std::move(summary);
    p.markdown = [] { return toMarkdown<C>(); };
    p.defaults_toml = [name] { return toToml(C{}, "plumb " + name + " configuration (defaults)"); };
    p.check = [name](const ConfigArgs& args) -> Result<std::string> {
        C c{};
        PLUMB_RETURN_IF_ERROR(load(args, c));
        return toToml(c, "plumb " + name + " configuration (effective)");
    };
    return registerProgramConfig(std::move(p));
}

/// Every registered program configuration, sorted by name.
std::vector<ProgramConfig> programConfigs();

/// The program configuration called `name`, or NotFound listing the registered names.
Result<ProgramConfig> findProgramConfig(std::string_view name);

}  // namespace plumb::config

#define PLUMB_PROGRAM_CONFIG(ident, name, Type, summary)        \
    static const bool plumb_program_config_registered_##ident = \
        ::plumb::config::registerProgramConfig<Type>(name, summary)
