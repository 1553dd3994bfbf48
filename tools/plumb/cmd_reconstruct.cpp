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
#include "common/calibration/distortion_table.hpp"
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
#include "tools/plumb/calibration_aligner.hpp"
#include "tools/plumb/command.hpp"
#include "tools/plumb/interrupt.hpp"
#include "tools/plumb/output_folder.hpp"
#include "tools/plumb/planar_stage.hpp"
#include "tools/plumb/pose_lookup.hpp"
#include "tools/plumb/reconstruct_fusion.hpp"
#include "tools/plumb/run_record.hpp"
#include "tools/plumb/scan_cache.hpp"
#include "tools/plumb/source_arguments.hpp"

namespace plumb::tools {

/// `--self-calibrate`: how the depth distortion table is learned from the scan.
struct SelfCalibrateConfig {
    /// First learn the bend of the depth from each frame's planes, without poses
    /// (estimate.planar), and make the first reconstruction with that table; off: the first
    /// reconstruction is from the raw depth. On 600-frame simulated scans the planar table
    /// alone takes the raw depth's ATE from 13.8 to 3.2 cm (BENCHMARKS.md).
    bool planar = true;
    /// Every frame_step-th frame of the scan is compared with the model (each frame is held in
    /// memory twice, with up to 8 bytes per compared pixel). Every frame: on 600-frame
    /// simulated scans of three rooms, every second frame gave 15-51 % more ATE (BENCHMARKS.md).
    int frame_step = 1;
    /// ... but at most this many frames: a longer scan is compared at the smallest larger step
    /// that keeps it within (about 5 MB a 640x480 frame, 4.4 GB for 900; 0 = no limit).
    int max_frames = 900;
    /// Re-align every compared frame to each iteration's model by frame-to-model ICP before
    /// comparing it. Off: on a 600-frame living_room scan it made the learned table no better
    /// (median error at 3 m 0.66 % against 0.60 % with the reconstruction's poses) at 5x the
    /// time of the estimate (BENCHMARKS.md).
    bool refine_poses = false;
    /// The alternation starts from the table the first reconstruction was made with (the
    /// planar stage's, when it determined one) instead of the neutral table. On nine 600-frame
    /// simulated loops it then stops after 4 iterations instead of 5-8, with less ATE on eight
    /// of them (BENCHMARKS.md, "Self-calibration from the planar table").
    bool warm_start = true;
    /// The first reconstruction's final mesh integrates every k-th raw frame only: the estimate
    /// uses its poses, and its mesh gives the "before" figure alone.
    int first_model_frame_stride = 4;
    /// Rounds of reconstruction and refinement before the final reconstruction. Round 1
    /// reconstructs with the planar table (self_calibration/first) and refines the table at its
    /// poses; each further round reconstructs with the last round's table (into
    /// self_calibration/roundK, like the first: no baseline, the coarser mesh) and refines the
    /// table at those poses, starting from it. A learned table tracks better than the planar
    /// one, and the table refined at better poses learns less of their error: on nine 600-frame
    /// simulated loops two rounds gave 14 % less ATE and 8 % less reconstruction error than
    /// one, at 3.96x a plain run's time against 2.89x; a third helped only the L-shaped room
    /// (BENCHMARKS.md, "Self-calibration in two rounds").
    int rounds = 1;
    /// The estimator and its alternation (as `plumb calibrate`).
    calibration::SelfCalibrationConfig estimate;
};

void describe(config::Schema& s, SelfCalibrateConfig& c) {
    s.field("planar", c.planar,
            "first learn the bend from each frame's planes (no poses) and make the first "
            "reconstruction with it; off: the first reconstruction is from the raw depth");
    s.field("frame_step", c.frame_step,
            "every frame_step-th frame of the scan is compared with the model")
        .min(1);
    s.field("max_frames", c.max_frames,
            "at most this many frames are compared: a longer scan at the smallest larger step "
            "that keeps within it (memory: about 5 MB a 640x480 frame); 0 = no limit")
        .min(0);
    s.field("refine_poses", c.refine_poses,
            "re-align every compared frame to each iteration's model by frame-to-model ICP");
    s.field("warm_start", c.warm_start,
            "the alternation starts from the table the first reconstruction was made with (the "
            "planar stage's) instead of the neutral table");
    s.field("first_model_frame_stride", c.first_model_frame_stride,
            "the first reconstruction's final mesh integrates every k-th raw frame (its poses "
            "are what the estimate uses)")
        .min(1);
    s.field("rounds", c.rounds,
            "rounds of reconstruction and refinement: each round after the first reconstructs "
            "with the last round's table (into self_calibration/roundK) and refines the table at "
            "those poses; each costs about one reconstruction and a shorter estimate more")
        .range(1, 4);
    s.section("estimate", c.estimate, "the table estimate and its alternation (reference §7c)");
}

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
        Result<std::unique_ptr<FrameSource>> raw = openFrameSource(uri, source_options);
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

/// What the planar stage learned: its iterations and the planes' residual before and after, and
/// the right angles' offset when that step ran.
nlohmann::json planarFigures(const PlanarStage& p) {
    nlohmann::json iterations = nlohmann::json::array();
    for (const calibration::PlanarIteration& it : p.estimate.iterations) {
        iterations.push_back({{"segments", it.segments},
                              {"blocks", it.blocks},
                              {"residual_sigmas", it.rms_sigmas},
                              {"max_change", it.max_change}});
    }
    nlohmann::json out = {{"frames", p.estimate.frames},
                          {"iterations", iterations},
                          {"split_disagreement", p.estimate.split_disagreement},
                          {"cells_with_data", p.estimate.cells_with_data},
                          {"removed_depth_scale_per_m", p.estimate.removed_depth_scale_per_m}};
    if (p.right_angles) {
        const calibration::RightAngleEstimate& r = *p.right_angles;
        const calibration::DisparityOffset& d = r.delta;
        out["right_angles"] = {{"disparity_offset_1m_per_m", {d.near.x(), d.near.y(), d.near.z()}},
                               {"disparity_offset_3m_per_m", {d.far.x(), d.far.y(), d.far.z()}},
                               {"perpendicular_pairs", r.perpendicular},
                               {"parallel_pairs", r.parallel},
                               {"frames", r.frames},
                               {"residual_before_deg", r.rms_before_deg},
                               {"residual_after_deg", r.rms_after_deg}};
    } else if (!p.right_angles_skipped.empty()) {
        out["right_angles"] = {{"skipped", p.right_angles_skipped}};
    }
    return out;
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

/// `--self-calibrate`: the bend learned from the planes of the scan's frames undistorted by
/// `undistort` ("none": the raw frames), composed with that table and written to `path`.
Result<PlanarStage> planarStage(const ScanCache& scan, const SelfCalibrateConfig& sc,
                                const std::string& undistort, const std::filesystem::path& path) {
    Result<std::unique_ptr<FrameSource>> source = scan.open(undistort, /*colour=*/false);
    if (!source.isOk()) return source.status();
    calibration::RightAngleConfig right_angles = sc.estimate.right_angles;
    if (undistort == "none" && !right_angles.first_pass) right_angles.enabled = false;
    Result<PlanarStage> planar = learnPlanarTable(
        **source, sc.estimate.planar, right_angles, [](const calibration::PlanarIteration& it) {
            log::info(
                "self-calibration, planes, iteration {}: {} planar segments ({} blocks), "
                "residual {:.2f} noise sigmas, largest change {:.5f}",
                it.iteration + 1, it.segments, it.blocks, it.rms_sigmas, it.max_change);
        });
    if (!planar.isOk()) return prefixed(planar.status(), "self-calibration, planes");
    if (planar->estimate.cells_with_data > 0) {
        log::info(
            "self-calibration, planes: the scale growing with depth over the {} cells with depth "
            "was {:+.4f} %/m; removed (no later stage observes it)",
            planar->estimate.cells_with_data, 100.0 * planar->estimate.removed_depth_scale_per_m);
    }
    if (undistort != "none") {
        Result<DistortionTable> first = DistortionTable::load(undistort);
        if (!first.isOk()) return first.status();
        planar->table = composeTables(*first, planar->table);
    }
    std::error_code ec;
    std::filesystem::create_directories(path.parent_path(), ec);
    if (Status s = planar->table.save(path); !s.isOk()) return s;
    return planar;
}

/// The refinement of `--self-calibrate`: the table estimated at the poses of the
/// reconstruction in `recon_dir` (reference §7c), starting from `initial` (null: the neutral
/// table; `initial_name` names it in the log), written to `refined_path`, then the bend left in
/// the frames it undistorts learned from the planes (self_calibration.planar) and composed with
/// it; the resulting table (the product, or the refined table when the planes do not determine
/// the bend) is written to `table_path`.
struct Refinement {
    calibration::SelfCalibrationResult learned;
    nlohmann::json iterations = nlohmann::json::array();
    size_t frames = 0;
    int64_t frame_step = 1;  ///< the step the frames were compared at (max_frames)
    size_t unaligned = 0;
    std::optional<PlanarStage> planar;  ///< the bend left after the refined table
};

Result<Refinement> refineAtPoses(const ScanCache& scan, const SelfCalibrateConfig& sc,
                                 const PinholeCamera& camera, const DistortionTable* initial,
                                 const std::filesystem::path& recon_dir,
                                 const std::filesystem::path& refined_path,
                                 const std::filesystem::path& table_path,
                                 const std::string& step_refine, const std::string& step_planar,
                                 const std::string& initial_name) {
    Refinement out;
    Result<PoseLookup> poses = PoseLookup::read(recon_dir / "trajectory.txt");
    if (!poses.isOk()) return poses.status();
    // The raw frames at the reconstruction's poses.
    Result<std::unique_ptr<FrameSource>> source = scan.open("none", /*colour=*/false);
    if (!source.isOk()) return source.status();
    out.frame_step = sc.frame_step;
    if (sc.max_frames > 0) {
        const auto limit = static_cast<size_t>(sc.max_frames);
        out.frame_step = std::max<int64_t>(
            out.frame_step, static_cast<int64_t>((poses->size() + limit - 1) / limit));
    }
    Result<PosedDepth> posed = readPosedDepth(**source, *poses, out.frame_step);
    if (!posed.isOk()) return posed.status();
    const std::vector<DepthImage>& depth = posed->depth;  // frames not tracked have no pose
    out.frames = depth.size();
    log::info(
        "self-calibration {}: estimating the depth distortion table from {} frames (frame step "
        "{}) at the poses of {}, starting from {}",
        step_refine, depth.size(), out.frame_step, recon_dir.string(),
        initial != nullptr ? initial_name : "the neutral table");
    auto observe = [&](const calibration::CalibrationIteration& it) {
        const calibration::DistortionEstimate& e = it.estimate;
        log::info(
            "self-calibration iteration {}: change median {:.5f} max {:.5f}; cells covered per "
            "bin (1/3/5/7/9 m) {} {} {} {} {} of 6400",
            it.iteration + 1, e.median_change, e.max_change, e.covered_cells[0], e.covered_cells[1],
            e.covered_cells[2], e.covered_cells[3], e.covered_cells[4]);
        out.iterations.push_back({{"change_median", e.median_change},
                                  {"change_max", e.max_change},
                                  {"covered_cells", e.covered_cells}});
    };
    const calibration::FrameAligner aligner =
        sc.refine_poses ? icpFrameAligner(CalibrationAlignerConfig{}, &out.unaligned)
                        : calibration::FrameAligner{};
    Result<calibration::SelfCalibrationResult> learned = calibration::selfCalibrate(
        depth, camera, posed->T_W_C, sc.estimate, initial, observe, aligner);
    if (!learned.isOk()) return prefixed(learned.status(), "self-calibration");
    out.learned = std::move(*learned);
    std::error_code ec;
    std::filesystem::create_directories(refined_path.parent_path(), ec);
    if (Status s = out.learned.table.save(refined_path); !s.isOk()) return s;
    log::info("self-calibration: {} after {} iterations; table written to {}",
              out.learned.converged ? "converged" : "stopped at the iteration limit",
              out.learned.iterations.size(), refined_path.string());
    // The refinement learns the table's cell-to-cell structure, but at poses that still carry
    // the reconstruction's error, which bends it back; the bend left in the frames it
    // undistorts is what the planes show.
    if (sc.planar) {
        log::info(
            "self-calibration {}: learning the bend left in the frames the refined table "
            "undistorts",
            step_planar);
        Result<PlanarStage> p = planarStage(scan, sc, refined_path.string(), table_path);
        if (p.isOk()) {
            out.planar = std::move(*p);
        } else if (p.status().code() == StatusCode::kFailedPrecondition) {
            log::warn("{}; the refined table is used as it is", p.status().message());
        } else {
            return p.status();
        }
    }
    if (!out.planar) {
        if (Status s = out.learned.table.save(table_path); !s.isOk()) return s;
    }
    return out;
}

/// `--self-calibrate`: a first reconstruction (`raw_source`, opened without depth calibration,
/// or with the bend learned from the frames' planes when self_calibration.planar), the table
/// refined at its poses with the bend left after it (refineAtPoses), and the reconstruction
/// with that table into o.out.
Result<backend::PipelineResult> selfCalibratedRun(FrameSource& raw_source, const std::string& uri,
                                                  const Options& o, const ReconstructConfig& cfg,
                                                  const backend::PipelineInput& base) {
    const auto start = std::chrono::steady_clock::now();
    auto seconds = [&start] {
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
    const SelfCalibrateConfig& sc = cfg.self_calibration;
    const std::filesystem::path folder = o.out / "self_calibration";
    int step = 0;
    // The passes: the planes, three per round (reconstruction, estimate, planes again), the
    // final reconstruction.
    const int passes = 2 + 3 * sc.rounds;
    auto next = [&step, passes] { return fmt::format("{}/{}", ++step, passes); };
    SourceOptions raw_options = o.source_options;
    raw_options.depth_calibration = "none";
    // Every pass below reads the scan: the raw frames are read once and replayed to each.
    log::info("self-calibration: reading the scan once for its {} passes (at most {} MB kept)",
              passes, cfg.keep_frames_mb);
    Result<ScanCache> scan = ScanCache::read(raw_source, uri, raw_options,
                                             static_cast<size_t>(cfg.keep_frames_mb) * 1000000,
                                             InterruptScope::requested);
    if (!scan.isOk()) return scan.status();
    if (scan->complete()) {
        log::info("self-calibration: the scan's {} raw frames are kept for every pass",
                  scan->frames());
    } else {
        log::info("self-calibration: every pass reads the scan again: {}", scan->notKeptBecause());
    }
    std::optional<PlanarStage> planar;
    Result<std::unique_ptr<FrameSource>> opened = scan->open("none");
    if (!opened.isOk()) return opened.status();
    std::unique_ptr<FrameSource> first_source = std::move(*opened);
    SourceOptions first_options = raw_options;
    const std::string planar_step = next();
    if (sc.planar) {
        const std::filesystem::path planar_path = folder / "planar_table.txt";
        log::info("self-calibration {}: learning the bend of the depth from each frame's planes",
                  planar_step);
        Result<PlanarStage> p = planarStage(*scan, sc, "none", planar_path);
        if (p.isOk()) {
            planar = std::move(*p);
            first_options.depth_calibration = planar_path.string();
            opened = scan->open(first_options.depth_calibration);
            if (!opened.isOk()) return opened.status();
            first_source = std::move(*opened);
        } else if (p.status().code() == StatusCode::kFailedPrecondition) {
            // Without the bend, a table refined at poses tracked from the raw depth learns the
            // poses' error as much as the camera's (BENCHMARKS.md, real data): no table is
            // learned, and the raw depth is reconstructed once.
            log::warn("{}; no table is learned, the reconstruction uses the raw depth",
                      p.status().message());
            backend::PipelineInput input = base;
            input.self_calibration = {{"status", "not_determined"},
                                      {"reason", p.status().message()},
                                      {"table", nullptr},
                                      {"planar", nullptr}};
            return reconstructOnce(*first_source, uri, raw_options, cfg, cfg.pipeline,
                                   std::move(input), o.out, o);
        } else {
            return p.status();
        }
    }
    backend::PipelineConfig first = cfg.pipeline;
    first.compare_baseline = false;
    first.final_model.frame_stride =
        std::max(first.final_model.frame_stride, sc.first_model_frame_stride);
    const std::filesystem::path table_path = o.out / "depth_calibration.txt";
    // Round r reconstructs with `recon_options`' table into its folder, refines the table at
    // those poses from `refine_from` and learns the bend left from the planes; the last round's
    // table is the result.
    SourceOptions recon_options = first_options;
    std::unique_ptr<FrameSource> recon_source = std::move(first_source);
    std::optional<DistortionTable> last_table;
    const DistortionTable* refine_from = sc.warm_start && planar ? &planar->table : nullptr;
    std::optional<backend::PipelineResult> before;
    double first_seconds = 0.0;
    std::optional<Refinement> refined;
    std::filesystem::path refined_path;  // the last round's refined table
    nlohmann::json rounds = nlohmann::json::array();
    auto relative = [&o](const std::filesystem::path& p) {
        return p.lexically_relative(o.out).generic_string();
    };
    for (int round = 1; round <= sc.rounds; ++round) {
        const bool last_round = round == sc.rounds;
        const std::string name = round == 1 ? "first" : fmt::format("round{}", round);
        const std::filesystem::path recon_dir = folder / name;
        const double round_start = seconds();
        if (!recon_source) {
            opened = scan->open(recon_options.depth_calibration);
            if (!opened.isOk()) return opened.status();
            recon_source = std::move(*opened);
        }
        log::info("self-calibration {}: reconstructing {} into {}", next(),
                  round == 1 ? (planar ? "from the planar-corrected depth" : "from the raw depth")
                             : fmt::format("with round {}'s table", round - 1),
                  recon_dir.string());
        Result<backend::PipelineResult> recon =
            reconstructOnce(*recon_source, uri, recon_options, cfg, first, base, recon_dir, o);
        recon_source.reset();
        if (!recon.isOk())
            return prefixed(recon.status(),
                            round == 1 ? std::string("self-calibration, first reconstruction")
                                       : fmt::format("self-calibration, round {}", round));
        const nlohmann::json figures = mainFigures(*recon);
        if (round == 1) {
            before = std::move(*recon);
            first_seconds = seconds();
        }
        const std::string prefix = round == 1 ? "" : fmt::format("round{}_", round);
        refined_path = folder / (prefix + "refined_table.txt");
        const std::filesystem::path round_table =
            last_round ? table_path : folder / fmt::format("round{}_table.txt", round);
        const std::string refine_step = next();
        const std::string planar_step = next();
        Result<Refinement> r = refineAtPoses(
            *scan, sc, base.camera, refine_from, recon_dir, refined_path, round_table, refine_step,
            planar_step,
            round == 1 ? "the planar table" : fmt::format("round {}'s table", round - 1));
        if (!r.isOk()) return r.status();
        refined = std::move(*r);
        Result<DistortionTable> learned = DistortionTable::load(round_table.string());
        if (!learned.isOk()) return learned.status();
        last_table = std::move(*learned);
        refine_from = &*last_table;
        recon_options.depth_calibration = round_table.string();
        rounds.push_back({{"round", round},
                          {"reconstruction", relative(recon_dir)},
                          {"reconstruction_figures", figures},
                          {"iterations", refined->iterations.size()},
                          {"converged", refined->learned.converged},
                          {"refined_table", relative(refined_path)},
                          {"table", relative(round_table)},
                          {"seconds", seconds() - round_start}});
    }
    const calibration::DistortionEstimate& last = refined->learned.iterations.back().estimate;

    log::info("self-calibration {}: reconstructing with the learned table", next());
    backend::PipelineInput input = base;
    input.self_calibration = {
        {"status", "learned"},
        {"table", table_path.filename().string()},
        {"frames", refined->frames},
        {"frame_step", refined->frame_step},
        {"refine_poses", sc.refine_poses},
        {"warm_start", sc.warm_start && planar},
        {"frames_not_aligned", refined->unaligned},
        {"rounds", sc.rounds},
        {"round_results", rounds},
        {"iterations", refined->iterations},
        {"converged", refined->learned.converged},
        {"covered_cells", last.covered_cells},
        {"gauge_bin_m", DistortionTable::binCentreM(last.gauge_bin)},
        {"gauge_scale", last.gauge_scale},
        {"first_table", planar ? "self_calibration/planar_table.txt" : "none"},
        {"planar", planar ? planarFigures(*planar) : nlohmann::json(nullptr)},
        {"refined_table", relative(refined_path)},
        {"final_planar",
         refined->planar ? planarFigures(*refined->planar) : nlohmann::json(nullptr)},
        {"first_reconstruction", "self_calibration/first"},
        {"before", mainFigures(*before)},
        {"first_reconstruction_seconds", first_seconds},
        {"estimate_seconds", seconds() - first_seconds}};
    SourceOptions calibrated = o.source_options;
    calibrated.depth_calibration = table_path.string();
    Result<std::unique_ptr<FrameSource>> calibrated_source = scan->open(table_path.string());
    if (!calibrated_source.isOk()) return calibrated_source.status();
    return reconstructOnce(**calibrated_source, uri, calibrated, cfg, cfg.pipeline,
                           std::move(input), o.out, o);
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

    const std::string uri = normaliseUri(o.source);
    if (!o.source_options.sim_noise.empty() && uri.rfind("sim:", 0) != 0) {
        return usageError(kCommand, "--noise applies to sim: sources only");
    }
    if (Status s = checkSourceArguments(uri, o.source_options); !s.isOk())
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
    base.config_toml = config_toml;
    base.command_line = std::string("plumb ") + kCommand;
    for (const std::string& a : arguments)
        base.command_line +=
            " " + (a.find_first_of(" \t'\"") == std::string::npos ? a : "'" + a + "'");

    Result<backend::PipelineResult> result =
        o.self_calibrate ? selfCalibratedRun(**source, uri, o, cfg, base)
                         : reconstructOnce(**source, uri, o.source_options, cfg, cfg.pipeline, base,
                                           o.out, o, record.has_value());
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
    const nlohmann::json& sc = result->metrics.value("self_calibration", nlohmann::json());
    if (o.self_calibrate && sc.value("status", std::string()) == "not_determined") {
        std::cout << "self-calibration: no table learned (" << sc.value("reason", std::string())
                  << "); the reconstruction used the raw depth\n";
    } else if (o.self_calibrate) {
        const nlohmann::json before = sc.value("before", nlohmann::json::object());
        std::cout << "self-calibration: table " << (o.out / "depth_calibration.txt").string();
        if (before.contains("ate_rmse_m")) {
            std::cout << fmt::format("; first reconstruction ({}) ATE RMSE {:.2f} cm",
                                     sc.value("first_table", std::string("none")) == "none"
                                         ? "raw depth"
                                         : "the bend from the planes",
                                     100.0 * before.value("ate_rmse_m", 0.0));
        }
        if (before.contains("recon_mean_m")) {
            std::cout << fmt::format(", recon error mean {:.2f} cm",
                                     100.0 * before.value("recon_mean_m", 0.0));
        }
        std::cout << " (" << (o.out / "self_calibration" / "first").string() << ")\n";
        for (const nlohmann::json& r : sc.value("round_results", nlohmann::json::array())) {
            const int round = r.value("round", 0);
            if (round < 2) continue;
            const nlohmann::json f = r.value("reconstruction_figures", nlohmann::json::object());
            std::cout << fmt::format(
                "self-calibration: round {} reconstructed with round {}'s table", round, round - 1);
            if (f.contains("ate_rmse_m"))
                std::cout << fmt::format(": ATE RMSE {:.2f} cm",
                                         100.0 * f.value("ate_rmse_m", 0.0));
            if (f.contains("recon_mean_m"))
                std::cout << fmt::format(", recon error mean {:.2f} cm",
                                         100.0 * f.value("recon_mean_m", 0.0));
            std::cout << " (" << (o.out / r.value("reconstruction", std::string())).string()
                      << ")\n";
        }
    }
    std::cout << backend::summarize(*result);
    std::cout << "output: " << std::filesystem::absolute(o.out).string()
              << " (report.html, metrics.json, mesh.ply, layout.json, floorplan.svg)\n";
    return kExitOk;
}

PLUMB_COMMAND(reconstruct, "reconstruct",
              "reconstruct a room from a dataset or the simulated scanner", runReconstruct);

}  // namespace plumb::tools
