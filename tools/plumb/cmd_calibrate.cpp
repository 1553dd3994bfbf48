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

int runCalibrate(const std::vector<std::string>& arguments) {
    std::vector<std::string> args = arguments;
    Result<config::ConfigArgs> config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(kCommand, config_args.status().message());
    std::string source_uri;
    std::filesystem::path out;
    SourceOptions source_options;
    source_options.max_frames = 300;
    source_options.colour = false;
    source_options.depth_calibration = "none";  // the raw depth is what is calibrated
    std::optional<int> iterations;
    std::optional<std::filesystem::path> poses_path;
    std::optional<std::filesystem::path> reference_path;
    std::optional<std::filesystem::path> initial_path;
    bool refine_poses = false;
    bool planar_only = false;
    bool planar_first = true;
    int threads = 0;
    bool quiet = false;
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
            if (!value(&v) || v.empty()) return usageError(kCommand, "--out needs a file");
            out = v;
        } else if (a == "--frames") {
            if (!value(&v) || !parseNumber(v, &source_options.max_frames) ||
                source_options.max_frames == 0)
                return usageError(kCommand, "--frames needs a positive integer");
        } else if (a == "--poses") {
            if (!value(&v) || v.empty())
                return usageError(kCommand, "--poses needs a trajectory file");
            poses_path = v;
        } else if (a == "--refine-poses") {
            refine_poses = true;
        } else if (a == "--planar-only") {
            planar_only = true;
        } else if (a == "--no-planar") {
            planar_first = false;
        } else if (a == "--reference") {
            if (!value(&v) || v.empty())
                return usageError(kCommand, "--reference needs a table file");
            reference_path = v;
        } else if (a == "--initial") {
            if (!value(&v) || v.empty())
                return usageError(kCommand, "--initial needs a table file");
            initial_path = v;
        } else if (a == "--iterations") {
            int k = 0;
            if (!value(&v) || !parseNumber(v, &k) || k < 1)
                return usageError(kCommand, "--iterations needs a positive integer");
            iterations = k;
        } else if (a == "--intrinsics") {
            if (!value(&source_options.intrinsics))
                return usageError(kCommand, "--intrinsics needs a preset or a file");
        } else if (a == "--depth-scale") {
            if (!value(&v) || !parseNumber(v, &source_options.depth_scale) ||
                !(source_options.depth_scale > 0))
                return usageError(kCommand, "--depth-scale needs a positive number");
        } else if (a == "--seed") {
            if (!value(&v) || !parseNumber(v, &source_options.seed))
                return usageError(kCommand, "--seed needs a non-negative integer");
        } else if (a == "--noise") {
            if (!value(&source_options.sim_noise))
                return usageError(kCommand, "--noise needs a mode");
            if (Status s = sim::checkNoiseMode(source_options.sim_noise); !s.isOk())
                return usageError(kCommand, s.message());
        } else if (a == "--threads") {
            if (!value(&v) || !parseNumber(v, &threads) || threads < 1)
                return usageError(kCommand, "--threads needs a positive integer");
        } else if (a == "--quiet") {
            quiet = true;
        } else if (!a.empty() && a[0] == '-') {
            return usageError(kCommand, "unknown option " + a);
        } else if (source_uri.empty()) {
            source_uri = a;
        } else {
            return usageError(kCommand, "more than one source given: " + source_uri + " and " + a);
        }
    }
    if (source_uri.empty()) return usageError(kCommand, "no source given");
    if (out.empty()) return usageError(kCommand, "--out is required");
    if (planar_only && !planar_first)
        return usageError(kCommand, "--planar-only and --no-planar exclude each other");
    if (planar_only && (poses_path || refine_poses)) {
        return usageError(kCommand, "--planar-only uses no poses: drop --poses and --refine-poses");
    }

    calibration::SelfCalibrationConfig cfg;
    if (Status s = config::load(*config_args, cfg); !s.isOk())
        return usageError(kCommand, s.message());
    if (iterations) cfg.max_iterations = *iterations;
    if (Status s = calibration::validate(cfg); !s.isOk()) return usageError(kCommand, s.message());
    std::optional<tbb::global_control> thread_limit;
    if (threads > 0) {
        thread_limit.emplace(tbb::global_control::max_allowed_parallelism,
                             static_cast<size_t>(threads));
    }

    const std::string uri =
        (source_uri.rfind("sim:", 0) == 0 || source_uri.rfind("dataset:", 0) == 0)
            ? source_uri
            : "dataset:" + source_uri;
    if (!source_options.sim_noise.empty() && uri.rfind("sim:", 0) != 0) {
        return usageError(kCommand, "--noise applies to sim: sources only");
    }
    if (Status s = checkSourceArguments(uri, source_options); !s.isOk())
        return usageError(kCommand, s.message());
    std::optional<PoseLookup> pose_file;
    if (poses_path) {
        Result<PoseLookup> p = PoseLookup::read(*poses_path);
        if (!p.isOk()) return failure(kCommand, p.status());
        pose_file = std::move(*p);
    }
    std::optional<DistortionTable> reference;
    if (reference_path) {
        Result<DistortionTable> t = DistortionTable::load(*reference_path);
        if (!t.isOk()) return failure(kCommand, t.status());
        reference = std::move(*t);
    }
    std::optional<DistortionTable> initial;
    if (initial_path) {
        Result<DistortionTable> t = DistortionTable::load(*initial_path);
        if (!t.isOk()) return failure(kCommand, t.status());
        initial = std::move(*t);
    }
    // --planar-only --initial TABLE: the bend left in the depth undistorted by TABLE.
    if (planar_only && initial_path) source_options.depth_calibration = initial_path->string();
    Result<std::unique_ptr<FrameSource>> opened = openFrameSource(uri, source_options);
    if (!opened.isOk()) return failure(kCommand, opened.status());
    std::unique_ptr<FrameSource> source = std::move(opened).value();
    const PinholeCamera camera = source->camera();
    if (planar_only) {
        Result<PlanarStage> planar = learnPlanarTable(*source, cfg.planar, planarPrinter(quiet));
        if (!planar.isOk()) return failure(kCommand, planar.status());
        if (initial) planar->table = composeTables(*initial, planar->table);
        if (Status s = planar->table.save(out); !s.isOk()) return failure(kCommand, s);
        if (!quiet) {
            std::printf(
                "the bend from the planes of %zu frames (the scan's halves agree within %.3f "
                "%%); table written to %s\n",
                planar->frames_read, 100.0 * planar->estimate.split_disagreement,
                out.string().c_str());
        }
        if (reference) {
            return printComparison(planar->table, planarCoverage(planar->estimate), *reference,
                                   *reference_path);
        }
        return kExitOk;
    }

    std::vector<DepthImage> depth;
    std::vector<Eigen::Isometry3d> T_W_C;
    size_t without_pose = 0;
    if (pose_file) {
        Result<PosedDepth> posed = readPosedDepth(*source, *pose_file);
        if (!posed.isOk()) return failure(kCommand, posed.status());
        depth = std::move(posed->depth);
        T_W_C = std::move(posed->T_W_C);
        without_pose = posed->without_pose;
    }
    while (!pose_file) {
        Result<Frame> frame = source->next();
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            return failure(kCommand, frame.status());
        }
        if (!frame->T_W_C_gt) {
            return failure(
                kCommand,
                invalidArgument(fmt::format(
                    "frame {} ({}) has no ground-truth pose: plumb calibrate needs a source with "
                    "ground truth (sim:SCENE, or a dataset with groundtruth.txt), --poses FILE, "
                    "or --planar-only",
                    frame->index, frame->name)));
        }
        depth.push_back(std::move(frame->depth));
        T_W_C.push_back(*frame->T_W_C_gt);
    }
    if (depth.empty()) {
        return failure(
            kCommand,
            invalidArgument(
                pose_file ? fmt::format("none of the source's frames has a pose in {} ({} poses)",
                                        poses_path->string(), pose_file->size())
                          : std::string("the source delivered no frames")));
    }
    if (!quiet) {
        std::printf("calibrating from %zu frames of %s (%dx%d), poses from %s\n", depth.size(),
                    source->description().c_str(), camera.width, camera.height,
                    poses_path ? poses_path->string().c_str() : "the ground truth");
        if (without_pose > 0)
            std::printf("%zu frames without a pose in the trajectory skipped\n", without_pose);
    }

    if (planar_first && !initial) {
        calibration::PlanarDistortionEstimator estimator(camera, cfg.planar);
        for (const DepthImage& d : depth) {
            if (Status s = estimator.addFrame(d); !s.isOk()) return failure(kCommand, s);
        }
        Result<calibration::PlanarEstimate> planar = estimator.estimate(planarPrinter(quiet));
        if (planar.isOk()) {
            initial = planar->model.toTable();
            if (!quiet) {
                std::printf(
                    "the alternation starts from the bend of the frames' planes (the scan's "
                    "halves agree within %.3f %%)\n",
                    100.0 * planar->split_disagreement);
            }
        } else if (planar.status().code() == StatusCode::kFailedPrecondition) {
            std::fprintf(stderr,
                         "plumb calibrate: warning: %s; the alternation starts from the "
                         "neutral table\n",
                         planar.status().message().c_str());
        } else {
            return failure(kCommand, planar.status());
        }
    }

    const auto start = std::chrono::steady_clock::now();
    auto report = [&](const calibration::CalibrationIteration& it) {
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
    size_t unaligned = 0;
    const bool refine = refine_poses;
    const calibration::FrameAligner aligner =
        refine ? icpFrameAligner(CalibrationAlignerConfig{}, &unaligned) : nullptr;
    Result<calibration::SelfCalibrationResult> result = calibration::selfCalibrate(
        depth, camera, T_W_C, cfg, initial ? &*initial : nullptr, report, aligner);
    if (!result.isOk()) return failure(kCommand, result.status());
    if (Status s = result->table.save(out); !s.isOk()) return failure(kCommand, s);
    if (!quiet && refine) {
        std::printf(
            "poses refined against every iteration's model; %zu alignments failed (the "
            "frame kept its pose)\n",
            unaligned);
    }
    if (!quiet) {
        std::printf("%s after %zu iterations; table written to %s\n",
                    result->converged ? "converged" : "stopped at the iteration limit",
                    result->iterations.size(), out.string().c_str());
    }
    if (reference) {
        return printComparison(result->table, result->iterations.back().estimate, *reference,
                               *reference_path);
    }
    return kExitOk;
}

}  // namespace

PLUMB_PROGRAM_CONFIG(calibrate, "calibrate", calibration::SelfCalibrationConfig,
                     "plumb calibrate: self-calibration of the depth distortion table");
PLUMB_COMMAND(calibrate, "calibrate",
              "estimate the depth distortion table from a scan (self-calibration)", runCalibrate);

}  // namespace plumb::tools
