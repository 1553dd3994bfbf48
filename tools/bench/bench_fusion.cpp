// SPDX-License-Identifier: Apache-2.0
// plumb-bench-fusion: the on-device pipeline on simulated depth (640x480 or --intrinsics; voxel
// 3 m / 512, truncation 4 cm, 2 threads): TSDF integration, tracking (raycast + ICP) and the whole
// per-frame pipeline (preprocessing, tracking, integration, fragment cuts every 50 frames with
// surface extraction) on the frames without colour and, when the simulator renders it, with colour
// (RGB-D tracking, coloured fusion) and the overhead of colour; the device's per-frame budget at
// the camera's rate and the share of frames a live device would keep; and Open3D's
// t::geometry::VoxelBlockGrid integration of the same frames at the same poses in the same process
// (CPU). Not a test: it prints figures, the last line is one JSON object.

#include <fmt/format.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config.hpp"
#include "common/core/timing.hpp"
#include "common/tsdf/tsdf_volume.hpp"
#include "device/fusion/fragment_builder.hpp"
#include "device/fusion/fusion_config.hpp"
#include "device/fusion/live_rate.hpp"
#include "drivers/sim/sim_source.hpp"
#include "tools/bench/bench_args.hpp"

#ifdef PLUMB_HAVE_OPEN3D
#include <open3d/core/Tensor.h>
#include <open3d/t/geometry/Image.h>
#include <open3d/t/geometry/VoxelBlockGrid.h>
#endif

namespace {

using plumb::msSince;
using plumb::SteadyClock;

/// CPU time of the whole process (all threads), milliseconds.
double processCpuMs() {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double mean(const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / static_cast<double>(v.size());
}

constexpr const char* kUsage =
    "usage: plumb-bench-fusion [--frames N] [--threads N] [--scene NAME] [--noise MODE]\n"
    "                          [--fragment N] [--repeat N] [--model-level L]\n"
    "                          [--intrinsics PRESET] [--sensor-hz HZ] [--set KEY=VALUE]...\n"
    "  --frames N     simulated frames (default 100)\n"
    "  --threads N    worker threads for ours and Open3D (default 2)\n"
    "  --scene NAME   simulated room (default living_room)\n"
    "  --noise MODE   redwood (default), off, parametric, undistorted\n"
    "  --intrinsics PRESET  camera preset of the simulated sensor (default primesense,\n"
    "                 640x480; qvga: 320x240, OpenNI2's 60 Hz mode)\n"
    "  --sensor-hz HZ  frame rate of that camera the device must keep up with (default 30,\n"
    "                 60 for a 320x240 preset): sets the per-frame budget, the fraction\n"
    "                 of the camera's frames a live device would process, and the\n"
    "                 simulated motion between frames (the hand moves as fast at any rate)\n"
    "  --fragment N   frames per fragment (default 50; the volumes restart every N frames)\n"
    "  --model-level L  pyramid level the tracking model is raycast at, with and\n"
    "                 without colour (default: the fusion config's model_level and\n"
    "                 model_level_rgbd)\n"
    "  --repeat N     integration passes over the frames for the integration-only figures\n"
    "                 (default 2; the median over all is reported)\n"
    "  --set KEY=VALUE  a fusion setting for the pipeline run, as `plumb fuse --set` takes\n"
    "                 it (`plumb config doc fusion` lists them), e.g. raycast_interval=2\n";

/// The command line.
struct BenchOptions {
    size_t num_frames = 100;
    int threads = 2;
    int fragment = 50;
    int repeat = 2;
    int model_level = -1;  // -1: the fusion config's defaults
    std::string scene = "living_room";
    std::string noise = "redwood";
    std::string intrinsics = "primesense";
    double sensor_hz = 0.0;  // 0: from the preset's size
    std::vector<std::string> overrides;
};

/// Reads the command line into `o`; an exit code when the program ends here (--help, or a bad
/// argument already reported).
std::optional<int> parseArgs(int argc, char** argv, BenchOptions* o) {
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto num = [&](auto* out) { return plumb::bench::nextNumber(argc, argv, &i, out); };
        bool ok = true;
        if (a == "--frames") {
            ok = num(&o->num_frames) && o->num_frames > 0;
        } else if (a == "--threads") {
            ok = num(&o->threads) && o->threads > 0;
        } else if (a == "--fragment") {
            ok = num(&o->fragment) && o->fragment > 0;
        } else if (a == "--model-level") {
            ok = num(&o->model_level) && o->model_level >= 0 && o->model_level <= 4;
        } else if (a == "--repeat") {
            ok = num(&o->repeat) && o->repeat > 0;
        } else if (a == "--scene" && i + 1 < argc) {
            o->scene = argv[++i];
        } else if (a == "--set" && i + 1 < argc) {
            o->overrides.push_back(argv[++i]);
        } else if (a == "--noise" && i + 1 < argc) {
            o->noise = argv[++i];
        } else if (a == "--intrinsics" && i + 1 < argc) {
            o->intrinsics = argv[++i];
        } else if (a == "--sensor-hz") {
            ok = num(&o->sensor_hz) && o->sensor_hz > 0.0;
        } else if (a == "-h" || a == "--help") {
            std::printf("%s", kUsage);
            return 0;
        } else {
            ok = false;
        }
        if (!ok) {
            std::fprintf(stderr, "plumb-bench-fusion: bad argument '%s'\n%s", a.c_str(), kUsage);
            return 2;
        }
    }
    return std::nullopt;
}

/// The simulated frames, rendered up front, and their camera.
struct Rendered {
    plumb::PinholeCamera camera;
    std::vector<plumb::Frame> frames;
};

/// Renders the frames of the simulated scan (setting o.sensor_hz from the preset when unset); an
/// exit code on failure (the message printed).
std::optional<int> renderFrames(BenchOptions* o, Rendered* out) {
    plumb::sim::SimConfig sc;
    sc.scene = o->scene;
    sc.trajectory.num_frames = o->num_frames;
    plumb::Result<plumb::PinholeCamera> preset = plumb::cameraPreset(o->intrinsics);
    if (!preset.isOk()) {
        std::fprintf(stderr, "plumb-bench-fusion: %s\n", preset.status().toString().c_str());
        return 2;
    }
    sc.camera = preset.value();
    if (o->sensor_hz <= 0.0) o->sensor_hz = sc.camera.width <= 320 ? 60.0 : 30.0;
    sc.trajectory.rate_hz = o->sensor_hz;  // the hand moves as far between frames as at that rate
    if (const plumb::Status s = plumb::sim::parseNoiseMode(o->noise, &sc.noise); !s.isOk()) {
        std::fprintf(stderr, "plumb-bench-fusion: %s\n", s.toString().c_str());
        return 2;
    }
    auto source = plumb::sim::SimSource::create(sc);
    if (!source.isOk()) {
        std::fprintf(stderr, "plumb-bench-fusion: %s\n", source.status().toString().c_str());
        return 1;
    }
    out->camera = (*source)->camera();
    std::printf("plumb-bench-fusion: %s\n", (*source)->description().c_str());
    std::printf("rendering %zu frames...\n", o->num_frames);
    std::fflush(stdout);
    out->frames.reserve(o->num_frames);
    for (size_t k = 0; k < o->num_frames; ++k) {
        auto f = (*source)->render(k);
        if (!f.isOk()) {
            std::fprintf(stderr, "plumb-bench-fusion: %s\n", f.status().toString().c_str());
            return 1;
        }
        out->frames.push_back(std::move(f->frame));
    }
    return std::nullopt;
}

/// What the whole device pipeline took, frame by frame.
struct PipelineRun {
    std::vector<double> frame_ms, track_ms, raycast_ms, integrate_ms, preprocess_ms, extract_ms;
    size_t tracking_failures = 0;
    size_t photometric_frames = 0;
    long icp_iterations = 0;
    double cpu_ms = 0.0;  ///< per frame, all threads
};

/// 1. The whole device pipeline, frame by frame, on `input`; false on failure (the message
///    printed).
bool runPipeline(const plumb::PinholeCamera& camera, const plumb::device::FusionConfig& config,
                 const std::vector<plumb::Frame>& input, PipelineRun* run) {
    const double cpu_start = processCpuMs();
    plumb::device::FragmentBuilder builder(camera, config);
    for (const plumb::Frame& f : input) {
        auto r = builder.process(f);
        if (!r.isOk()) {
            std::fprintf(stderr, "plumb-bench-fusion: %s\n", r.status().toString().c_str());
            return false;
        }
        run->frame_ms.push_back(r->timing.total_ms);
        run->preprocess_ms.push_back(r->timing.preprocess_ms);
        if (r->timing.track_ms > 0.0) run->track_ms.push_back(r->timing.track_ms);
        if (r->timing.raycast_ms > 0.0) run->raycast_ms.push_back(r->timing.raycast_ms);
        if (r->integrated) run->integrate_ms.push_back(r->timing.integrate_ms);
        run->extract_ms.push_back(r->timing.extract_ms);
        run->tracking_failures += r->tracked ? 0 : 1;
        run->photometric_frames += r->icp.photometric.used ? 1 : 0;
        run->icp_iterations += r->icp.iterations;
    }
    run->cpu_ms = (processCpuMs() - cpu_start) / static_cast<double>(input.size());
    return true;
}

/// Integration alone: wall-clock per frame, the most blocks a volume held, CPU per frame.
struct IntegrationRun {
    std::vector<double> frame_ms;
    size_t blocks = 0;
    double cpu_ms = 0.0;  ///< per frame, all threads
};

/// 2. Integration alone at the ground-truth poses, volumes restarted every `fragment` frames
///    (fragment frame = first camera); false on failure (the message printed).
bool integrateAtGroundTruth(const Rendered& in, const plumb::tsdf::TsdfConfig& tsdf,
                            const BenchOptions& o, IntegrationRun* run) {
    const double cpu_start = processCpuMs();
    for (int pass = 0; pass < o.repeat; ++pass) {
        plumb::tsdf::TsdfVolume volume(tsdf);
        Eigen::Isometry3d T_W_F = Eigen::Isometry3d::Identity();
        for (size_t k = 0; k < in.frames.size(); ++k) {
            if (k % static_cast<size_t>(o.fragment) == 0) {
                volume.clear();
                T_W_F = *in.frames[k].T_W_C_gt;
            }
            const Eigen::Isometry3d T_F_C = T_W_F.inverse() * *in.frames[k].T_W_C_gt;
            const SteadyClock::time_point t0 = SteadyClock::now();
            auto r = volume.integrate(in.frames[k].depth, in.camera, T_F_C);
            run->frame_ms.push_back(msSince(t0));
            if (!r.isOk()) {
                std::fprintf(stderr, "plumb-bench-fusion: %s\n", r.status().toString().c_str());
                return false;
            }
            run->blocks = std::max(run->blocks, r->blocks_total);
        }
    }
    run->cpu_ms = (processCpuMs() - cpu_start) / static_cast<double>(run->frame_ms.size());
    return true;
}

/// Open3D's integration of the same frames: median wall-clock and mean CPU per frame (0 without
/// Open3D at build time).
struct Open3dRun {
    double ms = 0.0;
    double cpu_ms = 0.0;
};

#ifdef PLUMB_HAVE_OPEN3D
/// 3. Open3D's VoxelBlockGrid integration of the same frames at the same poses, volumes
///    restarted as ours; prints its line.
Open3dRun integrateOpen3d(const Rendered& in, const plumb::tsdf::TsdfConfig& tsdf,
                          const BenchOptions& o, size_t blocks) {
    namespace o3c = open3d::core;
    namespace o3g = open3d::t::geometry;
    const plumb::PinholeCamera& camera = in.camera;
    const o3c::Device cpu("CPU:0");
    o3c::Tensor K = o3c::Tensor::Eye(3, o3c::Float64, cpu);
    K[0][0] = camera.fx;
    K[1][1] = camera.fy;
    K[0][2] = camera.cx;
    K[1][2] = camera.cy;
    // The same depth as uint16 millimetres (Open3D's efficient input type).
    std::vector<o3g::Image> depth_mm;
    for (const plumb::Frame& f : in.frames) {
        o3c::Tensor t({camera.height, camera.width, 1}, o3c::UInt16, cpu);
        auto* p = t.GetDataPtr<uint16_t>();
        for (int v = 0; v < camera.height; ++v) {
            for (int u = 0; u < camera.width; ++u) {
                const float d = f.depth(u, v);
                p[v * camera.width + u] =
                    d > 0.0f ? static_cast<uint16_t>(std::lround(d * 1000.0f)) : 0;
            }
        }
        depth_mm.emplace_back(t);
    }
    const float voxel = tsdf.voxel_size_m;
    const float trunc_mult = tsdf.truncation_m / voxel;
    std::vector<double> o3d_frame_ms;
    double o3d_cpu = 0.0;
    for (int pass = 0; pass < o.repeat; ++pass) {
        std::unique_ptr<o3g::VoxelBlockGrid> vbg;
        Eigen::Isometry3d T_W_F = Eigen::Isometry3d::Identity();
        for (size_t k = 0; k < in.frames.size(); ++k) {
            if (k % static_cast<size_t>(o.fragment) == 0) {
                vbg = std::make_unique<o3g::VoxelBlockGrid>(
                    std::vector<std::string>{"tsdf", "weight"},
                    std::vector<o3c::Dtype>{o3c::Float32, o3c::Float32},
                    std::vector<o3c::SizeVector>{{1}, {1}}, voxel, 8,
                    static_cast<int64_t>(std::max<size_t>(blocks * 2, 20000)), cpu);
                T_W_F = *in.frames[k].T_W_C_gt;
            }
            // Open3D's extrinsic maps fragment (world) points into the camera.
            const Eigen::Matrix4d T_C_F =
                (T_W_F.inverse() * *in.frames[k].T_W_C_gt).inverse().matrix();
            o3c::Tensor extrinsic({4, 4}, o3c::Float64, cpu);
            for (int r = 0; r < 4; ++r) {
                for (int c = 0; c < 4; ++c) extrinsic[r][c] = T_C_F(r, c);
            }
            const double c0 = processCpuMs();
            const SteadyClock::time_point t0 = SteadyClock::now();
            const o3c::Tensor coords = vbg->GetUniqueBlockCoordinates(
                depth_mm[k], K, extrinsic, 1000.0f, tsdf.max_depth_m, trunc_mult);
            vbg->Integrate(coords, depth_mm[k], K, extrinsic, 1000.0f, tsdf.max_depth_m,
                           trunc_mult);
            o3d_frame_ms.push_back(msSince(t0));
            o3d_cpu += processCpuMs() - c0;
        }
    }
    Open3dRun run;
    run.cpu_ms = o3d_cpu / static_cast<double>(o3d_frame_ms.size());
    run.ms = median(o3d_frame_ms);
    std::printf("open3d VoxelBlockGrid integrate: median %.2f ms/frame, mean %.2f\n", run.ms,
                mean(o3d_frame_ms));
    return run;
}
#endif

/// The figures of the three runs as tables, then the last line: one JSON object.
void printReport(const BenchOptions& o, const Rendered& in, const plumb::tsdf::TsdfConfig& tsdf,
                 const PipelineRun& depth_run, const PipelineRun& colour_run, bool have_colour,
                 const IntegrationRun& ours, const Open3dRun& o3d) {
    const plumb::PinholeCamera& camera = in.camera;
    const double integrate = median(ours.frame_ms);
    const double track = median(depth_run.track_ms);
    const double frame = median(depth_run.frame_ms);
    const double icp_per_frame = depth_run.track_ms.empty()
                                     ? 0.0
                                     : static_cast<double>(depth_run.icp_iterations) /
                                           static_cast<double>(depth_run.track_ms.size());
    std::printf(
        "frames %zu (%dx%d), threads %d, voxel %.2f mm, truncation %.0f mm, up to %zu "
        "blocks, tracking failures %zu, ICP iterations per tracked frame %.1f (all levels)\n",
        in.frames.size(), camera.width, camera.height, o.threads, tsdf.voxel_size_m * 1e3,
        tsdf.truncation_m * 1e3, ours.blocks, depth_run.tracking_failures, icp_per_frame);
    std::printf("ours integrate (GT poses): median %.2f ms/frame, mean %.2f\n", integrate,
                mean(ours.frame_ms));
    std::printf(
        "pipeline: preprocess median %.2f ms, track median %.2f ms (mean %.2f; of it the model "
        "raycast %.2f), integrate median %.2f ms, extraction mean %.2f ms/frame\n",
        median(depth_run.preprocess_ms), track, mean(depth_run.track_ms),
        median(depth_run.raycast_ms), median(depth_run.integrate_ms), mean(depth_run.extract_ms));
    std::printf(
        "CPU time per frame (all threads): pipeline %.2f ms, ours integrate %.2f ms, "
        "open3d integrate %.2f ms\n",
        depth_run.cpu_ms, ours.cpu_ms, o3d.cpu_ms);
    std::printf("whole frame: median %.2f ms (mean %.2f, %.0f fps)\n", frame,
                mean(depth_run.frame_ms), 1e3 / std::max(1e-9, mean(depth_run.frame_ms)));
    const double ratio = integrate > 0.0 && o3d.ms > 0.0 ? o3d.ms / integrate : 0.0;
    if (ratio > 0.0) std::printf("ratio open3d / ours (integrate): %.2f\n", ratio);
    const double colour_frame = median(colour_run.frame_ms);
    const double colour_overhead = have_colour && frame > 0.0 ? colour_frame / frame - 1.0 : 0.0;
    if (have_colour) {
        std::printf(
            "with colour (RGB-D tracking, coloured fusion; %zu of %zu frames tracked with the "
            "photometric term, %zu tracking failures): preprocess median %.2f ms, track median "
            "%.2f ms (%zu model raycasts, median %.2f ms), integrate median %.2f ms (%zu frames "
            "fused), whole frame median %.2f ms: %+.1f %% against depth only\n",
            colour_run.photometric_frames, in.frames.size(), colour_run.tracking_failures,
            median(colour_run.preprocess_ms), median(colour_run.track_ms),
            colour_run.raycast_ms.size(), median(colour_run.raycast_ms),
            median(colour_run.integrate_ms), colour_run.integrate_ms.size(), colour_frame,
            100.0 * colour_overhead);
    } else {
        std::printf("the frames have no colour: no RGB-D figures\n");
    }
    // What a live device on this machine keeps of the camera's frames: all when a frame takes
    // at most the camera's period (the bench's mean, the queue evens out single frames).
    const double budget_ms = 1e3 / o.sensor_hz;
    const PipelineRun& device_run = have_colour ? colour_run : depth_run;
    const double device_mean_ms = mean(device_run.frame_ms);
    const double processed_fraction = std::min(1.0, budget_ms / std::max(1e-9, device_mean_ms));
    // The same replayed through the device's capture queue: frames that take long (a fragment
    // closing, a fresh model cast) drop the frames after them in a row.
    const plumb::device::LiveRate live = plumb::device::replayLiveCamera(
        device_run.frame_ms, budget_ms, plumb::device::kDefaultCaptureQueueFrames);
    std::printf(
        "device pipeline (%s): median %.2f ms a frame, mean %.2f, CPU %.2f ms (all threads); "
        "budget at %.0f Hz %.2f ms: a live device keeps %.0f %% of the camera's frames by the "
        "mean, %.0f %% through its %d-frame queue (at most %zu dropped in a row, latency up to "
        "%.0f ms)\n",
        have_colour ? "with colour" : "depth only", median(device_run.frame_ms), device_mean_ms,
        device_run.cpu_ms, o.sensor_hz, budget_ms, 100.0 * processed_fraction,
        100.0 * live.keptFraction(), plumb::device::kDefaultCaptureQueueFrames,
        live.longest_drop_run, live.max_latency_ms);
    std::printf(
        "{\"intrinsics\":\"%s\",\"width\":%d,\"height\":%d,\"sensor_hz\":%.1f,"
        "\"budget_ms\":%.3f,\"device_frame_ms\":%.3f,\"device_frame_mean_ms\":%.3f,"
        "\"device_frame_cpu_ms\":%.3f,"
        "\"processed_fraction\":%.4f,\"colour_raycast_ms\":%.3f,\"colour_frame_cpu_ms\":%.3f,"
        "\"integrate_ms\":%.3f,\"track_ms\":%.3f,\"frame_ms\":%.3f,\"open3d_integrate_ms\":%.3f,"
        "\"ratio\":%.3f,\"preprocess_ms\":%.3f,\"frame_mean_ms\":%.3f,\"frames\":%zu,"
        "\"threads\":%d,\"frame_cpu_ms\":%.3f,\"integrate_cpu_ms\":%.3f,"
        "\"open3d_integrate_cpu_ms\":%.3f,\"track_mean_ms\":%.3f,\"raycast_ms\":%.3f,"
        "\"icp_iterations\":%.2f,\"colour_frame_ms\":%.3f,\"colour_preprocess_ms\":%.3f,"
        "\"colour_track_ms\":%.3f,\"colour_integrate_ms\":%.3f,\"colour_overhead\":%.4f,"
        "\"colour_fused_fraction\":%.3f,\"queue_processed_fraction\":%.4f,"
        "\"queue_longest_drop_run\":%zu,\"queue_max_latency_ms\":%.1f}\n",
        o.intrinsics.c_str(), camera.width, camera.height, o.sensor_hz, budget_ms,
        median(device_run.frame_ms), device_mean_ms, device_run.cpu_ms, processed_fraction,
        median(colour_run.raycast_ms), colour_run.cpu_ms, integrate, track, frame, o3d.ms, ratio,
        median(depth_run.preprocess_ms), mean(depth_run.frame_ms), in.frames.size(), o.threads,
        depth_run.cpu_ms, ours.cpu_ms, o3d.cpu_ms, mean(depth_run.track_ms),
        median(depth_run.raycast_ms), icp_per_frame, colour_frame, median(colour_run.preprocess_ms),
        median(colour_run.track_ms), median(colour_run.integrate_ms), colour_overhead,
        static_cast<double>(colour_run.integrate_ms.size()) /
            static_cast<double>(std::max<size_t>(1, in.frames.size())),
        live.keptFraction(), live.longest_drop_run, live.max_latency_ms);
}

}  // namespace

int main(int argc, char** argv) {
    BenchOptions o;
    if (const std::optional<int> exit_code = parseArgs(argc, argv, &o)) return *exit_code;
    // Open3D's CPU kernels use OpenMP; read at its first parallel region.
    setenv("OMP_NUM_THREADS", std::to_string(o.threads).c_str(), 1);
    tbb::global_control tbb_threads(tbb::global_control::max_allowed_parallelism,
                                    static_cast<size_t>(o.threads));
    Rendered in;
    if (const std::optional<int> exit_code = renderFrames(&o, &in)) return *exit_code;

    plumb::device::FusionConfig config;
    config.frames_per_fragment = o.fragment;
    if (o.model_level >= 0) config.model_level = config.model_level_rgbd = o.model_level;
    config.tsdf.voxel_size_m = 3.0f / 512.0f;
    config.tsdf.truncation_m = 0.04f;
    config.tsdf.num_threads = o.threads;
    config.raycast.num_threads = o.threads;
    config.surface.num_threads = o.threads;
    config.preprocess.num_threads = o.threads;
    config.icp.num_threads = o.threads;
    if (const plumb::Status s = plumb::config::applyOverrides(o.overrides, config); !s.isOk()) {
        std::fprintf(stderr, "plumb-bench-fusion: %s\n", s.toString().c_str());
        return 2;
    }

    // 1. The whole device pipeline on the frames as rendered (with colour: RGB-D tracking and
    //    coloured fusion) and on the same frames without colour (depth only).
    const bool have_colour = !in.frames.front().colour.empty();
    PipelineRun depth_run, colour_run;
    {
        std::vector<plumb::Frame> depth_frames = in.frames;
        for (plumb::Frame& f : depth_frames) f.colour = plumb::ColourImage();
        if (!runPipeline(in.camera, config, depth_frames, &depth_run)) return 1;
    }
    if (have_colour && !runPipeline(in.camera, config, in.frames, &colour_run)) return 1;

    // 2. Integration alone at the ground-truth poses, ours and Open3D on identical input.
    IntegrationRun ours;
    if (!integrateAtGroundTruth(in, config.tsdf, o, &ours)) return 1;
    Open3dRun o3d;
#ifdef PLUMB_HAVE_OPEN3D
    o3d = integrateOpen3d(in, config.tsdf, o, ours.blocks);
#else
    std::printf("open3d: not available at build time (no ratio)\n");
#endif
    printReport(o, in, config.tsdf, depth_run, colour_run, have_colour, ours, o3d);
    return 0;
}
