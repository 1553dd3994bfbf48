// SPDX-License-Identifier: Apache-2.0
// `plumb calibrate`: self-calibration of the depth distortion table from a scan
// (backend/calibration, reference §7c), written in the CLAMS / Redwood dist-model.txt format that
// --depth-calibration reads.

#include <fmt/format.h>
#include <tbb/global_control.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "backend/calibration/self_calibration.hpp"
#include "common/config/config.hpp"
#include "common/config/registry.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tools/plumb/calibration_aligner.hpp"
#include "tools/plumb/command.hpp"
#include "tools/plumb/planar_stage.hpp"
#include "tools/plumb/pose_lookup.hpp"
#include "tools/plumb/scan_source.hpp"

namespace plumb::tools {
namespace {

constexpr const char* kUsage =
    "usage: plumb calibrate <source> --out TABLE [options]\n"
    "\n"
    "Estimates the depth camera's low-frequency distortion table from a scan of a static scene\n"
    "(CLAMS self-calibration, reference §7c): the raw depth is undistorted with the current\n"
    "table, fused into a TSDF at the frames' poses, the TSDF is raycast at every pose, and per\n"
    "image cell (80x80 cells of 8x6 px at 640x480) and depth bin (1, 3, 5, 7, 9 m) the factor\n"
    "z_model / z_raw is fitted robustly; this repeats until the table stops changing. The global\n"
    "scale is fixed by the mean factor of the 1 m bin being 1. Cells without enough samples keep\n"
    "the factor 1. Each iteration prints the change of the table and the cells covered per bin.\n"
    "The table is written in the dist-model.txt format (`--depth-calibration TABLE` reads it).\n"
    "\n"
    "The frames' poses are their ground truth (the simulator, or a dataset with\n"
    "groundtruth.txt; a frame without one is an error), or with --poses those of a trajectory\n"
    "file, e.g. the trajectory.txt of a `plumb reconstruct --depth-calibration none` run of the\n"
    "same scan (frames the trajectory does not hold are skipped). Every frame is kept in memory\n"
    "(raw and undistorted depth) with up to 8 bytes per compared pixel: for long\n"
    "full-resolution scans use --frames, --intrinsics ci (simulator) or --set pixel_stride=2.\n"
    "\n"
    "source:\n"
    "  DIR | dataset:DIR  a TUM, ICL-NUIM, Redwood, 7-Scenes or plumb-sim folder with ground\n"
    "                     truth (detected); its raw depth is used (no depth calibration)\n"
    "  sim:SCENE          the simulated scanner (living_room, weak_manhattan, l_shape,\n"
    "                     corridor, or a scene .toml file), raw depth with the Redwood table\n"
    "  store:DIR[?session=ID]  the raw frames plumb-backend kept of a live scan in its\n"
    "                     fragment store DIR (streamed with plumb-device --set\n"
    "                     stream.raw_frame_every=1; the newest session unless named)\n"
    "\n"
    "options:\n"
    "  --out TABLE        the table file to write (required)\n"
    "  --frames N         use the first N frames only (default 300)\n"
    "  --poses FILE       camera poses: a TUM trajectory (frames matched by timestamp, within\n"
    "                     1 ms) or a .log trajectory (matched by frame index); default: the\n"
    "                     source's ground truth\n"
    "  --planar-only      only the first stage: the bend from each frame's planes, with no\n"
    "                     poses (default: that stage, then the alternation at the poses)\n"
    "  --no-planar        skip the first stage: the alternation starts from the neutral\n"
    "                     table (default: from the first stage's table)\n"
    "  --refine-poses     re-align every frame to each iteration's model by frame-to-model\n"
    "                     ICP before comparing it (default off: measured no better, 5x slower)\n"
    "  --reference TABLE  also compare the learned table with this one (e.g. the sensor's\n"
    "                     measured table): per depth bin the median |learned - reference| over\n"
    "                     the covered cells, after dividing out one global scale (default:\n"
    "                     none)\n"
    "  --initial TABLE    start from this table instead of the neutral one; with\n"
    "                     --planar-only, learn the bend left after it and write their\n"
    "                     product (default: none)\n"
    "  --iterations K     at most K undistort-fuse-estimate steps (default: max_iterations, 8)\n"
    "  --intrinsics X     camera preset or intrinsics file (default: detected)\n"
    "  --depth-scale S    depth units per metre (default: the dataset's)\n"
    "  --seed S           seed of the simulator (default 1)\n"
    "  --noise MODE       simulator noise: redwood (default), off, parametric, undistorted\n"
    "  --threads N        worker threads (default: all); results do not depend on it\n"
    "  --config FILE      configuration file (default: none, every key at its default; see\n"
    "                     `plumb config doc calibrate`)\n"
    "  --set KEY=VALUE    override one configuration key, e.g. min_samples=50 (repeatable)\n"
    "  --quiet            no per-iteration output\n"
    "  -h, --help         this text\n"
    "\n"
    "exit status: 0 done, 1 the input failed (the message says which), 2 bad command line.\n";

constexpr const char* kCommand = "calibrate";

std::function<void(const calibration::PlanarIteration&)> planarPrinter(bool quiet) {
    if (quiet) return {};
    return [](const calibration::PlanarIteration& it) {
        std::printf(
            "planes, iteration %d: %zu planar segments (%zu blocks), residual %.2f noise sigmas, "
            "largest change %.5f\n",
            it.iteration + 1, it.segments, it.blocks, it.rms_sigmas, it.max_change);
        std::fflush(stdout);
    };
}

/// The planar stage's depth-proportional scale removed over the cells with data, for its
/// summary line ("" when the gauge is over the whole image).
std::string scaleGaugeText(const calibration::PlanarEstimate& e) {
    if (e.cells_with_data == 0) return "";
    return fmt::format(
        "; scale growing with depth over the {} cells with depth {:+.4f} %/m, removed",
        e.cells_with_data, 100.0 * e.removed_depth_scale_per_m);
}

/// The planar table covers every cell of the bins its frames reached.
calibration::DistortionEstimate planarCoverage(const calibration::PlanarEstimate& e) {
    calibration::DistortionEstimate coverage;
    coverage.covered.assign(DistortionTable::kCellsPerSide * DistortionTable::kCellsPerSide,
                            static_cast<uint8_t>(e.estimated_bins));
    return coverage;
}

int printComparison(const DistortionTable& learned, const calibration::DistortionEstimate& coverage,
                    const DistortionTable& reference, const std::filesystem::path& path) {
    Result<calibration::TableComparison> c =
        calibration::compareTables(learned, coverage, reference);
    if (!c.isOk()) return failure(kCommand, c.status());
    std::printf("against %s (learned factors divided by %.5f):\n", path.string().c_str(), c->scale);
    for (int bin = 0; bin < DistortionTable::kBins; ++bin) {
        const calibration::TableComparison::Bin& b = c->bins[static_cast<size_t>(bin)];
        if (b.cells == 0) continue;
        std::printf(
            "  %.0f m: %zu cells, median |learned - reference| %.3f %% (uncalibrated %.3f %%); "
            "beyond a projective part %.3f %% (uncalibrated %.3f %%)\n",
            DistortionTable::binCentreM(bin), b.cells, 100.0 * b.median_error,
            100.0 * b.median_uncalibrated, 100.0 * b.median_error_beyond_projective,
            100.0 * b.median_uncalibrated_beyond_projective);
    }
    return kExitOk;
}

/// The command line of `plumb calibrate`.
struct CalibrateArgs {
    std::string source_uri;
    std::filesystem::path out;
    SourceOptions source_options;
    std::optional<int> iterations;
    std::optional<std::filesystem::path> poses_path;
    std::optional<std::filesystem::path> reference_path;
    std::optional<std::filesystem::path> initial_path;
    bool refine_poses = false;
    bool planar_only = false;
    bool planar_first = true;
    int threads = 0;
    bool quiet = false;
};

/// Reads the options of `args` (without --config/--set) into `a`; an exit code when the command
/// ends here (--help, or a usage error already printed).
std::optional<int> parseCalibrateArgs(const std::vector<std::string>& args, CalibrateArgs* a) {
    SourceOptions& source_options = a->source_options;
    source_options.max_frames = 300;
    source_options.colour = false;
    source_options.depth_calibration = "none";  // the raw depth is what is calibrated
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& arg = args[i];
        auto value = [&](std::string* v) {
            if (i + 1 >= args.size()) return false;
            *v = args[++i];
            return true;
        };
        std::string v;
        if (arg == "-h" || arg == "--help") {
            std::cout << kUsage;
            return kExitOk;
        } else if (arg == "--out") {
            if (!value(&v) || v.empty()) return usageError(kCommand, "--out needs a file");
            a->out = v;
        } else if (arg == "--frames") {
            if (!value(&v) || !parseNumber(v, &source_options.max_frames) ||
                source_options.max_frames == 0)
                return usageError(kCommand, "--frames needs a positive integer");
        } else if (arg == "--poses") {
            if (!value(&v) || v.empty())
                return usageError(kCommand, "--poses needs a trajectory file");
            a->poses_path = v;
        } else if (arg == "--refine-poses") {
            a->refine_poses = true;
        } else if (arg == "--planar-only") {
            a->planar_only = true;
        } else if (arg == "--no-planar") {
            a->planar_first = false;
        } else if (arg == "--reference") {
            if (!value(&v) || v.empty())
                return usageError(kCommand, "--reference needs a table file");
            a->reference_path = v;
        } else if (arg == "--initial") {
            if (!value(&v) || v.empty())
                return usageError(kCommand, "--initial needs a table file");
            a->initial_path = v;
        } else if (arg == "--iterations") {
            int k = 0;
            if (!value(&v) || !parseNumber(v, &k) || k < 1)
                return usageError(kCommand, "--iterations needs a positive integer");
            a->iterations = k;
        } else if (arg == "--intrinsics") {
            if (!value(&source_options.intrinsics))
                return usageError(kCommand, "--intrinsics needs a preset or a file");
        } else if (arg == "--depth-scale") {
            if (!value(&v) || !parseNumber(v, &source_options.depth_scale) ||
                !(source_options.depth_scale > 0))
                return usageError(kCommand, "--depth-scale needs a positive number");
        } else if (arg == "--seed") {
            if (!value(&v) || !parseNumber(v, &source_options.seed))
                return usageError(kCommand, "--seed needs a non-negative integer");
        } else if (arg == "--noise") {
            if (!value(&source_options.sim_noise))
                return usageError(kCommand, "--noise needs a mode");
            if (Status s = sim::checkNoiseMode(source_options.sim_noise); !s.isOk())
                return usageError(kCommand, s.message());
        } else if (arg == "--threads") {
            if (!value(&v) || !parseNumber(v, &a->threads) || a->threads < 1)
                return usageError(kCommand, "--threads needs a positive integer");
        } else if (arg == "--quiet") {
            a->quiet = true;
        } else if (!arg.empty() && arg[0] == '-') {
            return usageError(kCommand, "unknown option " + arg);
        } else if (a->source_uri.empty()) {
            a->source_uri = arg;
        } else {
            return usageError(kCommand,
                              "more than one source given: " + a->source_uri + " and " + arg);
        }
    }
    if (a->source_uri.empty()) return usageError(kCommand, "no source given");
    if (a->out.empty()) return usageError(kCommand, "--out is required");
    if (a->planar_only && !a->planar_first)
        return usageError(kCommand, "--planar-only and --no-planar exclude each other");
    if (a->planar_only && (a->poses_path || a->refine_poses)) {
        return usageError(kCommand, "--planar-only uses no poses: drop --poses and --refine-poses");
    }
    return std::nullopt;
}

/// --planar-only: the bend from the frames' planes, composed with `initial`, written to a.out.
int runPlanarOnly(FrameSource& source, const CalibrateArgs& a,
                  const calibration::SelfCalibrationConfig& cfg,
                  const std::optional<DistortionTable>& initial,
                  const std::optional<DistortionTable>& reference) {
    Result<PlanarStage> planar =
        learnPlanarTable(source, cfg.planar, cfg.right_angles, planarPrinter(a.quiet));
    if (!planar.isOk()) return failure(kCommand, planar.status());
    if (initial) planar->table = composeTables(*initial, planar->table);
    if (Status s = planar->table.save(a.out); !s.isOk()) return failure(kCommand, s);
    if (!a.quiet) {
        std::printf(
            "the bend from the planes of %zu frames (the scan's halves agree within %.3f "
            "%%%s); table written to %s\n",
            planar->frames_read, 100.0 * planar->estimate.split_disagreement,
            scaleGaugeText(planar->estimate).c_str(), a.out.string().c_str());
    }
    if (reference) {
        return printComparison(planar->table, planarCoverage(planar->estimate), *reference,
                               *a.reference_path);
    }
    return kExitOk;
}

/// The raw depth of every frame with its pose: from `pose_file` when given, else the frames'
/// ground truth (a frame without one is an error). Fails when no frame has a pose.
Result<PosedDepth> readCalibrationFrames(FrameSource& source,
                                         const std::optional<PoseLookup>& pose_file,
                                         const std::optional<std::filesystem::path>& poses_path) {
    PosedDepth posed;
    if (pose_file) {
        Result<PosedDepth> read = readPosedDepth(source, *pose_file);
        if (!read.isOk()) return read.status();
        posed = std::move(*read);
    }
    while (!pose_file) {
        Result<Frame> frame = source.next();
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            return frame.status();
        }
        if (!frame->T_W_C_gt) {
            return invalidArgument(fmt::format(
                "frame {} ({}) has no ground-truth pose: plumb calibrate needs a source with "
                "ground truth (sim:SCENE, or a dataset with groundtruth.txt), --poses FILE, "
                "or --planar-only",
                frame->index, frame->name));
        }
        posed.depth.push_back(std::move(frame->depth));
        posed.T_W_C.push_back(*frame->T_W_C_gt);
    }
    if (posed.depth.empty()) {
        return invalidArgument(
            pose_file ? fmt::format("none of the source's frames has a pose in {} ({} poses)",
                                    poses_path->string(), pose_file->size())
                      : std::string("the source delivered no frames"));
    }
    return posed;
}

/// The first stage before the alternation: the bend of the frames' planes as the starting table
/// (nullopt, with a warning, when the planes do not determine it).
Result<std::optional<DistortionTable>> planarStartingTable(
    const std::vector<DepthImage>& depth, const PinholeCamera& camera,
    const calibration::SelfCalibrationConfig& cfg, bool quiet) {
    calibration::PlanarDistortionEstimator estimator(camera, cfg.planar);
    for (const DepthImage& d : depth) PLUMB_RETURN_IF_ERROR(estimator.addFrame(d));
    Result<calibration::PlanarEstimate> planar = estimator.estimate(planarPrinter(quiet));
    if (planar.isOk()) {
        if (!quiet) {
            std::printf(
                "the alternation starts from the bend of the frames' planes (the scan's "
                "halves agree within %.3f %%%s)\n",
                100.0 * planar->split_disagreement, scaleGaugeText(*planar).c_str());
        }
        return std::optional<DistortionTable>(planar->model.toTable());
    }
    if (planar.status().code() != StatusCode::kFailedPrecondition) return planar.status();
    std::fprintf(stderr,
                 "plumb calibrate: warning: %s; the alternation starts from the "
                 "neutral table\n",
                 planar.status().message().c_str());
    return std::optional<DistortionTable>();
}

/// Prints each iteration of the alternation (nothing when quiet), with the comparison against
/// `reference` when there is one.
std::function<void(const calibration::CalibrationIteration&)> iterationPrinter(
    bool quiet, const std::optional<DistortionTable>& reference) {
    const auto start = std::chrono::steady_clock::now();
    return [quiet, &reference, start](const calibration::CalibrationIteration& it) {
        if (quiet) return;
        const calibration::DistortionEstimate& e = it.estimate;
        const double s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        std::printf(
            "iteration %d: change median %.5f max %.5f over %zu factors; cells covered per bin "
            "(1/3/5/7/9 m) %d %d %d %d %d of 6400; %zu samples, %zu outliers; %.1f s\n",
            it.iteration + 1, e.median_change, e.max_change, e.compared_factors, e.covered_cells[0],
            e.covered_cells[1], e.covered_cells[2], e.covered_cells[3], e.covered_cells[4],
            e.samples, e.outliers, s);
        if (reference) {
            Result<calibration::TableComparison> c =
                calibration::compareTables(e.table, e, *reference);
            if (c.isOk()) {
                std::printf("  median |learned - reference| 1 m %.3f %%, 3 m %.3f %%\n",
                            100.0 * c->bins[0].median_error, 100.0 * c->bins[1].median_error);
            }
        }
        std::fflush(stdout);
    };
}

/// The alternation at the poses from `initial`, the table written to a.out.
int runAlternation(const PosedDepth& posed, const PinholeCamera& camera, const CalibrateArgs& a,
                   const calibration::SelfCalibrationConfig& cfg,
                   const std::optional<DistortionTable>& initial,
                   const std::optional<DistortionTable>& reference) {
    size_t unaligned = 0;
    const bool refine = a.refine_poses;
    const calibration::FrameAligner aligner =
        refine ? icpFrameAligner(CalibrationAlignerConfig{}, &unaligned) : nullptr;
    Result<calibration::SelfCalibrationResult> result = calibration::selfCalibrate(
        posed.depth, camera, posed.T_W_C, cfg, initial ? &*initial : nullptr,
        iterationPrinter(a.quiet, reference), aligner);
    if (!result.isOk()) return failure(kCommand, result.status());
    if (Status s = result->table.save(a.out); !s.isOk()) return failure(kCommand, s);
    if (!a.quiet && refine) {
        std::printf(
            "poses refined against every iteration's model; %zu alignments failed (the "
            "frame kept its pose)\n",
            unaligned);
    }
    if (!a.quiet) {
        std::printf("%s after %zu iterations; table written to %s\n",
                    result->converged ? "converged" : "stopped at the iteration limit",
                    result->iterations.size(), a.out.string().c_str());
    }
    if (reference) {
        return printComparison(result->table, result->iterations.back().estimate, *reference,
                               *a.reference_path);
    }
    return kExitOk;
}

/// Reads the table at `path`, when given.
Result<std::optional<DistortionTable>> loadTable(const std::optional<std::filesystem::path>& path) {
    if (!path) return std::optional<DistortionTable>();
    Result<DistortionTable> t = DistortionTable::load(*path);
    if (!t.isOk()) return t.status();
    return std::optional<DistortionTable>(std::move(*t));
}

int runCalibrate(const std::vector<std::string>& arguments) {
    std::vector<std::string> args = arguments;
    Result<config::ConfigArgs> config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(kCommand, config_args.status().message());
    CalibrateArgs a;
    if (const std::optional<int> exit_code = parseCalibrateArgs(args, &a)) return *exit_code;
    SourceOptions& source_options = a.source_options;

    calibration::SelfCalibrationConfig cfg;
    if (Status s = config::load(*config_args, cfg); !s.isOk())
        return usageError(kCommand, s.message());
    if (a.iterations) cfg.max_iterations = *a.iterations;
    if (Status s = calibration::validate(cfg); !s.isOk()) return usageError(kCommand, s.message());
    std::optional<tbb::global_control> thread_limit;
    if (a.threads > 0) {
        thread_limit.emplace(tbb::global_control::max_allowed_parallelism,
                             static_cast<size_t>(a.threads));
    }

    const std::string uri = normaliseScanUri(a.source_uri);
    if (!source_options.sim_noise.empty() && uri.rfind("sim:", 0) != 0) {
        return usageError(kCommand, "--noise applies to sim: sources only");
    }
    if (Status s = checkScanSourceArguments(uri, source_options); !s.isOk())
        return usageError(kCommand, s.message());
    std::optional<PoseLookup> pose_file;
    if (a.poses_path) {
        Result<PoseLookup> p = PoseLookup::read(*a.poses_path);
        if (!p.isOk()) return failure(kCommand, p.status());
        pose_file = std::move(*p);
    }
    Result<std::optional<DistortionTable>> reference = loadTable(a.reference_path);
    if (!reference.isOk()) return failure(kCommand, reference.status());
    Result<std::optional<DistortionTable>> initial = loadTable(a.initial_path);
    if (!initial.isOk()) return failure(kCommand, initial.status());
    // --planar-only --initial TABLE: the bend left in the depth undistorted by TABLE.
    if (a.planar_only && a.initial_path)
        source_options.depth_calibration = a.initial_path->string();
    Result<std::unique_ptr<FrameSource>> opened = openScanSource(uri, source_options);
    if (!opened.isOk()) return failure(kCommand, opened.status());
    std::unique_ptr<FrameSource> source = std::move(opened).value();
    const PinholeCamera camera = source->camera();
    if (a.planar_only) return runPlanarOnly(*source, a, cfg, *initial, *reference);

    Result<PosedDepth> posed = readCalibrationFrames(*source, pose_file, a.poses_path);
    if (!posed.isOk()) return failure(kCommand, posed.status());
    if (!a.quiet) {
        std::printf("calibrating from %zu frames of %s (%dx%d), poses from %s\n",
                    posed->depth.size(), source->description().c_str(), camera.width, camera.height,
                    a.poses_path ? a.poses_path->string().c_str() : "the ground truth");
        if (posed->without_pose > 0)
            std::printf("%zu frames without a pose in the trajectory skipped\n",
                        posed->without_pose);
    }
    if (a.planar_first && !*initial) {
        Result<std::optional<DistortionTable>> start =
            planarStartingTable(posed->depth, camera, cfg, a.quiet);
        if (!start.isOk()) return failure(kCommand, start.status());
        *initial = std::move(*start);
    }
    return runAlternation(*posed, camera, a, cfg, *initial, *reference);
}

}  // namespace

PLUMB_PROGRAM_CONFIG(calibrate, "calibrate", calibration::SelfCalibrationConfig,
                     "plumb calibrate: self-calibration of the depth distortion table");
PLUMB_COMMAND(calibrate, "calibrate",
              "estimate the depth distortion table from a scan (self-calibration)", runCalibrate);

}  // namespace plumb::tools
