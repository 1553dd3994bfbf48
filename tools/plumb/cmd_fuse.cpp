// SPDX-License-Identifier: Apache-2.0
// `plumb fuse`: the device's tracking and fusion over a dataset or the simulated scanner, writing
// every fragment (oriented surface points as PLY, metadata as JSON) for inspection, and measuring
// each fragment against whatever ground truth the source carries.

#include <fmt/format.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <numeric>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "common/config/config.hpp"
#include "common/core/logging.hpp"
#include "common/core/progress.hpp"
#include "common/eval/surface_distance.hpp"
#include "common/eval/trajectory_metrics.hpp"
#include "common/geometry/lie.hpp"
#include "common/io/ply.hpp"
#include "common/io/trajectory.hpp"
#include "device/fusion/fragment_builder.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tools/plumb/command.hpp"

namespace plumb::tools {
namespace {

constexpr const char* kUsage =
    "usage: plumb fuse <source> --out DIR [options]\n"
    "\n"
    "Runs the on-device pipeline (preprocessing, frame-to-model ICP tracking, voxel-hashed TSDF\n"
    "fusion, a fragment every N frames) over a recorded dataset or the simulated scanner and\n"
    "writes every fragment for inspection:\n"
    "  fragment_NNN.ply    oriented surface points in the fragment frame (coloured when the\n"
    "                      source has colour)\n"
    "  fragment_NNN.json   id, segment, why it was closed, T_W_F, frames (index, timestamp,\n"
    "                      T_F_C, tracking_ok, unconstrained_translations: how many\n"
    "                      translations the depth in view left free, along which the pose\n"
    "                      follows the constant-velocity prediction), frames_unconstrained\n"
    "                      (frames with any), depth_only (a frame with colour tracked by\n"
    "                      depth alone, and why: too little texture, or the photometric term\n"
    "                      rejected), frames_depth_only, tracking quality,\n"
    "                      odometry_information (the tracker's 6x6 J^T J of this fragment's\n"
    "                      pose relative to the previous one, rotation first; absent for a\n"
    "                      segment's first fragment), errors against ground truth\n"
    "  fragments.json      summary: source, timing, per-fragment figures, frames_photometric\n"
    "                      (tracked RGB-D), frames_depth_only and depth_only_reasons,\n"
    "                      processed_fraction (frames fused of those read: --frame-step),\n"
    "                      live (sensor_hz from the timestamps, keeps_fraction: the share of\n"
    "                      the camera's frames a live device as fast as this run would process)\n"
    "  trajectory.txt      odometry (TUM, camera->world = T_W_F * T_F_C of tracked frames)\n"
    "  config.toml         the effective configuration\n"
    "With ground truth (simulator, TUM/ICL-NUIM groundtruth.txt) each fragment gets its ATE\n"
    "(Horn-aligned, over its tracked frames), its drift (error of the last frame relative to the\n"
    "first) and, for the simulator, the median distance of its surface to the true room.\n"
    "\n"
    "source:\n"
    "  DIR | dataset:DIR  a TUM, ICL-NUIM, Redwood, 7-Scenes or plumb-sim folder (detected)\n"
    "  sim:SCENE          the simulated scanner (living_room, weak_manhattan, l_shape,\n"
    "                     corridor, or a scene .toml file)\n"
    "\n"
    "options:\n"
    "  --out DIR          output folder (required; created)\n"
    "  --frames N         use the first N frames only (default: all; the simulator 600)\n"
    "  --frame-step X     process only frames floor(j X), j = 0, 1, ... (X >= 1, may be\n"
    "                     fractional): what a live device that keeps up with 1/X of the sensor\n"
    "                     rate does when it drops the frames it has no time for (default 1)\n"
    "  --intrinsics X     camera preset or intrinsics file (default: detected)\n"
    "  --depth-scale S    depth units per metre (default: the dataset's)\n"
    "  --seed S           seed of the simulator (default 1)\n"
    "  --noise MODE       simulator noise: redwood (default), off, parametric, undistorted\n"
    "  --depth-calibration X  undistort depth: sensor (default: the sensor's own table), none,\n"
    "                     or a CLAMS/Redwood dist-model.txt\n"
    "  --no-colour        read depth only, even when the source has colour\n"
    "  --threads N        worker threads (default: all); results do not depend on it\n"
    "  --config FILE      configuration file (see `plumb config doc fusion`; default: none,\n"
    "                     every key at its default)\n"
    "  --set KEY=VALUE    override one configuration key, e.g. frames_per_fragment=100\n"
    "                     (repeatable)\n"
    "  --quiet            no progress output\n"
    "  -h, --help         this text\n"
    "\n"
    "exit status: 0 done, 1 the input failed (the message says which), 2 bad command line.\n";

constexpr const char* kCommand = "fuse";

struct FuseOptions {
    std::string source;
    std::filesystem::path out;
    SourceOptions source_options;
    int threads = 0;
    bool quiet = false;
    /// Process source frame floor(j * frame_step) for j = 0, 1, ... and drop the others.
    double frame_step = 1.0;
};

nlohmann::json poseJson(const Eigen::Isometry3d& T) {
    nlohmann::json rows = nlohmann::json::array();
    for (int r = 0; r < 4; ++r) {
        rows.push_back({T.matrix()(r, 0), T.matrix()(r, 1), T.matrix()(r, 2), T.matrix()(r, 3)});
    }
    return rows;
}

Status writeText(const std::filesystem::path& path, const std::string& text) {
    std::ofstream f(path);
    f << text;
    f.close();
    if (!f) return ioError("cannot write " + path.string());
    return Status::ok();
}

/// Ground truth known for the frames of the stream, by frame index.
struct FrameTruth {
    std::vector<std::optional<Eigen::Isometry3d>> T_W_C;  ///< by frame index
    std::optional<Eigen::Isometry3d> at(int64_t index) const {
        if (index < 0 || static_cast<size_t>(index) >= T_W_C.size()) return std::nullopt;
        return T_W_C[static_cast<size_t>(index)];
    }
};

/// Accuracy of one fragment against ground truth.
struct FragmentAccuracy {
    std::optional<eval::AteResult> ate;
    std::optional<double> drift_m, drift_deg;
    std::optional<double> surface_median_m;
};

FragmentAccuracy measureFragment(const Fragment& f, const FrameTruth& truth,
                                 const PointCloud* gt_surface_W) {
    FragmentAccuracy acc;
    std::vector<Eigen::Vector3d> est, gt;
    std::optional<Eigen::Isometry3d> first_gt;
    const FragmentFrame* last_ok = nullptr;
    std::optional<Eigen::Isometry3d> last_gt;
    for (const FragmentFrame& fr : f.frames) {
        const std::optional<Eigen::Isometry3d> T = truth.at(fr.frame_index);
        if (&fr == &f.frames.front()) first_gt = T;
        if (!fr.tracking_ok || !T) continue;
        est.push_back(fr.T_F_C.translation());
        gt.push_back(T->translation());
        last_ok = &fr;
        last_gt = T;
    }
    if (est.size() >= 3) {
        Result<eval::AteResult> ate = eval::computeAte(est, gt);
        if (ate.isOk()) acc.ate = std::move(*ate);
    }
    if (first_gt && last_ok != nullptr && last_gt) {
        // Frame 0 of a fragment is its origin: compare relative motions first -> last.
        const Eigen::Isometry3d rel_gt = first_gt->inverse() * *last_gt;
        const Eigen::Isometry3d err = rel_gt.inverse() * last_ok->T_F_C;
        acc.drift_m = err.translation().norm();
        acc.drift_deg = lie::rotationAngle(err) * 180.0 / std::numbers::pi;
    }
    if (gt_surface_W != nullptr && first_gt && !f.points_F.points.empty()) {
        // The surface placed with the true pose of the fragment's first frame.
        const Eigen::Isometry3f T_W_F = first_gt->cast<float>();
        std::vector<Eigen::Vector3f> points_W;
        points_W.reserve(f.points_F.points.size());
        for (const Eigen::Vector3f& p : f.points_F.points) points_W.push_back(T_W_F * p);
        Result<std::vector<double>> d =
            eval::pointToSurfaceDistances(points_W, *gt_surface_W, 0.05);
        if (d.isOk()) acc.surface_median_m = eval::median(std::move(*d));
    }
    return acc;
}

nlohmann::json fragmentJson(const Fragment& f, const FragmentAccuracy& acc) {
    nlohmann::json j;
    j["id"] = f.id;
    j["segment"] = f.segment;
    j["end"] = toString(f.end);
    j["T_W_F"] = poseJson(f.T_W_F);
    j["voxel_size_m"] = f.voxel_size_m;
    j["tracking_quality"] = f.tracking_quality;
    if (!f.odometry_information.isZero(0.0)) {
        nlohmann::json rows = nlohmann::json::array();
        for (int r = 0; r < 6; ++r) {
            nlohmann::json row = nlohmann::json::array();
            for (int c = 0; c < 6; ++c) row.push_back(f.odometry_information(r, c));
            rows.push_back(std::move(row));
        }
        j["odometry_information"] = std::move(rows);
    }
    j["num_points"] = f.points_F.size();
    j["points_file"] = fmt::format("fragment_{:03d}.ply", f.id);
    nlohmann::json frames = nlohmann::json::array();
    for (const FragmentFrame& fr : f.frames) {
        frames.push_back({{"frame_index", fr.frame_index},
                          {"timestamp_s", fr.timestamp_s},
                          {"tracking_ok", fr.tracking_ok},
                          {"T_F_C", poseJson(fr.T_F_C)}});
    }
    j["frames"] = std::move(frames);
    nlohmann::json gt = nlohmann::json::object();
    if (acc.ate) {
        gt["ate_rmse_m"] = acc.ate->rmse_m;
        gt["ate_median_m"] = acc.ate->median_m;
        gt["ate_max_m"] = acc.ate->max_m;
        gt["ate_pairs"] = acc.ate->num_pairs;
    }
    if (acc.drift_m) {
        gt["drift_m"] = *acc.drift_m;
        gt["drift_deg"] = *acc.drift_deg;
    }
    if (acc.surface_median_m) gt["surface_median_m"] = *acc.surface_median_m;
    if (!gt.empty()) j["ground_truth"] = std::move(gt);
    return j;
}

int runFuse(const std::vector<std::string>& arguments) {
    std::vector<std::string> args = arguments;
    Result<config::ConfigArgs> config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(kCommand, config_args.status().message());
    FuseOptions o;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&](std::string* v) {
            if (i + 1 >= args.size()) return false;
            *v = args[++i];
            return true;
        };
        std::string v;
        if (a == "-h" || a == "--help") {
            std::cout << kUsage;
            return kExitOk;
        } else if (a == "--out") {
            if (!value(&v) || v.empty()) return usageError(kCommand, "--out needs a folder");
            o.out = v;
        } else if (a == "--frames") {
            if (!value(&v) || !parseNumber(v, &o.source_options.max_frames) ||
                o.source_options.max_frames == 0)
                return usageError(kCommand, "--frames needs a positive integer");
        } else if (a == "--frame-step") {
            if (!value(&v) || !parseNumber(v, &o.frame_step) || !(o.frame_step >= 1.0) ||
                !std::isfinite(o.frame_step))
                return usageError(kCommand, "--frame-step needs a number >= 1");
        } else if (a == "--intrinsics") {
            if (!value(&o.source_options.intrinsics))
                return usageError(kCommand, "--intrinsics needs a preset or a file");
        } else if (a == "--depth-scale") {
            if (!value(&v) || !parseNumber(v, &o.source_options.depth_scale) ||
                !(o.source_options.depth_scale > 0))
                return usageError(kCommand, "--depth-scale needs a positive number");
        } else if (a == "--seed") {
            if (!value(&v) || !parseNumber(v, &o.source_options.seed))
                return usageError(kCommand, "--seed needs a non-negative integer");
        } else if (a == "--depth-calibration") {
            if (!value(&o.source_options.depth_calibration))
                return usageError(kCommand, "--depth-calibration needs a value");
            if (Status s = checkDepthCalibration(o.source_options.depth_calibration); !s.isOk())
                return usageError(kCommand, s.message());
        } else if (a == "--no-colour") {
            o.source_options.colour = false;
        } else if (a == "--noise") {
            if (!value(&o.source_options.sim_noise))
                return usageError(kCommand, "--noise needs a mode");
            if (Status s = sim::checkNoiseMode(o.source_options.sim_noise); !s.isOk())
                return usageError(kCommand, s.message());
        } else if (a == "--threads") {
            if (!value(&v) || !parseNumber(v, &o.threads) || o.threads < 1)
                return usageError(kCommand, "--threads needs a positive integer");
        } else if (a == "--quiet") {
            o.quiet = true;
        } else if (!a.empty() && a[0] == '-') {
            return usageError(kCommand, "unknown option " + a);
        } else if (o.source.empty()) {
            o.source = a;
        } else {
            return usageError(kCommand, "more than one source given: " + o.source + " and " + a);
        }
    }
    if (o.source.empty()) return usageError(kCommand, "no source given");
    if (o.out.empty()) return usageError(kCommand, "--out is required");

    device::FusionConfig cfg;
    // A configuration that does not load is a bad command line: what was asked cannot be done.
    if (Status s = config::load(*config_args, cfg); !s.isOk()) {
        return usageError(kCommand, s.message());
    }
    if (Status s = cfg.validate(); !s.isOk()) return usageError(kCommand, s.message());
    std::optional<tbb::global_control> threads;
    if (o.threads > 0) {
        threads.emplace(tbb::global_control::max_allowed_parallelism,
                        static_cast<size_t>(o.threads));
    }
    log::setupLogging("plumb fuse");

    const std::string uri = (o.source.rfind("sim:", 0) == 0 || o.source.rfind("dataset:", 0) == 0)
                                ? o.source
                                : "dataset:" + o.source;
    if (!o.source_options.sim_noise.empty() && uri.rfind("sim:", 0) != 0) {
        return usageError(kCommand, "--noise applies to sim: sources only");
    }
    if (Status s = checkSourceArguments(uri, o.source_options); !s.isOk()) {
        return usageError(kCommand, s.message());
    }
    Result<std::unique_ptr<FrameSource>> opened = openFrameSource(uri, o.source_options);
    if (!opened.isOk()) return failure(kCommand, opened.status());
    std::unique_ptr<FrameSource> source = std::move(opened).value();

    std::error_code ec;
    std::filesystem::create_directories(o.out, ec);
    if (ec)
        return failure(kCommand, ioError("cannot create " + o.out.string() + ": " + ec.message()));
    if (Status s = writeText(o.out / "config.toml", config::toToml(cfg, "plumb fuse (effective)"));
        !s.isOk()) {
        return failure(kCommand, s);
    }
    log::info("fusing {} into {}", source->description(), o.out.string());

    // Ground-truth surface of the simulated room, in W.
    std::optional<PointCloud> gt_surface;
    if (const auto* sim = dynamic_cast<const sim::SimSource*>(&source->underlying())) {
        gt_surface = sim::sampleSurfaces(sim->scene(), 0.01);
    }

    device::FragmentBuilder builder(source->camera(), cfg);
    FrameTruth truth;
    io::Trajectory odometry;
    nlohmann::json fragment_list = nlohmann::json::array();
    std::vector<double> ates, drifts_m, drifts_deg, medians;
    size_t frames = 0, lost = 0, relocalised = 0, segments_started = 0, budget = 0;
    double process_s = 0.0;
    // (source position, timestamp) of the first and last frame fused: the sensor's frame period.
    std::optional<std::pair<size_t, double>> first_stamp, last_stamp;
    ProgressOptions po;
    if (o.quiet) po.mode = ProgressOptions::Mode::kQuiet;
    po.unit = "frames";
    Progress progress("tracking and fusing", source->size().value_or(0), po);

    // Tracked frames whose ICP left translations unconstrained (the geometry in view does not
    // fix them; the pose follows the constant-velocity prediction along them), by frame index,
    // until their fragment is written.
    std::unordered_map<int64_t, int> unconstrained;
    size_t frames_unconstrained = 0;
    // Frames with colour tracked by depth only, and why (photometric fall-back), by frame index
    // until their fragment is written; counts of the reasons' kinds (the text before ':').
    std::unordered_map<int64_t, std::string> depth_only;
    size_t frames_photometric = 0;
    std::map<std::string, size_t> depth_only_kinds;
    auto emit = [&](const Fragment& f) -> Status {
        const FragmentAccuracy acc = measureFragment(f, truth, gt_surface ? &*gt_surface : nullptr);
        if (acc.ate) ates.push_back(acc.ate->rmse_m);
        if (acc.drift_m) {
            drifts_m.push_back(*acc.drift_m);
            drifts_deg.push_back(*acc.drift_deg);
        }
        if (acc.surface_median_m) medians.push_back(*acc.surface_median_m);
        for (const FragmentFrame& fr : f.frames) {
            if (!fr.tracking_ok) continue;
            odometry.push_back({fr.timestamp_s, f.T_W_F * fr.T_F_C});
        }
        const std::string stem = fmt::format("fragment_{:03d}", f.id);
        PLUMB_RETURN_IF_ERROR(io::writePointCloud(o.out / (stem + ".ply"), f.points_F));
        nlohmann::json j = fragmentJson(f, acc);
        size_t num_unconstrained = 0, num_depth_only = 0;
        for (nlohmann::json& fr : j["frames"]) {
            const auto it = unconstrained.find(fr["frame_index"].get<int64_t>());
            const int n = it == unconstrained.end() ? 0 : it->second;
            if (it != unconstrained.end()) unconstrained.erase(it);
            fr["unconstrained_translations"] = n;
            num_unconstrained += n > 0 ? 1 : 0;
            if (const auto d = depth_only.find(fr["frame_index"].get<int64_t>());
                d != depth_only.end()) {
                fr["depth_only"] = d->second;
                ++num_depth_only;
                depth_only.erase(d);
            }
        }
        j["frames_depth_only"] = num_depth_only;
        frames_unconstrained += num_unconstrained;
        j["frames_unconstrained"] = num_unconstrained;
        PLUMB_RETURN_IF_ERROR(writeText(o.out / (stem + ".json"), j.dump(2) + "\n"));
        j.erase("frames");
        j["num_frames"] = f.frames.size();
        fragment_list.push_back(std::move(j));
        if (!o.quiet || f.end != FragmentEnd::kFrameCount) {
            std::string gt_text;
            if (acc.ate) gt_text += fmt::format(", ATE {:.2f} cm", acc.ate->rmse_m * 100.0);
            if (acc.drift_m) {
                gt_text += fmt::format(", drift {:.2f} cm {:.2f} deg", *acc.drift_m * 100.0,
                                       *acc.drift_deg);
            }
            if (acc.surface_median_m) {
                gt_text += fmt::format(", surface median {:.2f} mm", *acc.surface_median_m * 1e3);
            }
            if (num_unconstrained > 0) {
                gt_text += fmt::format(
                    "; {} frames tracked with a translation the depth does not constrain",
                    num_unconstrained);
            }
            log::info("fragment {} (segment {}): {} frames, {} points, closed by {}{}", f.id,
                      f.segment, f.frames.size(), f.points_F.size(), toString(f.end), gt_text);
        }
        return Status::ok();
    };

    size_t read = 0, kept = 0;  // source frames read, frames kept (--frame-step)
    for (;;) {
        Result<Frame> frame = source->next();
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            if (source->canSkipErrors()) {
                log::warn("skipping a frame: {}", frame.status().toString());
                continue;
            }
            return failure(kCommand, frame.status());
        }
        const size_t position = read++;
        if (position != static_cast<size_t>(std::floor(static_cast<double>(kept) * o.frame_step))) {
            progress.advance();
            continue;  // dropped, as a device that has no time for it
        }
        ++kept;
        if (!first_stamp) first_stamp = std::make_pair(position, frame->timestamp_s);
        last_stamp = std::make_pair(position, frame->timestamp_s);
        if (frame->index >= 0) {
            if (truth.T_W_C.size() <= static_cast<size_t>(frame->index)) {
                truth.T_W_C.resize(static_cast<size_t>(frame->index) + 1);
            }
            truth.T_W_C[static_cast<size_t>(frame->index)] = frame->T_W_C_gt;
        }
        const auto t0 = std::chrono::steady_clock::now();
        Result<device::FrameReport> report = builder.process(*frame);
        process_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (!report.isOk()) return failure(kCommand, report.status());
        ++frames;
        lost += report->tracked ? 0 : 1;
        relocalised += report->relocalised ? 1 : 0;
        segments_started += report->new_segment ? 1 : 0;
        budget += report->budget_reached ? 1 : 0;
        if (report->tracked && report->icp.num_degenerate_directions > 0) {
            unconstrained[report->frame_index] = report->icp.num_degenerate_directions;
        }
        if (report->tracked && report->icp.photometric.used) ++frames_photometric;
        if (report->tracked && !report->icp.photometric.fallback.empty()) {
            const std::string& why = report->icp.photometric.fallback;
            depth_only[report->frame_index] = why;
            ++depth_only_kinds[why.substr(0, why.find(':'))];
        }
        if (!report->message.empty()) {
            log::warn("frame {}: {}", report->frame_index, report->message);
        }
        for (const Fragment& f : report->closed) {
            if (Status s = emit(f); !s.isOk()) return failure(kCommand, s);
        }
        progress.advance();
    }
    if (std::optional<Fragment> last = builder.finish()) {
        if (Status s = emit(*last); !s.isOk()) return failure(kCommand, s);
    }
    progress.finish();
    if (frames == 0) return failure(kCommand, failedPrecondition("the source gave no frames"));

    if (Status s = io::writeTumTrajectory(o.out / "trajectory.txt", odometry); !s.isOk()) {
        return failure(kCommand, s);
    }
    nlohmann::json summary;
    summary["source"] = source->description();
    summary["frames"] = frames;
    summary["frame_step"] = o.frame_step;
    summary["frames_tracking_failed"] = lost;
    summary["frames_unconstrained"] = frames_unconstrained;
    summary["frames_photometric"] = frames_photometric;
    size_t frames_depth_only = 0;
    for (const auto& [kind, n] : depth_only_kinds) {
        summary["depth_only_reasons"][kind] = n;
        frames_depth_only += n;
    }
    summary["frames_depth_only"] = frames_depth_only;
    summary["relocalisations"] = relocalised;
    summary["new_segments"] = segments_started;
    summary["block_budget_closures"] = budget;
    const double ms_per_frame = 1e3 * process_s / static_cast<double>(frames);
    summary["ms_per_frame"] = ms_per_frame;
    summary["frames_read"] = read;
    summary["processed_fraction"] =
        static_cast<double>(frames) / static_cast<double>(std::max<size_t>(read, 1));
    // What a live device as fast as this run would keep of the camera's frames (it drops the
    // frames it has no time for): all while a frame takes at most the sensor's frame period.
    std::string realtime_text;
    if (first_stamp && last_stamp && last_stamp->first > first_stamp->first &&
        last_stamp->second > first_stamp->second) {
        const double period_ms = 1e3 * (last_stamp->second - first_stamp->second) /
                                 static_cast<double>(last_stamp->first - first_stamp->first);
        const double keeps = std::min(1.0, period_ms / std::max(ms_per_frame, 1e-9));
        summary["live"] = {
            {"sensor_hz", 1e3 / period_ms},
            {"keeps_fraction", keeps},
            {"threads",
             o.threads > 0 ? o.threads : static_cast<int>(std::thread::hardware_concurrency())}};
        realtime_text =
            fmt::format(" (a live device this fast keeps {:.0f} % of a {:.0f} Hz camera's frames)",
                        100.0 * keeps, 1e3 / period_ms);
    }
    summary["fragments"] = fragment_list;
    auto stats = [](const std::vector<double>& v) {
        nlohmann::json s;
        if (v.empty()) return s;
        s["mean"] = std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
        s["median"] = eval::median(v);
        s["max"] = *std::max_element(v.begin(), v.end());
        return s;
    };
    if (!ates.empty()) summary["ate_rmse_m"] = stats(ates);
    if (!drifts_m.empty()) {
        summary["drift_m"] = stats(drifts_m);
        summary["drift_deg"] = stats(drifts_deg);
    }
    if (!medians.empty()) summary["surface_median_m"] = stats(medians);
    if (Status s = writeText(o.out / "fragments.json", summary.dump(2) + "\n"); !s.isOk()) {
        return failure(kCommand, s);
    }
    std::string gt_text;
    if (!ates.empty()) {
        gt_text += fmt::format("; per-fragment ATE RMSE mean {:.2f} cm, max {:.2f} cm",
                               summary["ate_rmse_m"]["mean"].get<double>() * 100.0,
                               summary["ate_rmse_m"]["max"].get<double>() * 100.0);
    }
    if (!drifts_m.empty()) {
        gt_text += fmt::format("; drift max {:.2f} cm {:.2f} deg",
                               summary["drift_m"]["max"].get<double>() * 100.0,
                               summary["drift_deg"]["max"].get<double>());
    }
    if (!medians.empty()) {
        gt_text += fmt::format("; surface median max {:.2f} mm",
                               summary["surface_median_m"]["max"].get<double>() * 1e3);
    }
    if (frames_photometric > 0 || frames_depth_only > 0) {
        std::string kinds;
        for (const auto& [kind, n] : depth_only_kinds) {
            kinds += fmt::format("{}{} {}", kinds.empty() ? " (" : ", ", n, kind);
        }
        if (!kinds.empty()) kinds += ")";
        gt_text += fmt::format("; colour: {} frames tracked RGB-D, {} by depth only{}",
                               frames_photometric, frames_depth_only, kinds);
    }
    log::info("{} frames -> {} fragments in {}, {:.1f} ms/frame{}{}", frames, fragment_list.size(),
              o.out.string(), ms_per_frame, realtime_text, gt_text);
    return kExitOk;
}

}  // namespace
}  // namespace plumb::tools

PLUMB_COMMAND(fuse, "fuse",
              "track and fuse a dataset or simulated scan into fragments (PLY + JSON) for "
              "inspection",
              plumb::tools::runFuse);
