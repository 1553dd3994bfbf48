// SPDX-License-Identifier: Apache-2.0
// Acceptance of the device's fusion on the simulated scanner (drivers/sim: furnished rooms,
// handheld trajectory, Redwood depth noise) and on real recordings (../shared/data): drift over a
// 50-frame fragment, fragment surface against the exact room, per-fragment ATE against motion
// capture. Images are 320x240 for the simulator (to keep the suite quick) and full size for the
// recordings.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "common/eval/surface_distance.hpp"
#include "common/eval/trajectory_metrics.hpp"
#include "common/geometry/lie.hpp"
#include "device/fusion/fragment_builder.hpp"
#include "device/fusion/fuse_frames.hpp"
#include "drivers/calibrated_source.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::device {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

struct FusedRun {
    std::vector<Fragment> fragments;
    std::vector<std::optional<Eigen::Isometry3d>> gt;  ///< T_W_C by frame index
    int tracking_failures = 0;
    int frames_with_colour = 0;
    int frames_photometric = 0;  ///< tracked with the photometric term
};

/// Feeds up to `max_frames` frames of `source` through a FragmentBuilder; with
/// `require_tracking` every frame must track. `keep` (when given) drops the frames it refuses,
/// as a live device that falls behind its camera does.
FusedRun fuse(FrameSource& source, const FusionConfig& config, size_t max_frames,
              bool require_tracking = true, const std::function<bool(const Frame&)>& keep = {}) {
    FragmentBuilder builder(source.camera(), config);
    FusedRun out;
    FuseHooks hooks;
    hooks.keep = [&](const Frame& frame) {
        // Ground truth by frame index, for the kept frames and the dropped ones alike.
        out.gt.resize(static_cast<size_t>(frame.index) + 1);
        out.gt[static_cast<size_t>(frame.index)] = frame.T_W_C_gt;
        return !keep || keep(frame);
    };
    hooks.on_frame = [&](const Frame& frame, const FrameReport& r) {
        const size_t k = static_cast<size_t>(frame.index);
        out.frames_with_colour += frame.colour.empty() ? 0 : 1;
        if (require_tracking) {
            EXPECT_TRUE(r.tracked) << "frame " << k << ": " << r.message;
        }
        out.tracking_failures += r.tracked ? 0 : 1;
        out.frames_photometric += r.icp.photometric.used ? 1 : 0;
        return Status::ok();
    };
    hooks.on_fragment = [&](Fragment f) {
        out.fragments.push_back(std::move(f));
        return Status::ok();
    };
    // Reading stops at the end of the source (kOutOfRange) only.
    const Result<bool> fused = fuseFrames(source, builder, hooks, max_frames);
    EXPECT_TRUE(fused.isOk()) << fused.status().toString();
    return out;
}

/// Error of the fragment's last frame relative to its first, against ground truth.
bool drift(const Fragment& f, const FusedRun& run, double* t_err, double* r_err) {
    const auto& first_gt = run.gt[static_cast<size_t>(f.frames.front().frame_index)];
    const auto& last_gt = run.gt[static_cast<size_t>(f.frames.back().frame_index)];
    *t_err = *r_err = 0.0;
    if (!first_gt || !last_gt) return false;  // no ground truth for an end frame
    const Eigen::Isometry3d& first = *first_gt;
    const Eigen::Isometry3d& last = *last_gt;
    const Eigen::Isometry3d err = (first.inverse() * last).inverse() * f.frames.back().T_F_C;
    *t_err = err.translation().norm();
    *r_err = lie::rotationAngle(err);
    return true;
}

/// Horn-aligned ATE RMSE of the fragment's frames (T_F_C) against ground truth.
double fragmentAte(const Fragment& f, const FusedRun& run) {
    std::vector<Eigen::Vector3d> est, gt;
    for (const FragmentFrame& fr : f.frames) {
        const auto& T = run.gt[static_cast<size_t>(fr.frame_index)];
        if (!fr.tracking_ok || !T) continue;
        est.push_back(fr.T_F_C.translation());
        gt.push_back(T->translation());
    }
    Result<eval::AteResult> ate = eval::computeAte(est, gt);
    EXPECT_TRUE(ate.isOk()) << ate.status().toString();
    return ate.isOk() ? ate->rmse_m : 1e9;
}

/// Median point-to-surface distance of the fragment's points, placed with the true pose of its
/// first frame, to dense samples of the simulated room.
double surfaceMedian(const Fragment& f, const FusedRun& run, const sim::Scene& scene) {
    const PointCloud truth = sim::sampleSurfaces(scene, 0.01);
    const Eigen::Isometry3f T_W_F =
        run.gt[static_cast<size_t>(f.frames.front().frame_index)]->cast<float>();
    std::vector<Eigen::Vector3f> points_W;
    for (const Eigen::Vector3f& p : f.points_F.points) points_W.push_back(T_W_F * p);
    Result<std::vector<double>> d = eval::pointToSurfaceDistances(points_W, truth, 0.05);
    EXPECT_TRUE(d.isOk()) << d.status().toString();
    return d.isOk() ? eval::median(std::move(*d)) : 1e9;
}

/// Views of the default trajectory: back along the path at the corner just left, two walls, the
/// floor and the furniture along them, so that every translation is observable by depth alone.
constexpr double kDefaultLook = sim::TrajectoryConfig{}.look_offset_deg;
/// Views sideways at the nearest wall: one wall and the floor, degenerate along the wall.
constexpr double kWallLook = -65.0;

/// Raw sensor depth, or undistorted with the sensor's own table (drivers/calibrated_source).
enum class Calibration { kRaw, kSensor };

void checkSimulatedFragment(const std::string& scene, const std::string& noise, double max_median_m,
                            bool check_drift, double look_offset_deg = kDefaultLook,
                            Calibration calibration = Calibration::kRaw) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");  // the macro needs `path`
    sim::SimConfig sc;
    sc.scene = scene;
    sc.camera = PinholeCamera{320, 240, 262.5, 262.5, 159.5, 119.5};
    sc.trajectory.num_frames = 51;
    sc.trajectory.look_offset_deg = look_offset_deg;
    sc.noise_model_path = path.string();
    ASSERT_TRUE(sim::parseNoiseMode(noise, &sc.noise).isOk());
    Result<std::unique_ptr<sim::SimSource>> source = sim::SimSource::create(sc);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const sim::Scene truth = (*source)->scene();
    std::unique_ptr<FrameSource> input = std::move(source).value();
    if (calibration == Calibration::kSensor) {
        Result<DepthCalibration> table = DepthCalibration::load(path);
        ASSERT_TRUE(table.isOk()) << table.status().toString();
        input = std::make_unique<CalibratedSource>(std::move(input), std::move(table).value());
    }
    const FusedRun run = fuse(*input, FusionConfig{}, 51);
    ASSERT_EQ(run.fragments.size(), 2u);
    const Fragment& f = run.fragments[0];
    ASSERT_EQ(f.frames.size(), 50u);
    EXPECT_EQ(f.end, FragmentEnd::kFrameCount);
    double t_err = 0.0, r_err = 0.0;
    ASSERT_TRUE(drift(f, run, &t_err, &r_err));
    const double median = surfaceMedian(f, run, truth);
    const double ate = fragmentAte(f, run);
    std::printf(
        "%s noise %s%s, look %.0f deg: drift %.2f mm %.3f deg, ATE %.2f mm, surface median %.2f "
        "mm, "
        "%zu points\n",
        scene.c_str(), noise.c_str(), calibration == Calibration::kSensor ? " (calibrated)" : "",
        look_offset_deg, t_err * 1e3, r_err / kDeg, ate * 1e3, median * 1e3, f.points_F.size());
    if (check_drift) {
        EXPECT_LT(t_err, 0.01);
        EXPECT_LT(r_err, 0.5 * kDeg);
    }
    EXPECT_LT(median, max_median_m);
    EXPECT_GT(f.points_F.size(), 10000u);
    ::testing::Test::RecordProperty("drift_mm", std::to_string(t_err * 1e3));
    ::testing::Test::RecordProperty("drift_deg", std::to_string(r_err / kDeg));
    ::testing::Test::RecordProperty("surface_median_mm", std::to_string(median * 1e3));
}

TEST(SimFusion, LivingRoomNoiseOffSurface) {
    checkSimulatedFragment("living_room", "off", 0.005, false);
}

TEST(SimFusion, LivingRoomRedwoodCalibratedSurface) {
    checkSimulatedFragment("living_room", "redwood", 0.01, false, kDefaultLook,
                           Calibration::kSensor);
}

// Drift acceptance (< 1 cm, < 0.5 deg over 50 frames) on the default views, which constrain
// every direction. "Noise on" is the Redwood model: without its low-frequency distortion table
// (reference §2.7: noise A, k1 = 0: jitter, 2x2 disparity sampling, quantisation and disparity
// noise), and with the table as a calibrated sensor sees it (measured, then undistorted).
TEST(SimFusion, LivingRoomNoiseOffDrift) {
    checkSimulatedFragment("living_room", "off", 0.005, true);
}

TEST(SimFusion, LivingRoomUndistortedNoiseDrift) {
    checkSimulatedFragment("living_room", "undistorted", 0.01, true);
}

TEST(SimFusion, LivingRoomRedwoodCalibratedDrift) {
    checkSimulatedFragment("living_room", "redwood", 0.01, true, kDefaultLook,
                           Calibration::kSensor);
}

// Open (issue 4). Views sideways at the nearest wall: wall-and-floor views leave one translation
// that depth cannot observe, and tracking slides along the wall (measured at 320x240 with
// undistorted noise: 74 cm over 50 frames). Uncalibrated, the measured distortion table bends
// frames by 1-5 % (up to 17 cm at 3 m in the image corners) in a pattern fixed to the image,
// and the model's bend pulls the camera back towards where it was (1.7 cm, 0.37 deg on the
// default views; 5-75 cm on other look directions).
TEST(SimFusion, DISABLED_LivingRoomWallViewsUndistortedNoiseDrift) {
    checkSimulatedFragment("living_room", "undistorted", 0.01, true, kWallLook);
}

TEST(SimFusion, DISABLED_LivingRoomRedwoodUncalibratedDrift) {
    checkSimulatedFragment("living_room", "redwood", 0.01, true);
}

// A fragment's first frame alone is a thin model (160x120, 2 cm voxels, noise at 2-3 m): the
// first frames after each cut are tracked against the previous fragment's volume (handover).
TEST(SimFusion, HandoverKeepsTrackingAcrossCutsAtLowResolution) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto run = [&](int handover_frames) {
        SourceOptions so;
        so.intrinsics = "ci";
        so.max_frames = 40;
        Result<std::unique_ptr<FrameSource>> source = openFrameSource("sim:living_room", so);
        EXPECT_TRUE(source.isOk()) << source.status().toString();
        FusionConfig config;
        config.frames_per_fragment = 8;
        config.tsdf.voxel_size_m = 0.02;
        config.handover_frames = handover_frames;
        FusedRun run = fuse(**source, config, so.max_frames, /*require_tracking=*/false);
        std::printf("handover %d frames: %d tracking failures, %zu fragments\n", handover_frames,
                    run.tracking_failures, run.fragments.size());
        return std::make_pair(run.tracking_failures, std::move(run.fragments));
    };
    const auto [failures, fragments] = run(FusionConfig{}.handover_frames);
    EXPECT_EQ(failures, 0);
    ASSERT_EQ(fragments.size(), 5U);
    for (const Fragment& f : fragments) {
        EXPECT_EQ(f.end, FragmentEnd::kFrameCount);
        EXPECT_EQ(f.frames.size(), 8U);
        EXPECT_GT(f.points_F.size(), 1000U);
    }
    run(0);  // for comparison in the log: the new fragment's own volume from its second frame
}

// A live device that falls behind its camera drops the frames that find its queue full, in a
// burst while one frame takes long (a fragment being closed on a loaded machine). The frame
// after the gap is predicted from the motion over the time it spans, and the one after that
// from the motion of the gap scaled back to one frame period; a prediction per frame instead
// starts the next ICP a whole gap's motion away and loses tracking.
TEST(SimFusion, TrackingBridgesABurstOfDroppedFrames) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    sim::SimConfig sc;
    sc.scene = "living_room";
    sc.camera = PinholeCamera{320, 240, 262.5, 262.5, 159.5, 119.5};
    sc.trajectory.num_frames = 60;
    sc.noise_model_path = path.string();
    Result<std::unique_ptr<sim::SimSource>> source = sim::SimSource::create(sc);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    Result<DepthCalibration> table = DepthCalibration::load(path);
    ASSERT_TRUE(table.isOk()) << table.status().toString();
    CalibratedSource input(std::move(source).value(), std::move(table).value());
    constexpr int64_t kFirstDropped = 20, kDropped = 12;
    const FusedRun run =
        fuse(input, FusionConfig{}, 60, /*require_tracking=*/true, [&](const Frame& frame) {
            return frame.index < kFirstDropped || frame.index >= kFirstDropped + kDropped;
        });
    EXPECT_EQ(run.tracking_failures, 0);
    ASSERT_FALSE(run.fragments.empty());
    const Fragment& f = run.fragments[0];
    double t_err = 0.0, r_err = 0.0;
    ASSERT_TRUE(drift(f, run, &t_err, &r_err));
    const double ate = fragmentAte(f, run);
    std::printf("%lld frames dropped after frame %lld: drift %.2f mm %.3f deg, ATE %.2f mm\n",
                static_cast<long long>(kDropped), static_cast<long long>(kFirstDropped - 1),
                t_err * 1e3, r_err / kDeg, ate * 1e3);
    EXPECT_LT(t_err, 0.01);
    EXPECT_LT(r_err, 0.5 * kDeg);
    EXPECT_LT(ate, 0.005);
}

/// Per-fragment ATE on the first `frames` frames of a recorded dataset.
void checkRecording(const std::string& name, size_t frames, double max_ate_m) {
    PLUMB_REQUIRE_SHARED_DATA(path, name);
    Result<std::unique_ptr<FrameSource>> source = openFrameSource("dataset:" + path.string());
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const FusedRun run = fuse(**source, FusionConfig{}, frames);
    ASSERT_FALSE(run.fragments.empty());
    for (const Fragment& f : run.fragments) {
        if (f.frames.size() < 10) continue;
        const double ate = fragmentAte(f, run);
        double t_err = 0.0, r_err = 0.0;
        if (drift(f, run, &t_err, &r_err)) {
            std::printf("%s fragment %u (%zu frames): ATE %.2f mm, drift %.2f mm %.3f deg\n",
                        name.c_str(), f.id, f.frames.size(), ate * 1e3, t_err * 1e3, r_err / kDeg);
        } else {
            std::printf("%s fragment %u (%zu frames): ATE %.2f mm\n", name.c_str(), f.id,
                        f.frames.size(), ate * 1e3);
        }
        EXPECT_LT(ate, max_ate_m) << "fragment " << f.id;
        for (const FragmentFrame& fr : f.frames) EXPECT_TRUE(fr.tracking_ok);
    }
}

TEST(RealFusion, TumStructureNotextureFarFragmentAte) {
    checkRecording("tum-fr3-structure-notexture-far", 50, 0.02);
}

TEST(RealFusion, IclNuimOfficeKt0FragmentAte) { checkRecording("icl-nuim-office-kt0", 30, 0.02); }

// ICL-NUIM kt3 with its colour: RGB-D tracking uses it on (nearly) every frame and its
// per-fragment ATE is no worse than depth-only tracking's.
TEST(RealFusion, IclNuimOfficeKt3RgbdNoWorseThanDepthOnly) {
    PLUMB_REQUIRE_SHARED_DATA(path, "icl-nuim-office-kt3-rgbd");
    auto run = [&](bool colour) {
        Result<std::unique_ptr<FrameSource>> source = openFrameSource("dataset:" + path.string());
        EXPECT_TRUE(source.isOk()) << source.status().toString();
        FusionConfig config;
        config.tracking.enabled = colour;
        return fuse(**source, config, 99);
    };
    const FusedRun rgbd = run(true), depth = run(false);
    EXPECT_EQ(rgbd.frames_with_colour, 99);
    EXPECT_GE(rgbd.frames_photometric, 95);
    EXPECT_EQ(depth.frames_photometric, 0);
    ASSERT_EQ(rgbd.fragments.size(), depth.fragments.size());
    for (size_t i = 0; i < rgbd.fragments.size(); ++i) {
        if (rgbd.fragments[i].frames.size() < 10) continue;
        const double ate_c = fragmentAte(rgbd.fragments[i], rgbd);
        const double ate_d = fragmentAte(depth.fragments[i], depth);
        std::printf("kt3 fragment %zu: ATE RGB-D %.2f mm, depth only %.2f mm\n", i, ate_c * 1e3,
                    ate_d * 1e3);
        EXPECT_LE(ate_c, 1.05 * ate_d + 0.0005) << "fragment " << i;
    }
}

}  // namespace
}  // namespace plumb::device
