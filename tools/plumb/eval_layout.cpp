// SPDX-License-Identifier: Apache-2.0
// `plumb eval layout`: wall, floor and ceiling errors of an estimated layout against ground truth.

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/eval/layout_metrics.hpp"
#include "common/layout/layout_json.hpp"
#include "tools/plumb/command.hpp"
#include "tools/plumb/flag_reader.hpp"

namespace plumb::tools {
namespace {

constexpr const char* kUsage =
    "usage: plumb eval layout <estimate.json> <groundtruth.json> [options]\n"
    "\n"
    "Compares an estimated room layout with the ground truth (both plumb-layout-1 JSON files).\n"
    "Each layout is mapped by its own T_W_L into one comparison frame; every ground-truth wall\n"
    "is matched one to one with the estimated wall of closest normal and position (cost =\n"
    "angle in radians x --angle-weight + distance of the estimated plane from the ground-truth\n"
    "wall's centre). Reported per wall: normal angle error, offset error (d_est - d_gt in the\n"
    "comparison frame, positive = the estimated wall lies outside the true one) and the\n"
    "distance at the wall centre; unmatched walls on both sides; floor and ceiling errors;\n"
    "the error of the angle between every two matched walls; the ceiling height error.\n"
    "\n"
    "options:\n"
    "  --frame F         gt (the ground-truth layout frame, default) or world\n"
    "  --angle-weight W  metres per radian in the matching cost (default 1)\n"
    "  --max-angle DEG   walls further apart in normal angle never match (default 30)\n"
    "  --max-distance M  walls further apart at the ground-truth centre never match\n"
    "                    (default 0.5)\n"
    "  --json            print one JSON object (metres, degrees) instead of text (cm, degrees)\n"
    "  -h, --help        this text\n"
    "\n"
    "exit status: 0 measured, 1 unreadable or unusable data (the message names the file and\n"
    "field), 2 bad command line.\n";

struct Options {
    std::string estimate;
    std::string groundtruth;
    eval::LayoutMetricsConfig config;
    bool json = false;
};

constexpr const char* kCommand = "eval layout";

std::optional<std::string> parseArgs(const std::vector<std::string>& args, Options* options) {
    std::vector<std::string> positional;
    FlagReader reader(args);
    while (reader.next()) {
        const std::string& flag = reader.flag();
        if (flag == "--json" && reader.hasInlineValue()) return "--json takes no value";

        if (flag == "--frame") {
            const std::optional<std::string> text = reader.value();
            if (!text) return "--frame needs a value (gt or world)";
            if (*text == "gt") {
                options->config.frame = eval::LayoutFrame::kGroundTruthLayout;
            } else if (*text == "world") {
                options->config.frame = eval::LayoutFrame::kWorld;
            } else {
                return "--frame takes gt or world, got '" + *text + "'";
            }
        } else if (flag == "--angle-weight") {
            if (auto e =
                    reader.positive(&options->config.angle_weight_m_per_rad, "metres per radian")) {
                return e;
            }
        } else if (flag == "--max-angle") {
            if (auto e = reader.positive(&options->config.max_match_angle_deg, "degrees")) return e;
        } else if (flag == "--max-distance") {
            if (auto e = reader.positive(&options->config.max_match_distance_m, "metres")) return e;
        } else if (flag == "--json") {
            options->json = true;
        } else if (reader.isOption()) {
            return "unknown option '" + reader.arg() + "'";
        } else {
            positional.push_back(reader.arg());
        }
    }
    if (positional.size() != 2) {
        return fmt::format("expected <estimate.json> <groundtruth.json>, got {} file argument(s)",
                           positional.size());
    }
    options->estimate = positional[0];
    options->groundtruth = positional[1];
    return std::nullopt;
}

nlohmann::json planeErrorJson(const eval::PlaneError& e) {
    return {{"gt_id", e.gt_id},
            {"est_id", e.est_id},
            {"angle_error_deg", e.angle_error_deg},
            {"offset_error_m", e.offset_error_m},
            {"centre_distance_m", e.centre_distance_m},
            {"flipped", e.flipped},
            {"estimate",
             {{"normal", {e.estimate.normal.x(), e.estimate.normal.y(), e.estimate.normal.z()}},
              {"d", e.estimate.d}}}};
}

nlohmann::json toJson(const Options& options, const eval::LayoutMetrics& m) {
    using nlohmann::json;
    json out;
    out["estimate"] = options.estimate;
    out["groundtruth"] = options.groundtruth;
    out["frame"] = m.frame == eval::LayoutFrame::kWorld ? "world" : "gt";
    out["num_gt_walls"] = m.num_gt_walls;
    out["num_est_walls"] = m.num_est_walls;
    json walls = json::array();
    for (const eval::PlaneError& w : m.walls) walls.push_back(planeErrorJson(w));
    out["walls"] = walls;
    out["unmatched_gt_walls"] = m.unmatched_gt_walls;
    out["unmatched_est_walls"] = m.unmatched_est_walls;
    out["floor"] = m.floor ? planeErrorJson(*m.floor) : json(nullptr);
    out["ceiling"] = m.ceiling ? planeErrorJson(*m.ceiling) : json(nullptr);
    json pairs = json::array();
    for (const eval::WallPairAngle& p : m.wall_pairs) {
        pairs.push_back({{"gt_id_a", p.gt_id_a},
                         {"gt_id_b", p.gt_id_b},
                         {"gt_angle_deg", p.gt_angle_deg},
                         {"est_angle_deg", p.est_angle_deg},
                         {"error_deg", p.error_deg}});
    }
    out["wall_pairs"] = pairs;
    out["summary"] = {{"mean_wall_angle_error_deg", m.mean_wall_angle_error_deg},
                      {"max_wall_angle_error_deg", m.max_wall_angle_error_deg},
                      {"mean_abs_wall_offset_error_m", m.mean_abs_wall_offset_error_m},
                      {"max_abs_wall_offset_error_m", m.max_abs_wall_offset_error_m},
                      {"max_wall_pair_angle_error_deg", m.max_wall_pair_angle_error_deg}};
    out["ceiling_height_error_m"] =
        m.ceiling_height_error_m ? json(*m.ceiling_height_error_m) : json(nullptr);
    return out;
}

std::string idList(const std::vector<int>& ids) {
    if (ids.empty()) return "none";
    return fmt::format("{}", fmt::join(ids, ", "));
}

void printText(const Options& options, const eval::LayoutMetrics& m) {
    constexpr double kCm = 100.0;
    fmt::print("estimate:      {} ({} walls)\n", options.estimate, m.num_est_walls);
    fmt::print("ground truth:  {} ({} walls)\n", options.groundtruth, m.num_gt_walls);
    fmt::print("frame:         {}\n",
               m.frame == eval::LayoutFrame::kWorld ? "world" : "ground-truth layout");
    fmt::print("walls matched: {} of {}; unmatched ground truth: {}; unmatched estimate: {}\n",
               m.walls.size(), m.num_gt_walls, idList(m.unmatched_gt_walls),
               idList(m.unmatched_est_walls));
    for (const eval::PlaneError& w : m.walls) {
        fmt::print("  wall {} <- {}: angle {:.3f} deg, offset {:+.3f} cm, at centre {:+.3f} cm{}\n",
                   w.gt_id, w.est_id, w.angle_error_deg, w.offset_error_m * kCm,
                   w.centre_distance_m * kCm, w.flipped ? " (normal flipped)" : "");
    }
    auto printPlane = [&](const char* name, const std::optional<eval::PlaneError>& e) {
        if (!e) {
            fmt::print("{}: missing in one of the layouts\n", name);
            return;
        }
        fmt::print("{}: angle {:.3f} deg, offset {:+.3f} cm, at centre {:+.3f} cm\n", name,
                   e->angle_error_deg, e->offset_error_m * kCm, e->centre_distance_m * kCm);
    };
    printPlane("floor  ", m.floor);
    printPlane("ceiling", m.ceiling);
    if (m.ceiling_height_error_m) {
        fmt::print("ceiling height error: {:+.3f} cm\n", *m.ceiling_height_error_m * kCm);
    }
    fmt::print(
        "walls: angle mean {:.3f} deg, max {:.3f} deg; |offset| mean {:.3f} cm, max {:.3f} cm; "
        "wall-to-wall angle error max {:.3f} deg over {} pairs\n",
        m.mean_wall_angle_error_deg, m.max_wall_angle_error_deg,
        m.mean_abs_wall_offset_error_m * kCm, m.max_abs_wall_offset_error_m * kCm,
        m.max_wall_pair_angle_error_deg, m.wall_pairs.size());
}

int runEvalLayout(const std::vector<std::string>& args) {
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
    const Result<Layout> est = io::readLayoutJson(options.estimate);
    if (!est.isOk()) return failure(kCommand, est.status(), "estimate");
    const Result<Layout> gt = io::readLayoutJson(options.groundtruth);
    if (!gt.isOk()) return failure(kCommand, gt.status(), "ground truth");
    const Result<eval::LayoutMetrics> metrics = eval::evaluateLayout(*est, *gt, options.config);
    if (!metrics.isOk()) {
        return failure(kCommand, metrics.status(), options.estimate + " vs " + options.groundtruth);
    }
    if (options.json) {
        std::printf("%s\n", toJson(options, *metrics).dump(2).c_str());
    } else {
        printText(options, *metrics);
    }
    std::fflush(stdout);
    return kExitOk;
}

}  // namespace
}  // namespace plumb::tools

PLUMB_COMMAND(eval_layout, "eval layout",
              "wall, floor and ceiling errors of an estimated layout against ground truth",
              plumb::tools::runEvalLayout);
