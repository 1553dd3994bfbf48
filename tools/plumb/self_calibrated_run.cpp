// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/self_calibrated_run.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <optional>
#include <sstream>
#include <utility>
#include <vector>

#include "common/calibration/distortion_table.hpp"
#include "common/core/logging.hpp"
#include "tools/plumb/calibration_aligner.hpp"
#include "tools/plumb/interrupt.hpp"
#include "tools/plumb/planar_stage.hpp"
#include "tools/plumb/pose_lookup.hpp"
#include "tools/plumb/scan_cache.hpp"

namespace plumb::tools {

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

namespace {

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

/// The passes' numbering in the log ("3/5").
class PassNumbers {
  public:
    explicit PassNumbers(int passes) : passes_(passes) {}
    int passes() const { return passes_; }
    std::string next() { return fmt::format("{}/{}", ++step_, passes_); }

  private:
    int passes_;
    int step_ = 0;
};

/// The scan's raw frames, read once for every pass (within `keep_frames_bytes`).
Result<ScanCache> readScan(FrameSource& raw_source, const SelfCalibratedRunInput& run,
                           const SourceOptions& raw_options, int passes) {
    log::info("self-calibration: reading the scan once for its {} passes (at most {} MB kept)",
              passes, run.keep_frames_bytes / 1000000);
    Result<ScanCache> scan = ScanCache::read(raw_source, run.uri, raw_options,
                                             run.keep_frames_bytes, InterruptScope::requested);
    if (!scan.isOk()) return scan.status();
    if (scan->complete()) {
        log::info("self-calibration: the scan's {} raw frames are kept for every pass",
                  scan->frames());
    } else {
        log::info("self-calibration: every pass reads the scan again: {}", scan->notKeptBecause());
    }
    return scan;
}

/// What the rounds leave: the last round's refinement and refined table, and a record of every
/// round for metrics.json (the first's reconstruction figures are the "before" ones).
struct Rounds {
    double first_seconds = 0.0;  ///< from the start of the run to the first reconstruction's end
    std::optional<Refinement> refined;
    std::filesystem::path refined_path;
    nlohmann::json results = nlohmann::json::array();
};

/// The rounds of reconstruction and refinement: round 1 reconstructs with `first_options`'
/// table (the planar table, or the raw depth), each later round with the last round's table;
/// each refines the table at its reconstruction's poses from the table it was made with (or
/// from the neutral one without warm start) and learns the bend left from the planes. The last
/// round's table is written to `table_path`.
Result<Rounds> runRounds(const ScanCache& scan, const SelfCalibrateConfig& sc,
                         const SelfCalibratedRunInput& run, const backend::PipelineInput& base,
                         const ReconstructFn& reconstruct, const SourceOptions& first_options,
                         std::unique_ptr<FrameSource> first_source,
                         const std::optional<PlanarStage>& planar,
                         const std::filesystem::path& table_path,
                         const std::function<double()>& seconds, PassNumbers& passes) {
    const std::filesystem::path folder = run.out / "self_calibration";
    backend::PipelineConfig pipeline = run.pipeline;
    pipeline.compare_baseline = false;
    pipeline.final_model.frame_stride =
        std::max(pipeline.final_model.frame_stride, sc.first_model_frame_stride);
    auto relative = [&run](const std::filesystem::path& p) {
        return p.lexically_relative(run.out).generic_string();
    };
    Rounds out;
    SourceOptions recon_options = first_options;
    std::unique_ptr<FrameSource> recon_source = std::move(first_source);
    std::optional<DistortionTable> last_table;
    const DistortionTable* refine_from = sc.warm_start && planar ? &planar->table : nullptr;
    for (int round = 1; round <= sc.rounds; ++round) {
        const bool last_round = round == sc.rounds;
        const std::string name = round == 1 ? "first" : fmt::format("round{}", round);
        const std::filesystem::path recon_dir = folder / name;
        const double round_start = seconds();
        if (!recon_source) {
            Result<std::unique_ptr<FrameSource>> opened =
                scan.open(recon_options.depth_calibration);
            if (!opened.isOk()) return opened.status();
            recon_source = std::move(*opened);
        }
        log::info("self-calibration {}: reconstructing {} into {}", passes.next(),
                  round == 1 ? (planar ? "from the planar-corrected depth" : "from the raw depth")
                             : fmt::format("with round {}'s table", round - 1),
                  recon_dir.string());
        Result<backend::PipelineResult> recon =
            reconstruct(*recon_source, recon_options, pipeline, base, recon_dir);
        recon_source.reset();
        if (!recon.isOk())
            return prefixed(recon.status(),
                            round == 1 ? std::string("self-calibration, first reconstruction")
                                       : fmt::format("self-calibration, round {}", round));
        const nlohmann::json figures = mainFigures(*recon);
        if (round == 1) out.first_seconds = seconds();
        const std::string prefix = round == 1 ? "" : fmt::format("round{}_", round);
        out.refined_path = folder / (prefix + "refined_table.txt");
        const std::filesystem::path round_table =
            last_round ? table_path : folder / fmt::format("round{}_table.txt", round);
        const std::string refine_step = passes.next();
        const std::string planar_step = passes.next();
        Result<Refinement> r = refineAtPoses(
            scan, sc, base.camera, refine_from, recon_dir, out.refined_path, round_table,
            refine_step, planar_step,
            round == 1 ? "the planar table" : fmt::format("round {}'s table", round - 1));
        if (!r.isOk()) return r.status();
        out.refined = std::move(*r);
        // The next round starts from the table as written: what its reconstruction reads.
        Result<DistortionTable> learned = DistortionTable::load(round_table.string());
        if (!learned.isOk()) return learned.status();
        last_table = std::move(*learned);
        refine_from = &*last_table;
        recon_options.depth_calibration = round_table.string();
        out.results.push_back({{"round", round},
                               {"reconstruction", relative(recon_dir)},
                               {"reconstruction_figures", figures},
                               {"iterations", out.refined->iterations.size()},
                               {"converged", out.refined->learned.converged},
                               {"refined_table", relative(out.refined_path)},
                               {"table", relative(round_table)},
                               {"seconds", seconds() - round_start}});
    }
    return out;
}

/// metrics.json's "self_calibration" of a run that learned its table.
nlohmann::json learnedFigures(const SelfCalibrateConfig& sc, const SelfCalibratedRunInput& run,
                              const std::optional<PlanarStage>& planar, const Rounds& rounds,
                              const std::filesystem::path& table_path, double seconds) {
    const Refinement& refined = *rounds.refined;
    const calibration::DistortionEstimate& last = refined.learned.iterations.back().estimate;
    return {
        {"status", "learned"},
        {"table", table_path.filename().string()},
        {"frames", refined.frames},
        {"frame_step", refined.frame_step},
        {"refine_poses", sc.refine_poses},
        {"warm_start", sc.warm_start && planar},
        {"frames_not_aligned", refined.unaligned},
        {"rounds", sc.rounds},
        {"round_results", rounds.results},
        {"iterations", refined.iterations},
        {"converged", refined.learned.converged},
        {"covered_cells", last.covered_cells},
        {"gauge_bin_m", DistortionTable::binCentreM(last.gauge_bin)},
        {"gauge_scale", last.gauge_scale},
        {"first_table", planar ? "self_calibration/planar_table.txt" : "none"},
        {"planar", planar ? planarFigures(*planar) : nlohmann::json(nullptr)},
        {"refined_table", rounds.refined_path.lexically_relative(run.out).generic_string()},
        {"final_planar", refined.planar ? planarFigures(*refined.planar) : nlohmann::json(nullptr)},
        {"first_reconstruction", "self_calibration/first"},
        {"before", rounds.results.front().at("reconstruction_figures")},
        {"first_reconstruction_seconds", rounds.first_seconds},
        {"estimate_seconds", seconds - rounds.first_seconds}};
}

}  // namespace

Result<backend::PipelineResult> selfCalibratedRun(FrameSource& raw_source,
                                                  const SelfCalibrateConfig& sc,
                                                  const SelfCalibratedRunInput& run,
                                                  const backend::PipelineInput& base,
                                                  const ReconstructFn& reconstruct) {
    const auto start = std::chrono::steady_clock::now();
    const std::function<double()> seconds = [&start] {
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
    // The passes: the planes, three per round (reconstruction, estimate, planes again), the
    // final reconstruction.
    PassNumbers passes(2 + 3 * sc.rounds);
    SourceOptions raw_options = run.source_options;
    raw_options.depth_calibration = "none";
    Result<ScanCache> scan = readScan(raw_source, run, raw_options, passes.passes());
    if (!scan.isOk()) return scan.status();
    Result<std::unique_ptr<FrameSource>> opened = scan->open("none");
    if (!opened.isOk()) return opened.status();
    std::unique_ptr<FrameSource> first_source = std::move(*opened);
    SourceOptions first_options = raw_options;
    std::optional<PlanarStage> planar;
    const std::string planar_step = passes.next();
    if (sc.planar) {
        const std::filesystem::path planar_path = run.out / "self_calibration" / "planar_table.txt";
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
            return reconstruct(*first_source, raw_options, run.pipeline, std::move(input), run.out);
        } else {
            return p.status();
        }
    }
    const std::filesystem::path table_path = run.out / "depth_calibration.txt";
    Result<Rounds> rounds = runRounds(*scan, sc, run, base, reconstruct, first_options,
                                      std::move(first_source), planar, table_path, seconds, passes);
    if (!rounds.isOk()) return rounds.status();

    log::info("self-calibration {}: reconstructing with the learned table", passes.next());
    backend::PipelineInput input = base;
    input.self_calibration = learnedFigures(sc, run, planar, *rounds, table_path, seconds());
    SourceOptions calibrated = run.source_options;
    calibrated.depth_calibration = table_path.string();
    Result<std::unique_ptr<FrameSource>> calibrated_source = scan->open(table_path.string());
    if (!calibrated_source.isOk()) return calibrated_source.status();
    return reconstruct(**calibrated_source, calibrated, run.pipeline, std::move(input), run.out);
}

std::string selfCalibrationSummary(const nlohmann::json& sc, const std::filesystem::path& out) {
    std::ostringstream s;
    if (sc.value("status", std::string()) == "not_determined") {
        s << "self-calibration: no table learned (" << sc.value("reason", std::string())
          << "); the reconstruction used the raw depth\n";
        return s.str();
    }
    const nlohmann::json before = sc.value("before", nlohmann::json::object());
    s << "self-calibration: table " << (out / "depth_calibration.txt").string();
    if (before.contains("ate_rmse_m")) {
        s << fmt::format("; first reconstruction ({}) ATE RMSE {:.2f} cm",
                         sc.value("first_table", std::string("none")) == "none"
                             ? "raw depth"
                             : "the bend from the planes",
                         100.0 * before.value("ate_rmse_m", 0.0));
    }
    if (before.contains("recon_mean_m")) {
        s << fmt::format(", recon error mean {:.2f} cm", 100.0 * before.value("recon_mean_m", 0.0));
    }
    s << " (" << (out / "self_calibration" / "first").string() << ")\n";
    for (const nlohmann::json& r : sc.value("round_results", nlohmann::json::array())) {
        const int round = r.value("round", 0);
        if (round < 2) continue;
        const nlohmann::json f = r.value("reconstruction_figures", nlohmann::json::object());
        s << fmt::format("self-calibration: round {} reconstructed with round {}'s table", round,
                         round - 1);
        if (f.contains("ate_rmse_m"))
            s << fmt::format(": ATE RMSE {:.2f} cm", 100.0 * f.value("ate_rmse_m", 0.0));
        if (f.contains("recon_mean_m"))
            s << fmt::format(", recon error mean {:.2f} cm", 100.0 * f.value("recon_mean_m", 0.0));
        s << " (" << (out / r.value("reconstruction", std::string())).string() << ")\n";
    }
    return s.str();
}

}  // namespace plumb::tools
