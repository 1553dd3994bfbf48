// SPDX-License-Identifier: Apache-2.0
// plumb-bench-layout: per-fragment plane extraction (supervoxels, hypotheses, T-linkage, graph-cut
// multi-model fitting; backend/layout/fragment_planes.hpp) and world-frame layout estimation on
// a simulated loop scan fused with ground-truth poses (Redwood sensor noise without the
// distortion table). The peer is Open3D 0.16's legacy PointCloud::SegmentPlane repeated on the
// same working sample (RANSAC, 2 cm threshold, 1000 iterations, inliers removed after each
// plane, until a plane has fewer than min_label_points inliers): the usual "multi-plane" recipe.
// It is not the same algorithm (no smoothness, no null label, no global clustering) but it is
// the library's answer to the same question "which planes are in this fragment".
// The last line is one JSON object.
//
// Usage: plumb-bench-layout [--scene NAME] [--rate HZ] [--frames-per-fragment K] [--repeat R]

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "backend/layout/estimate_layout.hpp"
#include "backend/layout/fragment_planes.hpp"
#include "common/eval/layout_metrics.hpp"
#include "common/tsdf/surface.hpp"
#include "common/tsdf/tsdf_volume.hpp"
#include "drivers/sim/sim_source.hpp"

#ifdef PLUMB_HAVE_OPEN3D
#include <open3d/Open3D.h>
#endif

namespace {

using namespace plumb;
using Clock = std::chrono::steady_clock;
double ms(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

/// Fuses the first `num_frames` frames of `src` into fragments of `per_fragment` frames at the
/// ground-truth poses (2 cm TSDF), each in its first camera's frame; `poses` gets T_W_F.
Status fuseWithTruth(const sim::SimSource& src, size_t num_frames, int per_fragment,
                     std::vector<Fragment>* fragments, std::vector<Eigen::Isometry3d>* poses) {
    tsdf::TsdfConfig tc;
    tc.voxel_size_m = 0.02f;
    tc.truncation_m = 0.06f;
    for (size_t k0 = 0; k0 < num_frames; k0 += per_fragment) {
        tsdf::TsdfVolume volume(tc);
        Fragment f;
        f.id = static_cast<uint32_t>(fragments->size());
        for (size_t k = k0; k < std::min(num_frames, k0 + per_fragment); ++k) {
            auto fr = src.render(k);
            if (!fr.isOk()) return fr.status();
            if (k == k0) f.T_W_F = *fr->frame.T_W_C_gt;
            const Eigen::Isometry3d T_F_C = f.T_W_F.inverse() * *fr->frame.T_W_C_gt;
            PLUMB_RETURN_IF_ERROR(volume.integrate(fr->frame.depth, src.camera(), T_F_C).status());
        }
        f.points_F = tsdf::extractSurfacePoints(volume);
        if (f.points_F.empty()) continue;  // a one-frame tail has no twice-seen voxels
        poses->push_back(f.T_W_F);
        fragments->push_back(std::move(f));
    }
    return Status::ok();
}

/// Our per-fragment plane extraction, timed: the best of `repeat` runs per fragment.
struct TimedPlanes {
    std::vector<layout::FragmentPlanes> planes;
    std::vector<double> best_ms;               ///< per fragment
    double sample_points = 0.0;                ///< summed over the fragments
    double planes_found = 0.0;                 ///< summed over the fragments
    layout::FragmentPlaneDiagnostics stage{};  ///< stage times summed over the fragments
};

Result<TimedPlanes> extractPlanesTimed(const std::vector<Fragment>& fragments,
                                       const layout::FragmentPlaneConfig& pc, int repeat) {
    TimedPlanes out;
    for (const Fragment& f : fragments) {
        double best = 1e300;
        Result<layout::FragmentPlanes> r = invalidArgument("not run");
        for (int rep = 0; rep < repeat; ++rep) {
            const auto t0 = Clock::now();
            r = layout::extractFragmentPlanes(f, pc);
            best = std::min(best, ms(t0, Clock::now()));
        }
        if (!r.isOk()) return r.status();
        out.best_ms.push_back(best);
        out.sample_points += r->diagnostics.num_sample_points;
        out.planes_found += static_cast<double>(r->planes.size());
        out.stage.ms_sample += r->diagnostics.ms_sample;
        out.stage.ms_supervoxels += r->diagnostics.ms_supervoxels;
        out.stage.ms_hypotheses += r->diagnostics.ms_hypotheses;
        out.stage.ms_tlinkage += r->diagnostics.ms_tlinkage;
        out.stage.ms_graph_cut += r->diagnostics.ms_graph_cut;
        out.planes.push_back(std::move(r).value());
    }
    return out;
}

/// The peer: Open3D's SegmentPlane repeated on each fragment's working sample (see the file
/// comment), best of `repeat` runs: {mean ms a fragment, planes a fragment}; {-1, 0} without
/// Open3D.
std::pair<double, double> open3dSegmentPlanes(
    [[maybe_unused]] const std::vector<layout::FragmentPlanes>& planes,
    [[maybe_unused]] const layout::FragmentPlaneConfig& pc, [[maybe_unused]] int repeat) {
    double o3d_mean_ms = -1.0, o3d_planes = 0.0;
#ifdef PLUMB_HAVE_OPEN3D
    const double nf = static_cast<double>(planes.size());
    open3d::utility::SetVerbosityLevel(open3d::utility::VerbosityLevel::Error);
    open3d::utility::random::Seed(1);
    o3d_mean_ms = 0.0;
    for (const layout::FragmentPlanes& fp : planes) {
        double best = 1e300;
        size_t found = 0;
        for (int rep = 0; rep < repeat; ++rep) {
            open3d::geometry::PointCloud cloud;
            for (const auto& p : fp.sample_F.points) cloud.points_.push_back(p.cast<double>());
            const auto t0 = Clock::now();
            found = 0;
            auto rest = std::make_shared<open3d::geometry::PointCloud>(cloud);
            while (rest->points_.size() >= static_cast<size_t>(pc.min_label_points)) {
                auto [model, inliers] = rest->SegmentPlane(0.02, 3, 1000);
                if (inliers.size() < static_cast<size_t>(pc.min_label_points)) break;
                ++found;
                rest = rest->SelectByIndex(inliers, true);
            }
            best = std::min(best, ms(t0, Clock::now()));
        }
        o3d_mean_ms += best / nf;
        o3d_planes += static_cast<double>(found) / nf;
    }
#endif
    return {o3d_mean_ms, o3d_planes};
}

}  // namespace

int main(int argc, char** argv) {
    std::string scene = "living_room";
    double rate_hz = 3.0;
    int per_fragment = 6;
    int repeat = 3;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--scene" && i + 1 < argc) {
            scene = argv[++i];
        } else if (a == "--rate" && i + 1 < argc) {
            rate_hz = std::atof(argv[++i]);
        } else if (a == "--frames-per-fragment" && i + 1 < argc) {
            per_fragment = std::atoi(argv[++i]);
        } else if (a == "--repeat" && i + 1 < argc) {
            repeat = std::max(1, std::atoi(argv[++i]));
        } else {
            std::fprintf(stderr,
                         "usage: plumb-bench-layout [--scene NAME] [--rate HZ] "
                         "[--frames-per-fragment K] [--repeat R]\n");
            return 2;
        }
    }
    sim::SimConfig cfg;
    cfg.scene = scene;
    cfg.noise.distortion = sim::DistortionKind::kNone;
    cfg.trajectory.rate_hz = rate_hz;
    cfg.trajectory.pitch_deg = 0.0;  // tilt up and down to see the floor and the ceiling
    cfg.trajectory.pitch_sway_deg = 30.0;
    auto sc = sim::builtinScene(scene);
    if (!sc.isOk()) {
        std::fprintf(stderr, "error: %s\n", sc.status().toString().c_str());
        return 1;
    }
    auto path = sim::pathControlPoints(*sc);
    if (!path.isOk()) return 1;
    double perimeter = 0.0;
    for (size_t k = 0; k < path->size(); ++k) {
        perimeter += ((*path)[(k + 1) % path->size()] - (*path)[k]).norm();
    }
    cfg.trajectory.num_frames = static_cast<size_t>(std::ceil(perimeter / 0.35 * rate_hz));
    auto source = sim::SimSource::create(cfg);
    if (!source.isOk()) {
        std::fprintf(stderr, "error: %s\n", source.status().toString().c_str());
        return 1;
    }
    const sim::SimSource& src = **source;

    // Fragments fused with ground-truth poses (2 cm TSDF), each in its first camera's frame.
    const auto t_fuse = Clock::now();
    std::vector<Fragment> fragments;
    std::vector<Eigen::Isometry3d> poses;
    if (!fuseWithTruth(src, cfg.trajectory.num_frames, per_fragment, &fragments, &poses).isOk())
        return 1;
    std::printf(
        "plumb-bench-layout: %s loop, %zu frames at %.0f Hz, %zu fragments of %d frames "
        "(fused in %.1f s)\n",
        scene.c_str(), cfg.trajectory.num_frames, rate_hz, fragments.size(), per_fragment,
        ms(t_fuse, Clock::now()) / 1000.0);

    // Ours: per-fragment plane extraction, best of `repeat` runs per fragment.
    layout::FragmentPlaneConfig pc;
    auto extracted = extractPlanesTimed(fragments, pc, repeat);
    if (!extracted.isOk()) {
        std::fprintf(stderr, "error: %s\n", extracted.status().toString().c_str());
        return 1;
    }
    const std::vector<layout::FragmentPlanes>& planes = extracted->planes;
    const std::vector<double>& ours_ms = extracted->best_ms;
    const double sample_points = extracted->sample_points, planes_found = extracted->planes_found;
    const layout::FragmentPlaneDiagnostics& stage = extracted->stage;
    const double nf = static_cast<double>(fragments.size());
    double mean_ms = 0, max_ms = 0;
    for (double v : ours_ms) {
        mean_ms += v / nf;
        max_ms = std::max(max_ms, v);
    }
    std::vector<double> sorted = ours_ms;
    std::sort(sorted.begin(), sorted.end());
    const double median_ms = sorted[sorted.size() / 2];
    std::printf(
        "ours: %.0f sample points and %.1f planes per fragment; %.1f ms mean, %.1f ms "
        "median, %.1f ms max (stages, mean: sample %.1f, supervoxels %.1f, hypotheses "
        "%.1f, T-linkage %.1f, graph cut %.1f)\n",
        sample_points / nf, planes_found / nf, mean_ms, median_ms, max_ms, stage.ms_sample / nf,
        stage.ms_supervoxels / nf, stage.ms_hypotheses / nf, stage.ms_tlinkage / nf,
        stage.ms_graph_cut / nf);

    // World stage and its accuracy against the scene's exact layout.
    const auto t_layout = Clock::now();
    auto est = layout::estimateLayout(fragments, planes, poses);
    const double layout_ms = ms(t_layout, Clock::now());
    if (!est.isOk()) {
        std::fprintf(stderr, "error: %s\n", est.status().toString().c_str());
        return 1;
    }
    auto gt = makeRoomLayout(src.scene().polygon, src.scene().height_m);
    auto m = eval::evaluateLayout(est->layout, gt.value());
    if (!m.isOk()) return 1;
    std::printf("layout: %.1f ms; walls %zu/%zu, max angle error %.3f deg, max |offset| %.4f m\n",
                layout_ms, m->num_est_walls, m->num_gt_walls, m->max_wall_angle_error_deg,
                m->max_abs_wall_offset_error_m);

    const auto [o3d_mean_ms, o3d_planes] = open3dSegmentPlanes(planes, pc, repeat);
#ifdef PLUMB_HAVE_OPEN3D
    std::printf(
        "Open3D SegmentPlane x N: %.1f planes per fragment, %.1f ms mean; ratio "
        "(Open3D / ours) %.2fx\n",
        o3d_planes, o3d_mean_ms, o3d_mean_ms / mean_ms);
#else
    std::printf("Open3D: not built with it (no peer)\n");
#endif
    std::printf(
        "{\"bench\":\"layout\",\"scene\":\"%s\",\"fragments\":%zu,\"sample_points_per_fragment\":"
        "%.0f,\"planes_per_fragment\":%.2f,\"plane_extraction_ms_mean\":%.2f,"
        "\"plane_extraction_ms_median\":%.2f,\"plane_extraction_ms_max\":%.2f,"
        "\"open3d_segment_plane_ms_mean\":%.2f,\"open3d_planes_per_fragment\":%.2f,"
        "\"ratio_open3d_over_ours\":%.3f,\"layout_ms\":%.2f,\"walls\":%zu,\"gt_walls\":%zu,"
        "\"max_wall_angle_error_deg\":%.4f,\"max_wall_offset_error_m\":%.4f,"
        "\"target_ms\":100,\"target_met\":%s}\n",
        scene.c_str(), fragments.size(), sample_points / nf, planes_found / nf, mean_ms, median_ms,
        max_ms, o3d_mean_ms, o3d_planes, o3d_mean_ms > 0 ? o3d_mean_ms / mean_ms : -1.0, layout_ms,
        m->num_est_walls, m->num_gt_walls, m->max_wall_angle_error_deg,
        m->max_abs_wall_offset_error_m, mean_ms <= 100.0 ? "true" : "false");
    return 0;
}
