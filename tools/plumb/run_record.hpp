// SPDX-License-Identifier: Apache-2.0
#pragma once

// What `--resume DIR` needs to continue a `plumb reconstruct` or `plumb fuse` run that Ctrl-C
// stopped: the run's own command line, working folder and effective configuration, recorded in
// DIR/resume/run.json before any work (the command's checkpoint goes beside it) and removed with
// DIR/resume when the run completes; and the `--resume DIR [--quiet] [--threads N]` command line
// that continues it.

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/core/status.hpp"

namespace plumb::tools {

struct RunRecord {
    /// The command line after the command's name, as given.
    std::vector<std::string> arguments;
    /// The working folder the run started in (its relative paths are relative to it).
    std::filesystem::path cwd;
    /// The effective configuration as TOML: a resumed run must load the same.
    std::string config_toml;
    /// Facts only one command records (reconstruct: "self_calibrate"), a JSON object whose keys
    /// are stored beside the others in run.json.
    nlohmann::json details = nlohmann::json::object();
};

/// Writes `out`/resume/run.json (atomically) for a run of `plumb <command>`.
Status writeRunRecord(const std::filesystem::path& out, std::string_view command,
                      const RunRecord& record);

/// The record of the `plumb <command>` run interrupted in `dir`: kNotFound when there is none
/// (the message says a completed run keeps none), kCorrupt for a damaged one or one of another
/// command (the message names the command that continues it).
Result<RunRecord> readRunRecord(const std::filesystem::path& dir, std::string_view command);

/// `--resume DIR [--quiet] [--threads N]`.
struct ResumeArguments {
    std::filesystem::path dir;  ///< absolute
    bool quiet = false;
    int threads = 0;  ///< 0: the interrupted run's
};

/// For `plumb <command> --resume ...` (`args` hold --resume): parses `args` into `*resume`, reads
/// the record of the run interrupted in its folder into `*record` and enters that run's working
/// folder. nullopt to go on; otherwise the exit status to return (after printing `usage` for
/// --help, or a usage error for a bad command line or a folder without a record).
std::optional<int> beginResume(std::string_view command, const char* usage,
                               const std::vector<std::string>& args, ResumeArguments* resume,
                               RunRecord* record);

/// "plumb <command> --resume DIR": what continues the run interrupted in `dir`.
std::string resumeCommand(std::string_view command, const std::filesystem::path& dir);

/// Writes `text` to `path` atomically (written aside, synced, renamed into place).
Status writeTextFileAtomic(const std::filesystem::path& path, const std::string& text);

/// Removes `out`/resume (the record and any checkpoint): a completed run leaves nothing to resume.
void removeResumeFolder(const std::filesystem::path& out);

}  // namespace plumb::tools
