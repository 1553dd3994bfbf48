// SPDX-License-Identifier: Apache-2.0
#pragma once

// Typed configuration operations for any struct C with `void describe(config::Schema&, C&)`
// (see common/config/schema.hpp):
//
//   FusionConfig c;                                              // in-class defaults
//   PLUMB_RETURN_IF_ERROR(config::loadFile("fusion.toml", c));   // file values over defaults
//   PLUMB_RETURN_IF_ERROR(config::applyOverrides({"tsdf.voxel_size_m=0.02"}, c));  // then --set
//   std::string effective = config::toToml(c, "plumb fuse");     // every key documented
//
// All loaders are transactional: on error the struct is left unchanged. C must be
// default-constructible (its defaults are what a default-constructed C holds) and copyable.
//
// A program reads `--config FILE` and any number of `--set key=value` with extractConfigArgs(),
// then calls load(). Errors name the file and line, or the flag.
//
// Thread-safety: the functions touch only their arguments and may run concurrently on
// different structs.

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "common/config/schema.hpp"
#include "common/core/status.hpp"

namespace plumb::config {

/// A Schema bound to `c` (no defaults attached).
template <typename C>
Schema bind(C& c) {
    Schema s;
    describe(s, c);
    return s;
}

/// A Schema bound to `c` whose entries carry the defaults of a default-constructed C.
template <typename C>
Schema bindWithDefaults(C& c) {
    Schema s = bind(c);
    C defaults{};
    const Schema d = bind(defaults);
    s.attachDefaults(d);
    return s;
}

/// Reads a whole file into `*text`; NotFound / IoError with the path otherwise.
Status readTextFile(const std::filesystem::path& path, std::string* text);

/// Applies TOML `text` (named `source_name` in errors) to `c`; `c` unchanged on error.
template <typename C>
Status loadString(std::string_view text, std::string_view source_name, C& c) {
    C candidate = c;
    PLUMB_RETURN_IF_ERROR(bind(candidate).applyToml(text, source_name));
    c = std::move(candidate);
    return Status::ok();
}

/// Applies the TOML file at `path` to `c`; `c` unchanged on error.
template <typename C>
Status loadFile(const std::filesystem::path& path, C& c) {
    std::string text;
    PLUMB_RETURN_IF_ERROR(readTextFile(path, &text));
    return loadString(text, path.string(), c);
}

/// Applies `section.key=value` assignments in order (the values of `--set` flags); `c` unchanged
/// on error. Errors start with "--set <assignment>: ".
template <typename C>
Status applyOverrides(const std::vector<std::string>& assignments, C& c) {
    C candidate = c;
    Schema s = bind(candidate);
    for (const std::string& a : assignments) PLUMB_RETURN_IF_ERROR(s.applyAssignment(a));
    c = std::move(candidate);
    return Status::ok();
}

/// Ok when every value of `c` lies within its declared bounds.
template <typename C>
Status validate(const C& c) {
    C copy = c;
    return bind(copy).validate();
}

/// `c` as a commented TOML document (meaning, unit, range and default of every key) that loads
/// back to exactly `c`.
template <typename C>
std::string toToml(const C& c, std::string_view title = {}) {
    C copy = c;
    return bindWithDefaults(copy).toToml(title);
}

/// The markdown reference table of C's keys (key, type, default, unit, meaning).
template <typename C>
std::string toMarkdown() {
    C c{};
    return bindWithDefaults(c).toMarkdown();
}

/// The configuration flags of a program's command line.
struct ConfigArgs {
    std::filesystem::path file;          ///< `--config FILE`, empty when not given
    std::vector<std::string> overrides;  ///< every `--set key=value`, in order
};

/// Removes `--config FILE`, `--config=FILE`, `--set K=V` and `--set=K=V` from `args` and returns
/// them; the other arguments stay in order. InvalidArgument for a flag without its value or a
/// repeated --config.
Result<ConfigArgs> extractConfigArgs(std::vector<std::string>& args);

/// Defaults, then the file (if any), then the overrides, then validation.
template <typename C>
Status load(const ConfigArgs& args, C& c) {
    C candidate = c;
    if (!args.file.empty()) PLUMB_RETURN_IF_ERROR(loadFile(args.file, candidate));
    PLUMB_RETURN_IF_ERROR(applyOverrides(args.overrides, candidate));
    PLUMB_RETURN_IF_ERROR(validate(candidate));
    c = std::move(candidate);
    return Status::ok();
}

}  // namespace plumb::config
