// SPDX-License-Identifier: Apache-2.0
// `plumb reconstruct`: the whole pipeline in one process on a recorded dataset or the simulated
// scanner — fusion into fragments (as the device would), then the backend (registration, layout,
// layout-constrained global registration, final model, evaluation, report).

#include <fmt/format.h>
#include <tbb/global_control.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "backend/calibration/self_calibration.hpp"
#include "backend/pipeline/pipeline.hpp"
#include "common/config/config.hpp"
#include "common/config/registry.hpp"
#include "common/core/logging.hpp"
#include "common/core/progress.hpp"
#include "common/io/trajectory.hpp"
#include "common/layout/layout.hpp"
#include "device/fusion/fragment_builder.hpp"
#include "device/fusion/fusion_config.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tools/plumb/calibration_aligner.hpp"
#include "tools/plumb/command.hpp"
#include "tools/plumb/pose_lookup.hpp"

namespace plumb::tools {

/// `--self-calibrate`: how the depth distortion table is learned from the scan.
struct SelfCalibrateConfig {
    /// Every frame_step-th frame of the scan is compared with the model (each frame is held in
    /// memory twice, with up to 8 bytes per compared pixel).
    int frame_step = 2;
    /// Re-align every compared frame to each iteration's model by frame-to-model ICP before
    /// comparing it. Off: on a 600-frame living_room scan it made the learned table no better
    /// (median error at 3 m 0.66 % against 0.60 % with the reconstruction's poses) at 5x the
    /// time of the estimate (BENCHMARKS.md).
    bool refine_poses = false;
    /// The estimator and its alternation (as `plumb calibrate`).
    calibration::SelfCalibrationConfig estimate;
};

void describe(config::Schema& s, SelfCalibrateConfig& c) {
    s.field("frame_step", c.frame_step,
            "every frame_step-th frame of the scan is compared with the model")
        .min(1);
    s.field("refine_poses", c.refine_poses,
            "re-align every compared frame to each iteration's model by frame-to-model ICP");
    s.section("estimate", c.estimate, "the table estimate and its alternation (reference §7c)");
}

/// The configuration of `plumb reconstruct` (and of the backend half of `plumb demo`).
struct ReconstructConfig {
    device::FusionConfig fusion;
    backend::PipelineConfig pipeline;
    SelfCalibrateConfig self_calibration;
};

void describe(config::Schema& s, ReconstructConfig& c) {
    s.section("fusion", c.fusion, "tracking and fusion into fragments (as on the device)");
    s.section("pipeline", c.pipeline, "the backend: registration, layout, global registration");
    s.section("self_calibration", c.self_calibration,
              "--self-calibrate: learning the depth distortion table from the scan");
}

PLUMB_PROGRAM_CONFIG(reconstruct, "reconstruct", ReconstructConfig,
                     "plumb reconstruct: fusion into fragments and the whole backend");

namespace {

constexpr const char* kUsage =
    "usage: plumb reconstruct <source> --out DIR [options]\n"
    "\n"
    "Reconstructs a room from a recorded dataset or the simulated scanner in one process:\n"
    "tracking and fusion into fragments (as plumb-device does), initial registration (loop\n"
    "closures, line-process pose graph), layout estimation alternated with layout-constrained\n"
    "global registration, the final mesh, and an evaluation against whatever ground truth the\n"
    "input carries. Writes the output contract: trajectory.txt, trajectory.log, pose_graph.json,\n"
    "layout.json, floorplan.svg, mesh.ply, metrics.json, report.html, config.toml; the\n"
    "--no-layout baseline goes to DIR/baseline for comparison.\n"
    "\n"
    "source:\n"
    "  DIR | dataset:DIR  a TUM, ICL-NUIM, Redwood, 7-Scenes or plumb-sim folder (detected)\n"
    "  sim:SCENE          the simulated scanner (living_room, weak_manhattan, l_shape,\n"
    "                     corridor, or a scene .toml file)\n"
    "\n"
    "options:\n"
    "  --out DIR          output folder (required)\n"
    "  --no-layout        the Choi-style baseline only (registration without layout)\n"
    "  --no-baseline      do not also compute the baseline for comparison\n"
    "  --frames N         use the first N frames only\n"
    "  --frame-step X     fuse only frames floor(j X), j = 0, 1, ... (X >= 1, may be\n"
    "                     fractional), as a device keeping up with 1/X of the sensor rate\n"
    "                     (default 1)\n"
    "  --intrinsics X     camera preset or intrinsics file (default: detected)\n"
    "  --depth-scale S    depth units per metre (default: the dataset's)\n"
    "  --seed S           seed of the simulator (default 1)\n"
    "  --noise MODE       simulator noise: redwood (default; with the measured distortion\n"
    "                     table), undistorted, parametric, off\n"
    "  --depth-calibration X  undistort depth: sensor (default: the sensor's own table; the\n"
    "                     simulated sensor with the measured table is calibrated with it,\n"
    "                     recordings and real cameras have none), none, or a dist-model.txt\n"
    "  --self-calibrate   learn the depth distortion table from the scan itself: reconstruct\n"
    "                     from the raw depth (into DIR/self_calibration/raw), estimate the\n"
    "                     table against that model at the frames' poses (reference §7c), then\n"
    "                     reconstruct again with it; writes DIR/depth_calibration.txt (use it\n"
    "                     with --depth-calibration for later scans by the same camera) and its\n"
    "                     coverage and before/after figures into metrics.json and the report.\n"
    "                     Takes about 2.5x the time; excludes --depth-calibration\n"
    "  --no-colour        read depth only, even when the source has colour\n"
    "  --gt DIR           ground truth folder (groundtruth.txt or trajectory.log,\n"
    "                     gt_points.ply, layout.json; default: the dataset folder)\n"
    "  --no-gt            do not evaluate against ground truth\n"
    "  --threads N        worker threads (default: all); results do not depend on it\n"
    "  --config FILE      configuration file (default: none, every key at its default; see\n"
    "                     `plumb config doc reconstruct`)\n"
    "  --set KEY=VALUE    override one configuration key (repeatable)\n"
    "  --quiet            no progress output\n"
    "  -h, --help         this text\n"
    "\n"
    "exit status: 0 done, 1 the input or a stage failed (the message says which), 2 bad\n"
    "command line.\n";

constexpr const char* kCommand = "reconstruct";

struct Options {
    std::string source;
    std::filesystem::path out;
    bool no_layout = false;
    bool no_baseline = false;
    SourceOptions source_options;
    std::optional<std::filesystem::path> gt_dir;
    bool no_gt = false;
    bool self_calibrate = false;
    bool depth_calibration_given = false;
    /// Fuse source frame floor(j * frame_step) for j = 0, 1, ... only.
    double frame_step = 1.0;
    int threads = 0;
    bool quiet = false;
};

std::string normaliseUri(const std::string& source) {
    if (source.rfind("sim:", 0) == 0 || source.rfind("dataset:", 0) == 0) return source;
    return "dataset:" + source;
}

/// Ground truth of the simulated scanner: its trajectory, dense surface samples and room layout.
Result<backend::GroundTruth> simGroundTruth(const sim::SimSource& sim) {
    backend::GroundTruth gt;
    gt.trajectory = sim.trajectory();
    const PointCloud samples = sim::sampleSurfaces(sim.scene(), 0.01);
    gt.points = samples.points;
    Result<Layout> layout = makeRoomLayout(sim.scene().polygon, sim.scene().height_m);
    if (!layout.isOk()) return layout.status();
    gt.layout = std::move(*layout);
    gt.description =
        fmt::format("simulator ({}: trajectory, surface samples, layout)", sim.scene().name);
    return gt;
}

/// Runs the device's tracking and fusion over a whole source. Empty fragments (a tracking loss
/// on the first frame of a fragment) are dropped and the rest renumbered 0..n-1.
Result<std::vector<Fragment>> fuseSource(FrameSource& source, const device::FusionConfig& config,
                                         double frame_step, bool quiet,
                                         io::Trajectory* poses_read) {
    device::FragmentBuilder builder(source.camera(), config);
    std::vector<Fragment> fragments;
    ProgressOptions po;
    if (quiet) po.mode = ProgressOptions::Mode::kQuiet;
    po.unit = "frames";
    Progress progress("tracking and fusing", source.size().value_or(0), po);
    size_t lost = 0;
    size_t read = 0, fused = 0;  // source frames read, frames fused (--frame-step)
    for (;;) {
        Result<Frame> frame = source.next();
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            return frame.status();
        }
        if (frame->T_W_C_gt) poses_read->push_back({frame->timestamp_s, *frame->T_W_C_gt});
        const size_t position = read++;
        if (position != static_cast<size_t>(std::floor(static_cast<double>(fused) * frame_step))) {
            progress.advance();
            continue;  // dropped, as a device that keeps up with 1 / frame_step of the rate
        }
        ++fused;
        Result<device::FrameReport> report = builder.process(*frame);
        if (!report.isOk()) return report.status();
        if (!report->tracked) ++lost;
        for (Fragment& f : report->closed) fragments.push_back(std::move(f));
        progress.advance();
    }
    if (std::optional<Fragment> last = builder.finish()) fragments.push_back(std::move(*last));
    progress.finish();
    if (lost > 0)
        log::warn("tracking failed on {} frames (their fragments were closed early)", lost);
    std::vector<Fragment> kept;
    for (Fragment& f : fragments) {
        if (f.points_F.points.empty()) {
            log::warn("fragment {} has no surface points; dropped", f.id);
            continue;
        }
        f.id = static_cast<uint32_t>(kept.size());
        kept.push_back(std::move(f));
    }
    if (kept.empty()) return failedPrecondition("the scan produced no fragment with a surface");
    return kept;
}

/// Creates `out` (when missing) and checks that a file can be written into it, before any work.
Status prepareOutputFolder(const std::filesystem::path& out) {
    std::error_code ec;
    if (std::filesystem::exists(out, ec) && !std::filesystem::is_directory(out, ec)) {
        return invalidArgument(fmt::format("--out {}: exists and is not a folder", out.string()));
    }
    std::filesystem::create_directories(out, ec);
    if (ec) return ioError(fmt::format("--out {}: cannot create: {}", out.string(), ec.message()));
    const std::filesystem::path probe = out / ".plumb-write-test";
    {
        std::ofstream f(probe);
        if (!(f << "plumb\n")) {
            return ioError(fmt::format("--out {}: cannot write into it", out.string()));
        }
    }
    std::filesystem::remove(probe, ec);
    return Status::ok();
}

/// Fusion of `source` (opened from `uri` with `source_options`) into fragments, then the backend
/// into `out`.
Result<backend::PipelineResult> reconstructOnce(
    FrameSource& source, const std::string& uri, const SourceOptions& source_options,
    const ReconstructConfig& cfg, const backend::PipelineConfig& pipeline,
    backend::PipelineInput input, const std::filesystem::path& out, const Options& options) {
    io::Trajectory poses_read;
    Result<std::vector<Fragment>> fragments =
        fuseSource(source, cfg.fusion, options.frame_step, options.quiet, &poses_read);
    if (!fragments.isOk()) return fragments.status();
    // Poses the source reads with its frames (7-Scenes' per-frame files, a dataset's
    // groundtruth.txt) are scored when the folder has no trajectory file of its own.
    if (!options.no_gt && !input.ground_truth.trajectory && !poses_read.empty()) {
        std::string& d = input.ground_truth.description;
        const std::string what = fmt::format("the poses read with {} frames", poses_read.size());
        d = (d.empty() || d == "none") ? what : d + "; " + what;
        input.ground_truth.trajectory = std::move(poses_read);
    }
    input.fragments = std::move(*fragments);
    log::info("{} fragments fused", input.fragments.size());
    input.open_raw_frames = [uri, source_options]() {
        return openFrameSource(uri, source_options);
    };
    return backend::runPipeline(input, pipeline, out, !options.quiet);
}

/// The accuracy figures of a run's main variant, for the self-calibration's before/after.
nlohmann::json mainFigures(const backend::PipelineResult& r) {
    nlohmann::json out = nlohmann::json::object();
    const nlohmann::json& variants = r.metrics.value("variants", nlohmann::json::object());
    if (r.variants.empty() || !variants.contains(r.variants.front().name)) return out;
    const nlohmann::json& v = variants[r.variants.front().name];
    if (v.contains("ate")) out["ate_rmse_m"] = v["ate"].value("rmse_m", 0.0);
    if (v.contains("recon")) out["recon_mean_m"] = v["recon"].value("mean_m", 0.0);
    return out;
}

/// `--self-calibrate`: a reconstruction from the raw depth (`raw_source`, opened without depth
/// calibration), the table estimated against it at its poses, and the reconstruction with the
/// learned table into o.out.
Result<backend::PipelineResult> selfCalibratedRun(FrameSource& raw_source, const std::string& uri,
                                                  const Options& o, const ReconstructConfig& cfg,
                                                  const backend::PipelineInput& base) {
    const auto start = std::chrono::steady_clock::now();
    const SelfCalibrateConfig& sc = cfg.self_calibration;
    SourceOptions raw_options = o.source_options;
    raw_options.depth_calibration = "none";
    const std::filesystem::path raw_dir = o.out / "self_calibration" / "raw";
    log::info("self-calibration 1/3: reconstructing from the raw depth into {}", raw_dir.string());
    backend::PipelineConfig first = cfg.pipeline;
    first.compare_baseline = false;
    Result<backend::PipelineResult> before =
        reconstructOnce(raw_source, uri, raw_options, cfg, first, base, raw_dir, o);
    if (!before.isOk()) return prefixed(before.status(), "self-calibration, raw reconstruction");
    const double raw_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    Result<PoseLookup> poses = PoseLookup::read(raw_dir / "trajectory.txt");
    if (!poses.isOk()) return poses.status();

    // The raw frames at the reconstruction's poses.
    raw_options.colour = false;
    Result<std::unique_ptr<FrameSource>> source = openFrameSource(uri, raw_options);
    if (!source.isOk()) return source.status();
    Result<PosedDepth> posed = readPosedDepth(**source, *poses, sc.frame_step);
    if (!posed.isOk()) return posed.status();
    const std::vector<DepthImage>& depth = posed->depth;  // frames not tracked have no pose
    const std::vector<Eigen::Isometry3d>& T_W_C = posed->T_W_C;
    log::info("self-calibration 2/3: estimating the depth distortion table from {} frames",
              depth.size());
    nlohmann::json iterations = nlohmann::json::array();
    auto observe = [&](const calibration::CalibrationIteration& it) {
        const calibration::DistortionEstimate& e = it.estimate;
        log::info(
            "self-calibration iteration {}: change median {:.5f} max {:.5f}; cells covered per "
            "bin (1/3/5/7/9 m) {} {} {} {} {} of 6400",
            it.iteration + 1, e.median_change, e.max_change, e.covered_cells[0], e.covered_cells[1],
            e.covered_cells[2], e.covered_cells[3], e.covered_cells[4]);
        iterations.push_back({{"change_median", e.median_change},
                              {"change_max", e.max_change},
                              {"covered_cells", e.covered_cells}});
    };
    size_t unaligned = 0;
    const calibration::FrameAligner aligner =
        sc.refine_poses ? icpFrameAligner(CalibrationAlignerConfig{}, &unaligned)
                        : calibration::FrameAligner{};
    Result<calibration::SelfCalibrationResult> learned = calibration::selfCalibrate(
        depth, base.camera, T_W_C, sc.estimate, nullptr, observe, aligner);
    if (!learned.isOk()) return prefixed(learned.status(), "self-calibration");
    std::error_code ec;
    std::filesystem::create_directories(o.out, ec);
    const std::filesystem::path table_path = o.out / "depth_calibration.txt";
    if (Status s = learned->table.save(table_path); !s.isOk()) return s;
    const calibration::DistortionEstimate& last = learned->iterations.back().estimate;
    log::info("self-calibration: {} after {} iterations; table written to {}",
              learned->converged ? "converged" : "stopped at the iteration limit",
              learned->iterations.size(), table_path.string());

    log::info("self-calibration 3/3: reconstructing with the learned table");
    backend::PipelineInput input = base;
    input.self_calibration = {
        {"table", table_path.filename().string()},
        {"frames", depth.size()},
        {"frame_step", sc.frame_step},
        {"refine_poses", sc.refine_poses},
        {"frames_not_aligned", unaligned},
        {"iterations", iterations},
        {"converged", learned->converged},
        {"covered_cells", last.covered_cells},
        {"gauge_bin_m", sim::DistortionTable::binCentreM(last.gauge_bin)},
        {"gauge_scale", last.gauge_scale},
        {"raw_reconstruction", "self_calibration/raw"},
        {"before", mainFigures(*before)},
        {"raw_reconstruction_seconds", raw_seconds},
        {"estimate_seconds",
         std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() -
             raw_seconds}};
    SourceOptions calibrated = o.source_options;
    calibrated.depth_calibration = table_path.string();
    Result<std::unique_ptr<FrameSource>> calibrated_source = openFrameSource(uri, calibrated);
    if (!calibrated_source.isOk()) return calibrated_source.status();
    return reconstructOnce(**calibrated_source, uri, calibrated, cfg, cfg.pipeline,
                           std::move(input), o.out, o);
}

}  // namespace

int runReconstruct(const std::vector<std::string>& arguments) {
    std::vector<std::string> args = arguments;
    Result<config::ConfigArgs> config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(kCommand, config_args.status().message());
    Options o;
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
            if (!value(&v)) return usageError(kCommand, "--out needs a folder");
            o.out = v;
        } else if (a == "--no-layout") {
            o.no_layout = true;
        } else if (a == "--no-baseline") {
            o.no_baseline = true;
        } else if (a == "--frames") {
            if (!value(&v) || !parseNumber(v, &o.source_options.max_frames) ||
                o.source_options.max_frames == 0)
                return usageError(kCommand, "--frames needs a positive integer");
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
            o.depth_calibration_given = true;
        } else if (a == "--frame-step") {
            if (!value(&v) || !parseNumber(v, &o.frame_step) || !(o.frame_step >= 1.0))
                return usageError(kCommand, "--frame-step needs a number >= 1");
        } else if (a == "--self-calibrate") {
            o.self_calibrate = true;
        } else if (a == "--no-colour") {
            o.source_options.colour = false;
        } else if (a == "--noise") {
            if (!value(&o.source_options.sim_noise))
                return usageError(kCommand, "--noise needs a mode");
            if (Status s = sim::checkNoiseMode(o.source_options.sim_noise); !s.isOk())
                return usageError(kCommand, s.message());
        } else if (a == "--gt") {
            if (!value(&v)) return usageError(kCommand, "--gt needs a folder");
            o.gt_dir = v;
        } else if (a == "--no-gt") {
            o.no_gt = true;
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
    if (o.self_calibrate && o.depth_calibration_given)
        return usageError(
            kCommand, "--self-calibrate learns the depth calibration: drop --depth-calibration");

    ReconstructConfig cfg;
    if (Status s = config::load(*config_args, cfg); !s.isOk())
        return usageError(kCommand, s.message());
    if (o.no_layout) cfg.pipeline.use_layout = false;
    if (o.no_baseline) cfg.pipeline.compare_baseline = false;
    std::optional<tbb::global_control> threads;
    if (o.threads > 0)
        threads.emplace(tbb::global_control::max_allowed_parallelism,
                        static_cast<size_t>(o.threads));
    log::setupLogging("plumb reconstruct");

    const std::string uri = normaliseUri(o.source);
    if (!o.source_options.sim_noise.empty() && uri.rfind("sim:", 0) != 0) {
        return usageError(kCommand, "--noise applies to sim: sources only");
    }
    if (Status s = checkSourceArguments(uri, o.source_options); !s.isOk())
        return usageError(kCommand, s.message());
    if (Status s = calibration::validate(cfg.self_calibration.estimate);
        o.self_calibrate && !s.isOk())
        return usageError(kCommand, s.message());
    if (Status s = prepareOutputFolder(o.out); !s.isOk()) return usageError(kCommand, s.message());
    SourceOptions first_options = o.source_options;
    if (o.self_calibrate) first_options.depth_calibration = "none";
    Result<std::unique_ptr<FrameSource>> source = openFrameSource(uri, first_options);
    if (!source.isOk()) return failure(kCommand, source.status());
    log::info("reconstructing {} into {}{}", (*source)->description(), o.out.string(),
              o.self_calibrate ? ", self-calibrating the depth" : "");

    backend::PipelineInput base;
    base.description = uri;
    base.camera = (*source)->camera();
    if (!o.no_gt) {
        if (const auto* sim = dynamic_cast<const sim::SimSource*>(&(*source)->underlying())) {
            Result<backend::GroundTruth> gt = simGroundTruth(*sim);
            if (!gt.isOk()) return failure(kCommand, gt.status());
            base.ground_truth = std::move(*gt);
        } else {
            const std::filesystem::path dir =
                o.gt_dir ? *o.gt_dir : std::filesystem::path(uri.substr(uri.find(':') + 1));
            Result<backend::GroundTruth> gt = backend::loadGroundTruth(dir);
            if (!gt.isOk()) return failure(kCommand, gt.status());
            base.ground_truth = std::move(*gt);
        }
    }
    base.config_toml = config::toToml(cfg, "plumb reconstruct: effective configuration");

    Result<backend::PipelineResult> result =
        o.self_calibrate
            ? selfCalibratedRun(**source, uri, o, cfg, base)
            : reconstructOnce(**source, uri, o.source_options, cfg, cfg.pipeline, base, o.out, o);
    if (!result.isOk()) return failure(kCommand, result.status());
    if (o.self_calibrate) {
        const nlohmann::json& sc = result->metrics["self_calibration"];
        const nlohmann::json before = sc.value("before", nlohmann::json::object());
        std::cout << "self-calibration: table " << (o.out / "depth_calibration.txt").string();
        if (before.contains("ate_rmse_m")) {
            std::cout << fmt::format("; from the raw depth ATE RMSE {:.2f} cm",
                                     100.0 * before.value("ate_rmse_m", 0.0));
        }
        if (before.contains("recon_mean_m")) {
            std::cout << fmt::format(", recon error mean {:.2f} cm",
                                     100.0 * before.value("recon_mean_m", 0.0));
        }
        std::cout << " (" << (o.out / "self_calibration" / "raw").string() << ")\n";
    }
    std::cout << backend::summarize(*result);
    std::cout << "output: " << std::filesystem::absolute(o.out).string()
              << " (report.html, metrics.json, mesh.ply, layout.json, floorplan.svg)\n";
    return kExitOk;
}

PLUMB_COMMAND(reconstruct, "reconstruct",
              "reconstruct a room from a dataset or the simulated scanner", runReconstruct);

}  // namespace plumb::tools
