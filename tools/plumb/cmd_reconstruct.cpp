// SPDX-License-Identifier: Apache-2.0
// `plumb reconstruct`: the whole pipeline in one process on a recorded dataset or the simulated
// scanner — fusion into fragments (as the device would), then the backend (registration, layout,
// layout-constrained global registration, final model, evaluation, report).

#include <fmt/format.h>
#include <tbb/global_control.h>

#include <charconv>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "backend/pipeline/pipeline.hpp"
#include "common/config/config.hpp"
#include "common/config/registry.hpp"
#include "common/core/logging.hpp"
#include "common/core/progress.hpp"
#include "common/layout/layout.hpp"
#include "device/fusion/fragment_builder.hpp"
#include "device/fusion/fusion_config.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tools/plumb/command.hpp"

namespace plumb::tools {

/// The configuration of `plumb reconstruct` (and of the backend half of `plumb demo`).
struct ReconstructConfig {
    device::FusionConfig fusion;
    backend::PipelineConfig pipeline;
};

void describe(config::Schema& s, ReconstructConfig& c) {
    s.section("fusion", c.fusion, "tracking and fusion into fragments (as on the device)");
    s.section("pipeline", c.pipeline, "the backend: registration, layout, global registration");
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
    "  --intrinsics X     camera preset or intrinsics file (default: detected)\n"
    "  --depth-scale S    depth units per metre (default: the dataset's)\n"
    "  --seed S           seed of the simulator (default 1)\n"
    "  --noise MODE       simulator noise: redwood (default; with the measured distortion\n"
    "                     table), undistorted, parametric, off\n"
    "  --depth-calibration X  undistort depth: sensor (default: the sensor's own table; the\n"
    "                     simulated sensor with the measured table is calibrated with it,\n"
    "                     recordings and real cameras have none), none, or a dist-model.txt\n"
    "  --no-colour        read depth only, even when the source has colour\n"
    "  --gt DIR           ground truth folder (groundtruth.txt or trajectory.log,\n"
    "                     gt_points.ply, layout.json; default: the dataset folder)\n"
    "  --no-gt            do not evaluate against ground truth\n"
    "  --threads N        worker threads (default: all); results do not depend on it\n"
    "  --config FILE      configuration file (see `plumb config doc reconstruct`)\n"
    "  --set KEY=VALUE    override one configuration key (repeatable)\n"
    "  --quiet            no progress output\n"
    "  -h, --help         this text\n"
    "\n"
    "exit status: 0 done, 1 the input or a stage failed (the message says which), 2 bad\n"
    "command line.\n";

int usageError(const std::string& message) {
    std::cerr << "plumb reconstruct: " << message << "\n(see plumb reconstruct --help)\n";
    return kExitUsage;
}

int failure(const Status& status) {
    std::cerr << "plumb reconstruct: " << status.toString() << "\n";
    return kExitFailure;
}

template <typename T>
bool parseNumber(const std::string& text, T* value) {
    const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), *value);
    return ec == std::errc() && ptr == text.data() + text.size();
}

struct Options {
    std::string source;
    std::filesystem::path out;
    bool no_layout = false;
    bool no_baseline = false;
    SourceOptions source_options;
    std::optional<std::filesystem::path> gt_dir;
    bool no_gt = false;
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
                                         bool quiet) {
    device::FragmentBuilder builder(source.camera(), config);
    std::vector<Fragment> fragments;
    ProgressOptions po;
    if (quiet) po.mode = ProgressOptions::Mode::kQuiet;
    po.unit = "frames";
    Progress progress("tracking and fusing", source.size().value_or(0), po);
    size_t lost = 0;
    for (;;) {
        Result<Frame> frame = source.next();
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            return frame.status();
        }
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

}  // namespace

int runReconstruct(const std::vector<std::string>& arguments) {
    std::vector<std::string> args = arguments;
    Result<config::ConfigArgs> config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(config_args.status().message());
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
            if (!value(&v)) return usageError("--out needs a folder");
            o.out = v;
        } else if (a == "--no-layout") {
            o.no_layout = true;
        } else if (a == "--no-baseline") {
            o.no_baseline = true;
        } else if (a == "--frames") {
            if (!value(&v) || !parseNumber(v, &o.source_options.max_frames) ||
                o.source_options.max_frames == 0)
                return usageError("--frames needs a positive integer");
        } else if (a == "--intrinsics") {
            if (!value(&o.source_options.intrinsics))
                return usageError("--intrinsics needs a preset or a file");
        } else if (a == "--depth-scale") {
            if (!value(&v) || !parseNumber(v, &o.source_options.depth_scale) ||
                !(o.source_options.depth_scale > 0))
                return usageError("--depth-scale needs a positive number");
        } else if (a == "--seed") {
            if (!value(&v) || !parseNumber(v, &o.source_options.seed))
                return usageError("--seed needs a non-negative integer");
        } else if (a == "--depth-calibration") {
            if (!value(&o.source_options.depth_calibration))
                return usageError("--depth-calibration needs a value");
            if (Status s = checkDepthCalibration(o.source_options.depth_calibration); !s.isOk())
                return usageError(s.message());
        } else if (a == "--no-colour") {
            o.source_options.colour = false;
        } else if (a == "--noise") {
            if (!value(&o.source_options.sim_noise)) return usageError("--noise needs a mode");
            if (Status s = sim::checkNoiseMode(o.source_options.sim_noise); !s.isOk())
                return usageError(s.message());
        } else if (a == "--gt") {
            if (!value(&v)) return usageError("--gt needs a folder");
            o.gt_dir = v;
        } else if (a == "--no-gt") {
            o.no_gt = true;
        } else if (a == "--threads") {
            if (!value(&v) || !parseNumber(v, &o.threads) || o.threads < 1)
                return usageError("--threads needs a positive integer");
        } else if (a == "--quiet") {
            o.quiet = true;
        } else if (!a.empty() && a[0] == '-') {
            return usageError("unknown option " + a);
        } else if (o.source.empty()) {
            o.source = a;
        } else {
            return usageError("more than one source given: " + o.source + " and " + a);
        }
    }
    if (o.source.empty()) return usageError("no source given");
    if (o.out.empty()) return usageError("--out is required");

    ReconstructConfig cfg;
    if (Status s = config::load(*config_args, cfg); !s.isOk()) return failure(s);
    if (o.no_layout) cfg.pipeline.use_layout = false;
    if (o.no_baseline) cfg.pipeline.compare_baseline = false;
    std::optional<tbb::global_control> threads;
    if (o.threads > 0)
        threads.emplace(tbb::global_control::max_allowed_parallelism,
                        static_cast<size_t>(o.threads));
    log::setupLogging("plumb reconstruct");

    const std::string uri = normaliseUri(o.source);
    if (!o.source_options.sim_noise.empty() && uri.rfind("sim:", 0) != 0) {
        return usageError("--noise applies to sim: sources only");
    }
    Result<std::unique_ptr<FrameSource>> source = openFrameSource(uri, o.source_options);
    if (!source.isOk()) return failure(source.status());
    log::info("reconstructing {} into {}", (*source)->description(), o.out.string());

    backend::PipelineInput input;
    input.description = uri;
    input.camera = (*source)->camera();
    if (!o.no_gt) {
        if (const auto* sim = dynamic_cast<const sim::SimSource*>(&(*source)->underlying())) {
            Result<backend::GroundTruth> gt = simGroundTruth(*sim);
            if (!gt.isOk()) return failure(gt.status());
            input.ground_truth = std::move(*gt);
        } else {
            const std::filesystem::path dir =
                o.gt_dir ? *o.gt_dir : std::filesystem::path(uri.substr(uri.find(':') + 1));
            Result<backend::GroundTruth> gt = backend::loadGroundTruth(dir);
            if (!gt.isOk()) return failure(gt.status());
            input.ground_truth = std::move(*gt);
        }
    }

    Result<std::vector<Fragment>> fragments = fuseSource(**source, cfg.fusion, o.quiet);
    if (!fragments.isOk()) return failure(fragments.status());
    input.fragments = std::move(*fragments);
    log::info("{} fragments fused", input.fragments.size());
    const SourceOptions source_options = o.source_options;
    input.open_raw_frames = [uri, source_options]() {
        return openFrameSource(uri, source_options);
    };
    input.config_toml = config::toToml(cfg, "plumb reconstruct: effective configuration");

    Result<backend::PipelineResult> result =
        backend::runPipeline(input, cfg.pipeline, o.out, !o.quiet);
    if (!result.isOk()) return failure(result.status());
    std::cout << backend::summarize(*result);
    std::cout << "output: " << std::filesystem::absolute(o.out).string()
              << " (report.html, metrics.json, mesh.ply, layout.json, floorplan.svg)\n";
    return kExitOk;
}

PLUMB_COMMAND(reconstruct, "reconstruct",
              "reconstruct a room from a dataset or the simulated scanner", runReconstruct);

}  // namespace plumb::tools
