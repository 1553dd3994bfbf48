// SPDX-License-Identifier: Apache-2.0
// `plumb reconstruct`: the whole pipeline in one process on a recorded dataset or the simulated
// scanner — fusion into fragments (as the device would), then the backend (registration, layout,
// layout-constrained global registration, final model, evaluation, report).

#include <fmt/format.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
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
#include "common/frame/frame_recorder.hpp"
#include "common/io/trajectory.hpp"
#include "common/layout/layout.hpp"
#include "device/fusion/fusion_config.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tools/plumb/command.hpp"
#include "tools/plumb/interrupt.hpp"
#include "tools/plumb/output_folder.hpp"
#include "tools/plumb/reconstruct_fusion.hpp"
#include "tools/plumb/run_record.hpp"
#include "tools/plumb/scan_source.hpp"
#include "tools/plumb/self_calibrated_run.hpp"
#include "tools/plumb/source_arguments.hpp"

namespace plumb::tools {

/// The configuration of `plumb reconstruct` (and of the backend half of `plumb demo`).
struct ReconstructConfig {
    device::FusionConfig fusion;
    backend::PipelineConfig pipeline;
    SelfCalibrateConfig self_calibration;
    /// Memory, MB, for keeping the frames read by tracking and fusion, so that the final model
    /// re-integrates them without reading (decoding, rendering) them again: about 2.4 MB a
    /// 640x480 frame with colour, 4096 MB holds a 1700-frame scan. A longer scan is read again;
    /// 0 always reads again. The result is the same either way. `--self-calibrate` keeps the raw
    /// frames within the same budget for all its passes (tools/plumb/scan_cache.hpp).
    int keep_frames_mb = 4096;
};

void describe(config::Schema& s, ReconstructConfig& c) {
    s.section("fusion", c.fusion, "tracking and fusion into fragments (as on the device)");
    s.section("pipeline", c.pipeline, "the backend: registration, layout, global registration");
    s.section("self_calibration", c.self_calibration,
              "--self-calibrate: learning the depth distortion table from the scan");
    s.field("keep_frames_mb", c.keep_frames_mb,
            "memory (MB) for keeping the tracked frames for the final model instead of reading "
            "them again (with --self-calibrate also the raw frames, for all its passes); a "
            "longer scan is read again, 0 = always")
        .min(0);
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
    "layout.json, floorplan.svg, mesh.ply, metrics.json, report.html, config.toml, and the\n"
    "fragments as the device would send them (fragments/); the --no-layout baseline goes to\n"
    "DIR/baseline for comparison.\n"
    "\n"
    "Ctrl-C (or SIGTERM) stops at the next frame, or after the backend stage running: the\n"
    "fragments fused so far, the trajectory tracked so far (trajectory.txt) and metrics.json\n"
    "with \"status\": \"interrupted\" are kept, and `plumb reconstruct --resume DIR` continues\n"
    "the run, giving the same outputs byte for byte as a run never interrupted. A second\n"
    "Ctrl-C stops at once.\n"
    "\n"
    "source:\n"
    "  DIR | dataset:DIR  a TUM, ICL-NUIM, Redwood, 7-Scenes or plumb-sim folder (detected)\n"
    "  sim:SCENE          the simulated scanner (living_room, weak_manhattan, l_shape,\n"
    "                     corridor, or a scene .toml file)\n"
    "  store:DIR[?session=ID]  the raw frames plumb-backend kept of a live scan in its\n"
    "                     fragment store DIR (streamed with plumb-device --set\n"
    "                     stream.raw_frame_every=1; the newest session unless named)\n"
    "\n"
    "options:\n"
    "  --out DIR          output folder (required; created when missing). A folder that\n"
    "                     is not empty is refused, so that no earlier run's files mix in\n"
    "  --force            clear a non-empty --out folder of an earlier plumb run first\n"
    "  --resume DIR       continue the run interrupted in DIR, with its options; only\n"
    "                     --quiet and --threads may be given besides (default: a new run)\n"
    "  --no-layout        the Choi-style baseline only (registration without layout)\n"
    "  --no-baseline      do not also compute the baseline for comparison\n"
    "  --frames N         use the first N frames only (default: all; the simulator 600)\n"
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
    "  --self-calibrate   learn the depth distortion table from the scan itself: learn the\n"
    "                     bend of the depth from each frame's planes (no poses), reconstruct\n"
    "                     with it (into DIR/self_calibration/first), estimate the table\n"
    "                     against that model at the frames' poses (reference §7c), learn the\n"
    "                     bend left after that table from the planes again, then reconstruct\n"
    "                     with the result; writes DIR/depth_calibration.txt (use it with\n"
    "                     --depth-calibration for later scans by the same camera) and its\n"
    "                     coverage and before/after figures into metrics.json and the report.\n"
    "                     When the planes do not determine the bend (too few views, one\n"
    "                     corner), no table is learned and the raw depth is reconstructed,\n"
    "                     with a warning. Takes about 3x the time; excludes\n"
    "                     --depth-calibration. --set self_calibration.rounds=2 adds a\n"
    "                     second round (a reconstruction with the first round's table,\n"
    "                     the table refined at its poses): more accurate, about 4x\n"
    "                     the time of a plain run\n"
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
    "command line, 130 interrupted (the work so far kept; see --resume).\n";

constexpr const char* kCommand = "reconstruct";
/// The run record's note that a run is --self-calibrate (which --resume does not continue).
constexpr const char* kSelfCalibrateKey = "self_calibrate";

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
    bool force = false;
};

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

/// The raw frames for the final model, stopping (kCancelled) once Ctrl-C asked to.
class StoppableSource : public FrameSourceDecorator {
  public:
    using FrameSourceDecorator::FrameSourceDecorator;
    Result<Frame> next() override {
        if (InterruptScope::requested()) return cancelled("stopped on request");
        return inner().next();
    }
    Status skip() override {
        if (InterruptScope::requested()) return cancelled("stopped on request");
        return inner().skip();
    }
};

/// What an interrupted run keeps in `out`: the fusion checkpoint (resume/), the trajectory tracked
/// so far, and metrics.json saying where it stopped.
Status writeInterrupted(const std::filesystem::path& out, const FusionPass& pass,
                        const std::string& stage) {
    PLUMB_RETURN_IF_ERROR(pass.checkpoint());
    PLUMB_RETURN_IF_ERROR(io::writeTumTrajectory(out / "trajectory.txt", pass.tracked()));
    const FusionCounts& c = pass.counts();
    nlohmann::json m;
    m["format"] = "plumb-metrics-1";
    m["status"] = "interrupted";
    m["stage"] = stage;
    m["frames_read"] = c.read;
    m["frames_fused"] = c.fused;
    m["frames_tracking_failed"] = c.lost;
    m["fusion_finished"] = pass.finished();
    m["fragments_stored"] = pass.fragmentsStored();
    m["trajectory"] = fmt::format("trajectory.txt: the odometry of the {} frames tracked so far",
                                  pass.tracked().size());
    m["resume"] = resumeCommand(kCommand, out);
    return writeTextFileAtomic(out / "metrics.json", m.dump(2) + "\n");
}

/// Fusion of `source` (opened from `uri` with `source_options`) into fragments, then the backend
/// into `out`; with `resume`, the fusion continues from the checkpoint in `out`. kCancelled when
/// Ctrl-C stopped it, after writing what an interrupted run keeps.
Result<backend::PipelineResult> reconstructOnce(FrameSource& source, const std::string& uri,
                                                const SourceOptions& source_options,
                                                const ReconstructConfig& cfg,
                                                const backend::PipelineConfig& pipeline,
                                                backend::PipelineInput input,
                                                const std::filesystem::path& out,
                                                const Options& options, bool resume = false) {
    Result<std::unique_ptr<FusionPass>> opened =
        resume ? FusionPass::resume(out, source, source.camera(), cfg.fusion, options.frame_step)
               : FusionPass::start(out, source.camera(), cfg.fusion, options.frame_step);
    if (!opened.isOk()) return opened.status();
    FusionPass& pass = **opened;
    if (resume) {
        log::info("resuming after frame {} ({} fragments stored{})", pass.counts().read,
                  pass.fragmentsStored(), pass.finished() ? ", tracking and fusion done" : "");
    }
    // The frames are kept for the final model when this pass reads the whole scan.
    std::optional<FrameRecorder> recorder;
    if (!resume) recorder.emplace(source, static_cast<size_t>(cfg.keep_frames_mb) * 1000000);
    FrameSource& fused_from = recorder ? static_cast<FrameSource&>(*recorder) : source;
    const auto tracking_start = std::chrono::steady_clock::now();
    Result<bool> finished = pass.run(fused_from, InterruptScope::requested, options.quiet);
    if (!finished.isOk()) return finished.status();
    // This invocation's tracking and fusion (after a resume: only the frames read now).
    input.tracking_fusion_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - tracking_start).count();
    if (!*finished) {
        PLUMB_RETURN_IF_ERROR(writeInterrupted(out, pass, "tracking and fusion"));
        return cancelled(
            fmt::format("during tracking and fusion, after {} frames", pass.counts().read));
    }
    PLUMB_RETURN_IF_ERROR(pass.checkpoint());  // a resume from here goes straight to the backend
    Result<std::vector<Fragment>> fragments = pass.fragments();
    if (!fragments.isOk()) return fragments.status();
    // Poses the source reads with its frames (7-Scenes' per-frame files, a dataset's
    // groundtruth.txt) are scored when the folder has no trajectory file of its own.
    if (!options.no_gt && !input.ground_truth.trajectory && !pass.posesRead().empty()) {
        std::string& d = input.ground_truth.description;
        const std::string what =
            fmt::format("the poses read with {} frames", pass.posesRead().size());
        d = (d.empty() || d == "none") ? what : d + "; " + what;
        input.ground_truth.trajectory = pass.posesRead();
    }
    input.fragments = std::move(*fragments);
    log::info("{} fragments fused", input.fragments.size());
    std::shared_ptr<const std::vector<Frame>> kept = recorder ? recorder->take() : nullptr;
    if (recorder && !kept && cfg.keep_frames_mb > 0) {
        log::info("the final model reads the frames again: {}", recorder->droppedBecause());
    }
    recorder.reset();
    const PinholeCamera camera = source.camera();
    const std::string description = source.description();
    input.open_raw_frames = [uri, source_options, kept, camera,
                             description]() -> Result<std::unique_ptr<FrameSource>> {
        if (kept) {
            return std::unique_ptr<FrameSource>(new StoppableSource(std::make_unique<ReplaySource>(
                kept, camera, "the frames kept from " + description)));
        }
        Result<std::unique_ptr<FrameSource>> raw = openScanSource(uri, source_options);
        if (!raw.isOk()) return raw.status();
        return std::unique_ptr<FrameSource>(new StoppableSource(std::move(*raw)));
    };
    input.stop_requested = InterruptScope::requested;
    Result<backend::PipelineResult> result =
        backend::runPipeline(input, pipeline, out, !options.quiet);
    if (!result.isOk() && result.status().code() == StatusCode::kCancelled) {
        PLUMB_RETURN_IF_ERROR(writeInterrupted(out, pass, "backend"));
        return cancelled("in the backend (" + result.status().message() + ")");
    }
    return result;
}

/// Parses a command line (without --resume) into `*o`; nullopt to go on, else the exit status.
std::optional<int> parseOptions(const std::vector<std::string>& args, Options* o) {
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        bool source_option = false;
        if (std::optional<int> rc =
                parseSourceOption(kCommand, args, &i, &o->source_options, &source_option))
            return rc;
        if (source_option) {
            if (a == "--depth-calibration") o->depth_calibration_given = true;
            continue;
        }
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
            o->out = v;
        } else if (a == "--no-layout") {
            o->no_layout = true;
        } else if (a == "--no-baseline") {
            o->no_baseline = true;
        } else if (a == "--frame-step") {
            if (!value(&v) || !parseNumber(v, &o->frame_step) || !(o->frame_step >= 1.0))
                return usageError(kCommand, "--frame-step needs a number >= 1");
        } else if (a == "--self-calibrate") {
            o->self_calibrate = true;
        } else if (a == "--gt") {
            if (!value(&v)) return usageError(kCommand, "--gt needs a folder");
            o->gt_dir = v;
        } else if (a == "--no-gt") {
            o->no_gt = true;
        } else if (a == "--threads") {
            if (!value(&v) || !parseNumber(v, &o->threads) || o->threads < 1)
                return usageError(kCommand, "--threads needs a positive integer");
        } else if (a == "--quiet") {
            o->quiet = true;
        } else if (a == "--force") {
            o->force = true;
        } else if (a == "--resume") {
            return usageError(kCommand, "--resume DIR comes without a source and other options");
        } else if (!a.empty() && a[0] == '-') {
            return usageError(kCommand, "unknown option " + a);
        } else if (o->source.empty()) {
            o->source = a;
        } else {
            return usageError(kCommand, "more than one source given: " + o->source + " and " + a);
        }
    }
    if (o->source.empty()) return usageError(kCommand, "no source given");
    if (o->out.empty()) return usageError(kCommand, "--out is required");
    if (o->self_calibrate && o->depth_calibration_given)
        return usageError(
            kCommand, "--self-calibrate learns the depth calibration: drop --depth-calibration");
    return std::nullopt;
}

}  // namespace

int runReconstruct(const std::vector<std::string>& arguments) {
    std::vector<std::string> args = arguments;
    // --resume DIR: the interrupted run's own command line, in its working folder.
    ResumeArguments resumed;
    std::optional<RunRecord> record;
    if (std::find(args.begin(), args.end(), "--resume") != args.end()) {
        RunRecord r;
        if (std::optional<int> rc = beginResume(kCommand, kUsage, args, &resumed, &r)) return *rc;
        if (const auto sc = r.details.find(kSelfCalibrateKey);
            sc != r.details.end() && *sc == true) {
            return usageError(kCommand,
                              "--resume does not continue a --self-calibrate run; run it "
                              "again (with --force)");
        }
        args = r.arguments;
        record = std::move(r);
    }
    Result<config::ConfigArgs> config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(kCommand, config_args.status().message());
    Options o;
    if (std::optional<int> rc = parseOptions(args, &o)) return *rc;
    if (record) {
        o.out = resumed.dir;
        o.quiet = o.quiet || resumed.quiet;
        if (resumed.threads > 0) o.threads = resumed.threads;
    }

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

    const std::string uri = normaliseScanUri(o.source);
    if (!o.source_options.sim_noise.empty() && uri.rfind("sim:", 0) != 0) {
        return usageError(kCommand, "--noise applies to sim: sources only");
    }
    if (Status s = checkScanSourceArguments(uri, o.source_options); !s.isOk())
        return usageError(kCommand, s.message());
    if (Status s = calibration::validate(cfg.self_calibration.estimate);
        o.self_calibrate && !s.isOk())
        return usageError(kCommand, s.message());
    const std::string config_toml =
        config::toToml(cfg, "plumb reconstruct: effective configuration");
    if (record && record->config_toml != config_toml) {
        return usageError(kCommand,
                          "--resume: the configuration differs from the interrupted "
                          "run's (was its --config file changed?)");
    }
    if (!record) {
        if (Status s = prepareOutputFolder(o.out, o.force); !s.isOk())
            return usageError(kCommand, s.message());
        RunRecord r{arguments,
                    std::filesystem::current_path(),
                    config_toml,
                    {{kSelfCalibrateKey, o.self_calibrate}}};
        if (Status s = writeRunRecord(o.out, kCommand, r); !s.isOk()) return failure(kCommand, s);
    }
    InterruptScope interrupt("plumb reconstruct");
    SourceOptions first_options = o.source_options;
    if (o.self_calibrate) first_options.depth_calibration = "none";
    Result<std::unique_ptr<FrameSource>> source = openScanSource(uri, first_options);
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
            // A store holds no ground truth: only --gt gives one.
            if (o.gt_dir || !isStoreUri(uri)) {
                const std::filesystem::path dir =
                    o.gt_dir ? *o.gt_dir : std::filesystem::path(uri.substr(uri.find(':') + 1));
                Result<backend::GroundTruth> gt = backend::loadGroundTruth(dir);
                if (!gt.isOk()) return failure(kCommand, gt.status());
                base.ground_truth = std::move(*gt);
            }
        }
    }
    base.config_toml = config_toml;
    base.command_line = std::string("plumb ") + kCommand;
    for (const std::string& a : arguments)
        base.command_line +=
            " " + (a.find_first_of(" \t'\"") == std::string::npos ? a : "'" + a + "'");

    // One reconstruction of the scan, as the self-calibration's passes make them.
    const ReconstructFn reconstruct = [&](FrameSource& from, const SourceOptions& options,
                                          const backend::PipelineConfig& pipeline,
                                          backend::PipelineInput input,
                                          const std::filesystem::path& dir) {
        return reconstructOnce(from, uri, options, cfg, pipeline, std::move(input), dir, o);
    };
    Result<backend::PipelineResult> result =
        o.self_calibrate
            ? selfCalibratedRun(**source, cfg.self_calibration,
                                {uri, o.source_options, cfg.pipeline,
                                 static_cast<size_t>(cfg.keep_frames_mb) * 1000000, o.out},
                                base, reconstruct)
            : reconstructOnce(**source, uri, o.source_options, cfg, cfg.pipeline, base, o.out, o,
                              record.has_value());
    if (!result.isOk() && result.status().code() == StatusCode::kCancelled) {
        std::cerr << fmt::format(
            "plumb reconstruct: interrupted {}; the work so far is kept in {}{}\n",
            result.status().message(), o.out.string(),
            o.self_calibrate ? " (a --self-calibrate run cannot be resumed)"
                             : "; continue with: " + resumeCommand(kCommand, o.out));
        return kExitInterrupted;
    }
    if (!result.isOk()) return failure(kCommand, result.status());
    removeResumeFolder(o.out);  // complete: nothing left to resume
    if (o.self_calibrate) {
        std::cout << selfCalibrationSummary(
            result->metrics.value("self_calibration", nlohmann::json::object()), o.out);
    }
    std::cout << backend::summarize(*result);
    std::cout << "output: " << std::filesystem::absolute(o.out).string()
              << " (report.html, metrics.json, mesh.ply, layout.json, floorplan.svg)\n";
    return kExitOk;
}

PLUMB_COMMAND(reconstruct, "reconstruct",
              "reconstruct a room from a dataset or the simulated scanner", runReconstruct);

}  // namespace plumb::tools
