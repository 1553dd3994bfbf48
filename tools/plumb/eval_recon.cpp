// SPDX-License-Identifier: Apache-2.0
// `plumb eval recon`: reconstruction error of a point cloud or mesh against ground-truth geometry
// (reference §6.1: distance from each reconstructed point to the closest ground-truth point).

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "common/eval/recon_metrics.hpp"
#include "common/geometry/lie.hpp"
#include "common/io/ply.hpp"
#include "common/io/trajectory.hpp"
#include "tools/plumb/command.hpp"
#include "tools/plumb/flag_reader.hpp"

namespace plumb::tools {
namespace {

constexpr const char* kUsage =
    "usage: plumb eval recon <reconstruction.ply> <groundtruth.ply> [options]\n"
    "\n"
    "Measures reconstruction error: the distance from every reconstructed point (or mesh\n"
    "vertex) to the closest ground-truth point, reported as mean, median, RMS, 90th percentile\n"
    "and maximum, plus the accuracy fraction (reconstructed points within the threshold of the\n"
    "ground truth) and the completeness (ground-truth points within the threshold of the\n"
    "reconstruction). Nearest neighbours are exact.\n"
    "\n"
    "If the ground-truth PLY has faces, its surface is sampled on a regular barycentric grid\n"
    "(--gt-spacing) instead of using only its vertices. The reconstruction's vertices are used\n"
    "as they are.\n"
    "\n"
    "options:\n"
    "  --transform FILE  4x4 rigid transform mapping the reconstruction into the ground-truth\n"
    "                    frame (p_gt = T p_rec): 16 numbers, row by row, separated by spaces,\n"
    "                    commas or newlines; lines starting with '#' are ignored (default:\n"
    "                    identity, unless --gt-pose)\n"
    "  --gt-pose FILE    ground-truth trajectory (TUM, or Redwood .log by extension); the\n"
    "                    reconstruction is in the frame of the first camera and is mapped with\n"
    "                    the ground-truth pose of the earliest frame (P_gt = T_gt_0 P_rec;\n"
    "                    default: none)\n"
    "  --threshold M     distance for the accuracy fraction and completeness, metres\n"
    "                    (default 0.02)\n"
    "  --gt-spacing M    surface sample spacing for a ground-truth mesh, metres (default 0.005)\n"
    "  --threads N       worker threads (default: all); results do not depend on it\n"
    "  --json            print one JSON object (metres) instead of text (cm)\n"
    "  -h, --help        this text\n"
    "\n"
    "exit status: 0 measured, 1 unreadable or unusable data (the message names the file),\n"
    "2 bad command line.\n";

struct Options {
    std::string reconstruction;
    std::string groundtruth;
    std::optional<std::string> transform_file;
    std::optional<std::string> gt_pose_file;
    double gt_spacing_m = 0.005;
    eval::ReconMetricsConfig config;
    bool json = false;
};

constexpr const char* kCommand = "eval recon";

std::optional<std::string> parseArgs(const std::vector<std::string>& args, Options* options) {
    std::vector<std::string> positional;
    FlagReader reader(args);
    while (reader.next()) {
        const std::string& flag = reader.flag();
        if (flag == "--json" && reader.hasInlineValue()) return "--json takes no value";

        if (flag == "--transform" || flag == "--gt-pose") {
            const std::optional<std::string> text = reader.value();
            if (!text) return flag + " needs a file";
            (flag == "--transform" ? options->transform_file : options->gt_pose_file) = *text;
        } else if (flag == "--threshold") {
            if (auto e = reader.positive(&options->config.completeness_threshold_m, "metres"))
                return e;
        } else if (flag == "--gt-spacing") {
            if (auto e = reader.positive(&options->gt_spacing_m, "metres")) return e;
        } else if (flag == "--threads") {
            double n = 0.0;
            if (auto e = reader.positive(&n, "a number of threads")) return e;
            if (n != std::floor(n) || n > 1024) return "--threads takes an integer in 1..1024";
            options->config.num_threads = static_cast<int>(n);
        } else if (flag == "--json") {
            options->json = true;
        } else if (reader.isOption()) {
            return "unknown option '" + reader.arg() + "'";
        } else {
            positional.push_back(reader.arg());
        }
    }
    if (options->transform_file && options->gt_pose_file) {
        return "--transform and --gt-pose cannot be combined";
    }
    if (positional.size() != 2) {
        return fmt::format(
            "expected <reconstruction.ply> <groundtruth.ply>, got {} file "
            "argument(s)",
            positional.size());
    }
    options->reconstruction = positional[0];
    options->groundtruth = positional[1];
    return std::nullopt;
}

/// Reads 16 numbers (row-major 4x4) and checks that they form a rigid transform.
Result<Eigen::Isometry3d> readMatrixFile(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) {
        return notFound(fmt::format("{}: no such transform file", path));
    }
    std::ifstream in(path);
    if (!in) return ioError(fmt::format("{}: cannot open for reading", path));
    std::vector<double> values;
    std::string line;
    int line_no = 0;
    while (std::getline(in, line)) {
        ++line_no;
        const size_t first = line.find_first_not_of(" \t\r");
        if (first == std::string::npos || line[first] == '#') continue;
        std::replace(line.begin(), line.end(), ',', ' ');
        std::istringstream words(line);
        for (std::string w; words >> w;) {
            double v = 0.0;
            if (!parseNumber(w, &v)) {
                return corrupt(fmt::format("{}:{}: '{}' is not a number", path, line_no, w));
            }
            values.push_back(v);
        }
    }
    if (values.size() != 16) {
        return corrupt(
            fmt::format("{}: expected 16 numbers (a 4x4 matrix), found {}", path, values.size()));
    }
    Eigen::Matrix4d M;
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) M(r, c) = values[static_cast<size_t>(4 * r + c)];
    }
    if ((M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9) {
        return corrupt(fmt::format("{}: the last row must be 0 0 0 1", path));
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.matrix() = M;
    // Printed matrices carry a few digits only: accept 1e-4 and re-orthonormalise.
    if (!lie::isValidPose(T, 1e-4)) {
        return corrupt(fmt::format("{}: the rotation part is not a rotation", path));
    }
    return lie::orthonormalized(T);
}

/// The ground-truth pose of the earliest frame of a trajectory file.
Result<Eigen::Isometry3d> readFirstPose(const std::string& path) {
    const bool is_log = std::filesystem::path(path).extension() == ".log";
    Result<io::Trajectory> trajectory =
        is_log ? io::readLogTrajectory(path) : io::readTumTrajectory(path);
    if (!trajectory.isOk()) return trajectory.status();
    if (trajectory->empty()) return corrupt(fmt::format("{}: the trajectory has no poses", path));
    const auto first = std::min_element(trajectory->begin(), trajectory->end(),
                                        [](const io::StampedPose& a, const io::StampedPose& b) {
                                            return a.timestamp_s < b.timestamp_s;
                                        });
    return first->T_W_C;
}

nlohmann::json statsJson(const eval::DistanceStats& s) {
    return {{"count", s.count}, {"mean_m", s.mean_m}, {"median_m", s.median_m},
            {"rms_m", s.rms_m}, {"p90_m", s.p90_m},   {"max_m", s.max_m}};
}

std::string statsText(const eval::DistanceStats& s) {
    constexpr double kCm = 100.0;
    return fmt::format(
        "mean {:.3f} cm, median {:.3f} cm, rms {:.3f} cm, p90 {:.3f} cm, max "
        "{:.3f} cm",
        s.mean_m * kCm, s.median_m * kCm, s.rms_m * kCm, s.p90_m * kCm, s.max_m * kCm);
}

int runEvalRecon(const std::vector<std::string>& args) {
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

    Eigen::Isometry3d T_gt_rec = Eigen::Isometry3d::Identity();
    std::string transform_source = "identity";
    if (options.transform_file) {
        auto T = readMatrixFile(*options.transform_file);
        if (!T.isOk()) return failure(kCommand, T.status(), "transform");
        T_gt_rec = *T;
        transform_source = "matrix from " + *options.transform_file;
    } else if (options.gt_pose_file) {
        auto T = readFirstPose(*options.gt_pose_file);
        if (!T.isOk()) return failure(kCommand, T.status(), "ground-truth pose");
        T_gt_rec = *T;
        transform_source = "ground-truth pose of the first frame in " + *options.gt_pose_file;
    }

    auto rec = io::readTriangleMesh(options.reconstruction);
    if (!rec.isOk()) return failure(kCommand, rec.status(), "reconstruction");
    if (rec->vertices.empty()) {
        return failure(kCommand, corrupt(options.reconstruction + ": no points"), "reconstruction");
    }
    auto gt = io::readTriangleMesh(options.groundtruth);
    if (!gt.isOk()) return failure(kCommand, gt.status(), "ground truth");
    if (gt->vertices.empty()) {
        return failure(kCommand, corrupt(options.groundtruth + ": no points"), "ground truth");
    }
    std::vector<Eigen::Vector3f> gt_points;
    const bool gt_sampled = !gt->triangles.empty();
    if (gt_sampled) {
        auto samples = eval::sampleMeshSurface(gt->vertices, gt->triangles, options.gt_spacing_m);
        if (!samples.isOk()) {
            return failure(kCommand, samples.status(), "ground truth: " + options.groundtruth);
        }
        gt_points = std::move(*samples);
    } else {
        gt_points = std::move(gt->vertices);
    }
    const TriangleMesh rec_in_gt = transformed(*rec, T_gt_rec);

    const Result<eval::ReconMetrics> metrics =
        eval::evaluateReconstruction(rec_in_gt.vertices, gt_points, options.config);
    if (!metrics.isOk()) {
        return failure(kCommand, metrics.status(),
                       options.reconstruction + " vs " + options.groundtruth);
    }
    const eval::ReconMetrics& m = *metrics;
    if (options.json) {
        using nlohmann::json;
        json T = json::array();
        for (int r = 0; r < 4; ++r) {
            T.push_back(json::array({T_gt_rec.matrix()(r, 0), T_gt_rec.matrix()(r, 1),
                                     T_gt_rec.matrix()(r, 2), T_gt_rec.matrix()(r, 3)}));
        }
        json out;
        out["reconstruction"] = {{"path", options.reconstruction}, {"points", m.num_reconstructed}};
        out["groundtruth"] = {
            {"path", options.groundtruth},
            {"points", m.num_ground_truth},
            {"vertices", gt->vertices.size()},
            {"triangles", gt->triangles.size()},
            {"sampled", gt_sampled},
            {"spacing_m", gt_sampled ? json(options.gt_spacing_m) : json(nullptr)}};
        out["transform"] = {{"source", transform_source}, {"T_gt_rec", T}};
        out["threshold_m"] = m.threshold_m;
        out["accuracy"] = statsJson(m.accuracy);
        out["completeness_distances"] = statsJson(m.completeness_distances);
        out["accuracy_fraction"] = m.accuracy_fraction;
        out["completeness"] = m.completeness;
        std::printf("%s\n", out.dump(2).c_str());
    } else {
        fmt::print("reconstruction: {} ({} points)\n", options.reconstruction, m.num_reconstructed);
        if (gt_sampled) {
            fmt::print("ground truth:   {} ({} triangles sampled at {} m: {} points)\n",
                       options.groundtruth, gt->triangles.size(), options.gt_spacing_m,
                       m.num_ground_truth);
        } else {
            fmt::print("ground truth:   {} ({} points)\n", options.groundtruth, m.num_ground_truth);
        }
        fmt::print("transform:      {}\n", transform_source);
        fmt::print("error (reconstruction -> ground truth): {}\n", statsText(m.accuracy));
        fmt::print("coverage (ground truth -> reconstruction): {}\n",
                   statsText(m.completeness_distances));
        fmt::print("within {:.3f} cm: accuracy {:.2f} %, completeness {:.2f} %\n",
                   m.threshold_m * 100.0, m.accuracy_fraction * 100.0, m.completeness * 100.0);
    }
    std::fflush(stdout);
    return kExitOk;
}

}  // namespace
}  // namespace plumb::tools

PLUMB_COMMAND(eval_recon, "eval recon",
              "reconstruction error (mean/median distance to ground truth, completeness)",
              plumb::tools::runEvalRecon);
