// SPDX-License-Identifier: Apache-2.0
// `plumb eval traj`: trajectory accuracy of an estimate against ground truth (ATE and RPE with
// the TUM RGB-D benchmark conventions; reference §6.2).

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/eval/trajectory_metrics.hpp"
#include "common/io/trajectory.hpp"
#include "tools/plumb/command.hpp"
#include "tools/plumb/flag_reader.hpp"

namespace plumb::tools {
namespace {

constexpr const char* kUsage =
    "usage: plumb eval traj <estimate> <groundtruth> [options]\n"
    "\n"
    "Measures the accuracy of an estimated camera trajectory against ground truth with the\n"
    "TUM RGB-D benchmark conventions: poses are associated by timestamp, the estimated\n"
    "positions are rigidly aligned to the ground truth (Horn, no scale), and the absolute\n"
    "trajectory error (ATE) and relative pose error (RPE) are reported.\n"
    "\n"
    "Files: TUM text (`timestamp tx ty tz qx qy qz qw`, camera->world) or Redwood .log\n"
    "(4x4 camera->world matrices; the frame index is the timestamp). The format is taken from\n"
    "the extension (.log = Redwood, anything else = TUM) unless --format is given.\n"
    "\n"
    "options:\n"
    "  --max-diff S     largest timestamp difference for two poses to be associated, in seconds\n"
    "                   (strictly less than S, as TUM associate.py; default 0.02)\n"
    "  --offset S       seconds added to the estimate's timestamps before association\n"
    "                   (default 0)\n"
    "  --no-align       measure ATE in the given frames, without the rigid alignment\n"
    "  --delta N        RPE over motions of N frames (integer >= 1; default 1)\n"
    "  --delta-s S      RPE over motions of S seconds instead of frames (as evaluate_rpe.py;\n"
    "                   default: frames, --delta)\n"
    "  --format F       file format of both inputs: tum or log (default: by extension)\n"
    "  --json           print one JSON object (metres, radians) instead of text (cm, degrees)\n"
    "  -h, --help       this text\n"
    "\n"
    "exit status: 0 measured, 1 unreadable or unusable data (the message names the file),\n"
    "2 bad command line.\n";

enum class Format { kTum, kLog };

struct Options {
    std::string estimate;
    std::string groundtruth;
    std::optional<Format> format;
    eval::TrajectoryEvalConfig config;
    bool json = false;
};

constexpr const char* kCommand = "eval traj";

Format formatOf(const Options& options, const std::string& path) {
    if (options.format) return *options.format;
    return std::filesystem::path(path).extension() == ".log" ? Format::kLog : Format::kTum;
}

const char* formatName(Format format) { return format == Format::kLog ? "log" : "tum"; }

Result<io::Trajectory> readTrajectory(const std::string& path, Format format) {
    return format == Format::kLog ? io::readLogTrajectory(path) : io::readTumTrajectory(path);
}

/// Fills `options` from the command line; returns an error message for a usage error.
std::optional<std::string> parseArgs(const std::vector<std::string>& args, Options* options) {
    std::vector<std::string> positional;
    FlagReader reader(args);
    while (reader.next()) {
        const std::string& flag = reader.flag();
        const bool takes_no_value = flag == "--no-align" || flag == "--json";
        if (takes_no_value && reader.hasInlineValue()) return flag + " takes no value";

        if (flag == "--max-diff") {
            if (auto e = reader.number(&options->config.max_difference_s, "seconds")) return e;
            if (!(options->config.max_difference_s > 0.0)) return "--max-diff must be positive";
        } else if (flag == "--offset") {
            if (auto e = reader.number(&options->config.offset_s, "seconds")) return e;
        } else if (flag == "--delta") {
            double delta = 0.0;
            if (auto e = reader.number(&delta, "a number of frames")) return e;
            if (delta < 1.0 || delta != std::floor(delta)) {
                return "--delta takes an integer number of frames >= 1, got " +
                       fmt::format("{}", delta);
            }
            options->config.rpe.delta = delta;
            options->config.rpe.delta_unit = eval::DeltaUnit::kFrames;
        } else if (flag == "--delta-s") {
            double delta = 0.0;
            if (auto e = reader.number(&delta, "seconds")) return e;
            if (!(delta > 0.0)) return "--delta-s must be positive";
            options->config.rpe.delta = delta;
            options->config.rpe.delta_unit = eval::DeltaUnit::kSeconds;
        } else if (flag == "--format") {
            const std::optional<std::string> text = reader.value();
            if (!text) return "--format needs a value (tum or log)";
            if (*text == "tum") {
                options->format = Format::kTum;
            } else if (*text == "log") {
                options->format = Format::kLog;
            } else {
                return "--format takes tum or log, got '" + *text + "'";
            }
        } else if (flag == "--no-align") {
            options->config.ate.align = false;
        } else if (flag == "--json") {
            options->json = true;
        } else if (reader.isOption()) {
            return "unknown option '" + reader.arg() + "'";
        } else {
            positional.push_back(reader.arg());
        }
    }
    if (positional.size() != 2) {
        return fmt::format("expected <estimate> <groundtruth>, got {} file argument(s)",
                           positional.size());
    }
    options->estimate = positional[0];
    options->groundtruth = positional[1];
    return std::nullopt;
}

nlohmann::json toJson(const Options& options, const eval::TrajectoryEvaluation& e) {
    using nlohmann::json;
    json T = json::array();
    for (int r = 0; r < 4; ++r) {
        json row = json::array();
        for (int c = 0; c < 4; ++c) row.push_back(e.ate.T_gt_est.matrix()(r, c));
        T.push_back(row);
    }
    json out;
    out["estimate"] = {{"path", options.estimate},
                       {"format", formatName(formatOf(options, options.estimate))},
                       {"poses", e.num_est}};
    out["groundtruth"] = {{"path", options.groundtruth},
                          {"format", formatName(formatOf(options, options.groundtruth))},
                          {"poses", e.num_gt}};
    out["num_pairs"] = e.pairs.size();
    out["max_difference_s"] = options.config.max_difference_s;
    out["offset_s"] = options.config.offset_s;
    out["ate"] = {{"aligned", options.config.ate.align},
                  {"num_pairs", e.ate.num_pairs},
                  {"rmse_m", e.ate.rmse_m},
                  {"mean_m", e.ate.mean_m},
                  {"median_m", e.ate.median_m},
                  {"max_m", e.ate.max_m},
                  {"min_m", e.ate.min_m},
                  {"T_gt_est", T}};
    if (e.rpe) {
        const eval::RpeResult& r = *e.rpe;
        const bool frames = options.config.rpe.delta_unit == eval::DeltaUnit::kFrames;
        out["rpe"] = {{"delta", options.config.rpe.delta}, {"delta_unit", frames ? "frames" : "s"},
                      {"num_pairs", r.num_pairs},          {"trans_rmse_m", r.trans_rmse_m},
                      {"trans_mean_m", r.trans_mean_m},    {"trans_median_m", r.trans_median_m},
                      {"trans_max_m", r.trans_max_m},      {"rot_rmse_rad", r.rot_rmse_rad},
                      {"rot_mean_rad", r.rot_mean_rad},    {"rot_median_rad", r.rot_median_rad},
                      {"rot_max_rad", r.rot_max_rad}};
    } else {
        out["rpe"] = nullptr;
    }
    return out;
}

void printText(const Options& options, const eval::TrajectoryEvaluation& e) {
    const double kCm = 100.0;
    const double kDeg = 180.0 / M_PI;
    fmt::print("estimate:      {} ({}, {} poses)\n", options.estimate,
               formatName(formatOf(options, options.estimate)), e.num_est);
    fmt::print("ground truth:  {} ({}, {} poses)\n", options.groundtruth,
               formatName(formatOf(options, options.groundtruth)), e.num_gt);
    fmt::print("pairs:         {} (max difference {} s, offset {} s)\n", e.pairs.size(),
               options.config.max_difference_s, options.config.offset_s);
    fmt::print(
        "ATE ({}): rmse {:.3f} cm, mean {:.3f} cm, median {:.3f} cm, max {:.3f} cm, "
        "min {:.3f} cm\n",
        options.config.ate.align ? "rigidly aligned" : "not aligned", e.ate.rmse_m * kCm,
        e.ate.mean_m * kCm, e.ate.median_m * kCm, e.ate.max_m * kCm, e.ate.min_m * kCm);
    const bool frames = options.config.rpe.delta_unit == eval::DeltaUnit::kFrames;
    const std::string delta =
        fmt::format("{} {}", options.config.rpe.delta, frames ? "frame(s)" : "s");
    if (!e.rpe) {
        fmt::print("RPE (delta {}): no pair of associated poses is that far apart\n", delta);
        return;
    }
    const eval::RpeResult& r = *e.rpe;
    fmt::print(
        "RPE (delta {}, {} pairs): translation rmse {:.3f} cm, mean {:.3f} cm, median "
        "{:.3f} cm, max {:.3f} cm; rotation rmse {:.3f} deg, mean {:.3f} deg, median "
        "{:.3f} deg, max {:.3f} deg\n",
        delta, r.num_pairs, r.trans_rmse_m * kCm, r.trans_mean_m * kCm, r.trans_median_m * kCm,
        r.trans_max_m * kCm, r.rot_rmse_rad * kDeg, r.rot_mean_rad * kDeg, r.rot_median_rad * kDeg,
        r.rot_max_rad * kDeg);
}

int runEvalTraj(const std::vector<std::string>& args) {
    for (const std::string& a : args) {
        if (a == "-h" || a == "--help") {
            std::fputs(kUsage, stdout);
            return kExitOk;
        }
    }
    Options options;
    if (const std::optional<std::string> error = parseArgs(args, &options)) {
        return usageError(kCommand, *error);
    }
    const Result<io::Trajectory> est =
        readTrajectory(options.estimate, formatOf(options, options.estimate));
    if (!est.isOk()) return failure(kCommand, est.status(), "estimate");
    const Result<io::Trajectory> gt =
        readTrajectory(options.groundtruth, formatOf(options, options.groundtruth));
    if (!gt.isOk()) return failure(kCommand, gt.status(), "ground truth");
    const Result<eval::TrajectoryEvaluation> evaluation =
        eval::evaluateTrajectories(*est, *gt, options.config);
    if (!evaluation.isOk()) {
        return failure(kCommand, evaluation.status(),
                       options.estimate + " vs " + options.groundtruth);
    }
    if (options.json) {
        std::printf("%s\n", toJson(options, *evaluation).dump(2).c_str());
    } else {
        printText(options, *evaluation);
    }
    std::fflush(stdout);
    return kExitOk;
}

}  // namespace
}  // namespace plumb::tools

PLUMB_COMMAND(eval_traj, "eval traj",
              "trajectory accuracy (ATE, RPE) of an estimate against ground truth",
              plumb::tools::runEvalTraj);
