// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/run_record.hpp"

#include <fmt/format.h>

#include <cstdint>
#include <iostream>
#include <span>

#include "messages/files.hpp"
#include "tools/plumb/command.hpp"

namespace plumb::tools {
namespace fs = std::filesystem;
namespace {

constexpr int64_t kMaxRecordBytes = int64_t{1} << 24;

/// "plumb-<command>-run-1": the record's format, naming the command that wrote it.
std::string recordFormat(std::string_view command) {
    return fmt::format("plumb-{}-run-1", command);
}

/// The command of a record format ("" when `format` is none).
std::string formatCommand(const std::string& format) {
    const std::string prefix = "plumb-", suffix = "-run-1";
    if (format.size() <= prefix.size() + suffix.size() || format.rfind(prefix, 0) != 0 ||
        format.compare(format.size() - suffix.size(), suffix.size(), suffix) != 0) {
        return "";
    }
    return format.substr(prefix.size(), format.size() - prefix.size() - suffix.size());
}

/// Parses `--resume DIR [--quiet] [--threads N]` into `*r`.
std::optional<int> parseResumeArguments(std::string_view command, const char* usage,
                                        const std::vector<std::string>& args, ResumeArguments* r) {
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        if (a == "--resume" && i + 1 < args.size() && r->dir.empty()) {
            r->dir = args[++i];
        } else if (a == "--quiet") {
            r->quiet = true;
        } else if (a == "--threads" && i + 1 < args.size()) {
            if (!parseNumber(args[++i], &r->threads) || r->threads < 1)
                return usageError(command, "--threads needs a positive integer");
        } else if (a == "-h" || a == "--help") {
            std::cout << usage;
            return kExitOk;
        } else {
            return usageError(command,
                              "--resume DIR takes only --quiet and --threads besides (the "
                              "rest is the interrupted run's); not " +
                                  a);
        }
    }
    if (r->dir.empty()) return usageError(command, "--resume needs a folder");
    return std::nullopt;
}

}  // namespace

Status writeTextFileAtomic(const fs::path& path, const std::string& text) {
    return messages::writeFileAtomic(
        path, std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

Status writeRunRecord(const fs::path& out, std::string_view command, const RunRecord& record) {
    std::error_code ec;
    fs::create_directories(out / "resume", ec);
    if (ec) {
        return ioError(
            fmt::format("{}: cannot create: {}", (out / "resume").string(), ec.message()));
    }
    nlohmann::json j = record.details.is_object() ? record.details : nlohmann::json::object();
    j["format"] = recordFormat(command);
    j["arguments"] = record.arguments;
    j["cwd"] = record.cwd.string();
    j["config_toml"] = record.config_toml;
    return writeTextFileAtomic(out / "resume" / "run.json", j.dump(2) + "\n");
}

Result<RunRecord> readRunRecord(const fs::path& dir, std::string_view command) {
    const fs::path path = dir / "resume" / "run.json";
    std::error_code ec;
    if (!fs::exists(path, ec)) {
        return notFound(
            fmt::format("--resume {}: no interrupted run there (no {}; a run that "
                        "completed keeps none)",
                        dir.string(), path.string()));
    }
    Result<std::vector<uint8_t>> bytes = messages::readFile(path, kMaxRecordBytes);
    if (!bytes.isOk()) return bytes.status();
    nlohmann::json j = nlohmann::json::parse(bytes->begin(), bytes->end(), nullptr, false);
    if (j.is_discarded() || !j.is_object() || !j.contains("format") || !j["format"].is_string() ||
        !j.contains("arguments") || !j["arguments"].is_array()) {
        return corrupt(path.string() + ": not a plumb run record");
    }
    const std::string format = j["format"].get<std::string>();
    if (format != recordFormat(command)) {
        const std::string other = formatCommand(format);
        if (other.empty()) return corrupt(path.string() + ": not a plumb run record");
        return corrupt(
            fmt::format("--resume {}: the run interrupted there is a plumb {} run; "
                        "continue it with {}",
                        dir.string(), other, resumeCommand(other, dir)));
    }
    RunRecord r;
    try {
        r.arguments = j["arguments"].get<std::vector<std::string>>();
        r.cwd = j.at("cwd").get<std::string>();
        r.config_toml = j.at("config_toml").get<std::string>();
    } catch (const nlohmann::json::exception& e) {
        return corrupt(path.string() + ": " + e.what());
    }
    for (const char* key : {"format", "arguments", "cwd", "config_toml"}) j.erase(key);
    r.details = std::move(j);
    return r;
}

std::optional<int> beginResume(std::string_view command, const char* usage,
                               const std::vector<std::string>& args, ResumeArguments* resume,
                               RunRecord* record) {
    if (std::optional<int> rc = parseResumeArguments(command, usage, args, resume)) return *rc;
    resume->dir = fs::absolute(resume->dir);
    Result<RunRecord> r = readRunRecord(resume->dir, command);
    if (!r.isOk()) return usageError(command, r.status().message());
    std::error_code ec;
    fs::current_path(r->cwd, ec);
    if (ec) {
        return usageError(command, fmt::format("--resume: cannot enter {}, the interrupted "
                                               "run's working folder: {}",
                                               r->cwd.string(), ec.message()));
    }
    *record = std::move(*r);
    return std::nullopt;
}

std::string resumeCommand(std::string_view command, const fs::path& dir) {
    return fmt::format("plumb {} --resume {}", command, dir.string());
}

void removeResumeFolder(const fs::path& out) {
    std::error_code ec;
    fs::remove_all(out / "resume", ec);
}

}  // namespace plumb::tools
