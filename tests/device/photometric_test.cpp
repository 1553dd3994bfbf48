// SPDX-License-Identifier: Apache-2.0
// The photometric term of RGB-D tracking (device/tracking/photometric.hpp): its Jacobian against
// finite differences, what it adds to frame-to-model ICP on views depth cannot pin (a plain wall
// seen from the front), brightness changes, and the fall-back to depth only without texture.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <utility>

#include "common/tsdf/tsdf_volume.hpp"
#include "device/fusion/fragment_builder.hpp"
#include "device/tracking/icp.hpp"
#include "device/tracking/photometric.hpp"
#include "tests/device/room_scene.hpp"

namespace plumb::device {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

PinholeCamera halfCamera() { return cameraPreset("primesense").value().scaled(0.5); }

/// A wall 2 m in front of the identity camera (z forward), filling the view.
testing::Scene wall() {
    testing::Scene s;
    s.planes = {{{0, 0, -1}, 2.0}};
    return s;
}

/// A smooth float test image (not a rendered scene, not quantised), wavelengths of 30 px and more:
/// the bilinear interpolation's slope within a pixel cell, which finite differences see, is then
/// within 0.5 / 30 of the central-difference gradient the Jacobian uses.
IntensityLevel smoothLevel(const PinholeCamera& cam) {
    Image<float> intensity(cam.width, cam.height);
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            intensity(u, v) =
                static_cast<float>(0.5 + 0.3 * std::sin(u / 30.0) * std::cos(v / 35.0) +
                                   0.1 * std::sin((u + v) / 40.0));
        }
    }
    return makeIntensityLevel(cam, std::move(intensity));
}

/// Largest |J - J_fd| / |J_fd| over reference points seen in `level`; `checked` counts them.
double maxJacobianError(const IntensityLevel& level, int* checked) {
    const Eigen::Isometry3d T_M_R =
        lie::expSE3((Vector6d() << 0.02, -0.01, 0.03, 0.1, -0.05, 0.2).finished());
    const Eigen::Isometry3d T_M_C =
        lie::expSE3((Vector6d() << -0.01, 0.02, 0.01, 0.12, -0.02, 0.15).finished());
    const Brightness br{1.2, -0.05};
    *checked = 0;
    double worst = 0.0;
    for (int k = 0; k < 40; ++k) {
        const ReferencePoint point{
            Eigen::Vector3f(-0.6f + 0.03f * k, 0.4f - 0.02f * k, 1.5f + 0.02f * k), 0.4f};
        double r = 0.0;
        Vector6d J;
        if (!photometricResidual(point, level, T_M_R, T_M_C, br, &r, &J)) continue;
        constexpr double kEps = 1e-4;
        Vector6d fd;
        bool inside = true;
        for (int i = 0; i < 6; ++i) {
            double rp = 0.0, rm = 0.0;
            Vector6d dummy;
            const Vector6d e = kEps * Vector6d::Unit(i);
            inside &=
                photometricResidual(point, level, T_M_R, lie::expSE3(e) * T_M_C, br, &rp, &dummy);
            inside &=
                photometricResidual(point, level, T_M_R, lie::expSE3(-e) * T_M_C, br, &rm, &dummy);
            fd(i) = (rp - rm) / (2.0 * kEps);
        }
        if (!inside) continue;
        ++*checked;
        worst = std::max(worst, (J - fd).norm() / fd.norm());
    }
    return worst;
}

TEST(Photometric, JacobianMatchesFiniteDifferences) {
    // On a linear image bilinear interpolation and central differences are exact: the analytic
    // Jacobian equals the numeric one up to float rounding.
    const PinholeCamera cam = halfCamera();
    Image<float> ramp(cam.width, cam.height);
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) ramp(u, v) = 0.2f + 0.001f * u + 0.0015f * v;
    }
    int checked = 0;
    EXPECT_LT(maxJacobianError(makeIntensityLevel(cam, std::move(ramp)), &checked), 2e-3);
    EXPECT_GE(checked, 30);
    // On a smooth image the analytic gradient (central differences) and the numeric one (the
    // slope of the bilinear interpolation within a pixel cell) differ by up to half a pixel's
    // change of slope: 0.5 / 30 per axis for wavelengths of 30 px.
    EXPECT_LT(maxJacobianError(smoothLevel(cam), &checked), 0.04);
    EXPECT_GE(checked, 30);
}

TEST(Photometric, BilinearSampleInterpolatesAndRejectsOutside) {
    Image<float> img(3, 2);
    img(0, 0) = 0.0f;
    img(1, 0) = 1.0f;
    img(2, 0) = 2.0f;
    img(0, 1) = 10.0f;
    img(1, 1) = 11.0f;
    img(2, 1) = 12.0f;
    float v = 0.0f;
    ASSERT_TRUE(sampleBilinear(img, 1.5f, 0.5f, &v));
    EXPECT_FLOAT_EQ(v, 6.5f);
    ASSERT_TRUE(sampleBilinear(img, 2.0f, 1.0f, &v));
    EXPECT_FLOAT_EQ(v, 12.0f);
    EXPECT_FALSE(sampleBilinear(img, -0.01f, 0.5f, &v));
    EXPECT_FALSE(sampleBilinear(img, 2.01f, 0.5f, &v));
}

struct PairResult {
    IcpResult icp;
    Eigen::Isometry3d T_true;
};

/// Tracks a frame at T_true = Exp(offset) against the wall fused from the identity pose, starting
/// from the identity, with the identity frame's colour as the photometric reference (or none).
PairResult alignOnWall(const Vector6d& offset, bool colour, double gain = 1.0,
                       double (*albedo)(const Eigen::Vector3d&) = testing::texture) {
    const PinholeCamera cam = halfCamera();
    const testing::Scene scene = wall();
    const Eigen::Isometry3d T_ref = Eigen::Isometry3d::Identity();
    tsdf::TsdfConfig tc;
    tc.voxel_size_m = 0.01f;
    tc.truncation_m = 0.04f;
    tsdf::TsdfVolume volume(tc);
    EXPECT_TRUE(volume.integrate(scene.render(cam, T_ref), cam, T_ref).isOk());
    PairResult out;
    out.T_true = lie::expSE3(offset) * T_ref;
    const FramePyramid ref_frame = preprocess(scene.render(cam, T_ref), cam, {}).value();
    const FramePyramid frame = preprocess(scene.render(cam, out.T_true), cam, {}).value();
    const std::vector<ModelLevel> model = predictModel(volume, frame, T_ref, {});
    PhotometricConfig pc;
    const auto ref_intensity =
        buildIntensityPyramid(testing::renderColour(scene, cam, T_ref, albedo), ref_frame, pc);
    const auto cur_intensity = buildIntensityPyramid(
        testing::renderColour(scene, cam, out.T_true, albedo, gain), frame, pc);
    const PhotometricReference reference = selectReference(ref_frame, ref_intensity, pc);
    PhotometricInput input;
    input.current = &cur_intensity;
    input.reference = &reference;
    input.T_M_R = T_ref;
    input.config = pc;
    out.icp = alignFrameToModel(frame, model, T_ref, T_ref, IcpConfig{}, colour ? &input : nullptr);
    return out;
}

TEST(Photometric, PinsTheSlideAlongAWallThatDepthLeavesFree) {
    // 2 cm sideways and 1.5 cm down along the wall, turned 0.5 deg about its normal.
    const Vector6d offset = (Vector6d() << 0, 0, 0.5 * kDeg, 0.02, 0.015, 0.0).finished();
    const PairResult depth_only = alignOnWall(offset, false);
    const PairResult rgbd = alignOnWall(offset, true);
    ASSERT_TRUE(depth_only.icp.ok) << depth_only.icp.failure;
    ASSERT_TRUE(rgbd.icp.ok) << rgbd.icp.failure;
    const Eigen::Isometry3d err_d = depth_only.T_true.inverse() * depth_only.icp.T_M_C;
    const Eigen::Isometry3d err_c = rgbd.T_true.inverse() * rgbd.icp.T_M_C;
    // Depth alone keeps the start along the wall: two free translations.
    EXPECT_GT(err_d.translation().norm(), 0.02);
    EXPECT_EQ(depth_only.icp.num_degenerate_directions, 2);
    EXPECT_FALSE(depth_only.icp.photometric.used);
    // With colour every direction is observed and the pose is right to a millimetre.
    EXPECT_TRUE(rgbd.icp.photometric.used) << rgbd.icp.photometric.fallback;
    EXPECT_EQ(rgbd.icp.num_degenerate_directions, 0);
    EXPECT_LT(err_c.translation().norm(), 0.001);
    EXPECT_LT(lie::rotationAngle(err_c), 0.05 * kDeg);
    EXPECT_GT(rgbd.icp.photometric.inlier_fraction, 0.9);
}

TEST(Photometric, AffineBrightnessFollowsAnExposureChange) {
    const Vector6d offset = (Vector6d() << 0, 0, 0, 0.015, -0.01, 0.0).finished();
    const PairResult r = alignOnWall(offset, true, /*gain=*/1.3);
    ASSERT_TRUE(r.icp.ok) << r.icp.failure;
    ASSERT_TRUE(r.icp.photometric.used) << r.icp.photometric.fallback;
    // I_ref = a I_cur + b with I_cur = 1.3 I_ref (clipped pixels aside).
    EXPECT_NEAR(r.icp.photometric.brightness.a, 1.0 / 1.3, 0.03);
    EXPECT_NEAR(r.icp.photometric.brightness.b, 0.0, 0.02);
    EXPECT_LT((r.T_true.inverse() * r.icp.T_M_C).translation().norm(), 0.001);
}

TEST(Photometric, APlainWallFallsBackToDepthOnlyAndSaysSo) {
    const Vector6d offset = (Vector6d() << 0, 0, 0, 0.02, 0.0, 0.0).finished();
    const PairResult r = alignOnWall(offset, true, 1.0, /*albedo=*/nullptr);
    ASSERT_TRUE(r.icp.ok) << r.icp.failure;
    EXPECT_FALSE(r.icp.photometric.used);
    EXPECT_NE(r.icp.photometric.fallback.find("too little texture"), std::string::npos)
        << r.icp.photometric.fallback;
    EXPECT_EQ(r.icp.num_degenerate_directions, 2);
}

/// Slides the camera `length_m` along the wall in `frames` frames, starting and stopping twice
/// (two smooth moves with a rest between), with a slight bob; returns the largest position error
/// of the tracked trajectory and the number of frames tracked with the photometric term.
struct Slide {
    double max_error_m = 0.0;
    int photometric_frames = 0;
    int fallback_frames = 0;
    std::string last_fallback;
};

Eigen::Isometry3d slidePose(int k, int frames, double length_m) {
    // Two moves of length/2, each s(tau) = tau - sin(2 pi tau) / (2 pi) (zero speed at both
    // ends), with a rest of frames/6 between them.
    const int rest = frames / 6, move = (frames - rest) / 2;
    auto ease = [](double tau) {
        tau = std::clamp(tau, 0.0, 1.0);
        return tau - std::sin(2.0 * std::numbers::pi * tau) / (2.0 * std::numbers::pi);
    };
    const double s =
        0.5 * length_m *
        (ease(static_cast<double>(k) / move) + ease(static_cast<double>(k - move - rest) / move));
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = Eigen::Vector3d(s - 0.5 * length_m, 0.03 * std::sin(0.07 * k), 0.0);
    return T;
}

Slide slideAlongWall(bool colour, double (*albedo)(const Eigen::Vector3d&)) {
    const PinholeCamera cam = halfCamera();
    testing::Scene scene;
    scene.planes = {{{0, 0, -1}, 1.8}};
    FusionConfig config;
    config.tsdf.voxel_size_m = 0.01f;
    config.tsdf.truncation_m = 0.04f;
    config.tracking.enabled = colour;
    FragmentBuilder builder(cam, config);
    constexpr int kFrames = 100;
    Slide out;
    for (int k = 0; k < kFrames; ++k) {
        const Eigen::Isometry3d T_true = slidePose(k, kFrames, 1.0);
        Frame frame;
        frame.index = k;
        frame.depth = scene.render(cam, T_true, /*noise_seed=*/100 + k);
        frame.colour = testing::renderColour(scene, cam, T_true, albedo);
        const Result<FrameReport> report = builder.process(frame);
        EXPECT_TRUE(report.isOk());
        if (!report.isOk()) break;
        if (report->icp.photometric.used) ++out.photometric_frames;
        if (!report->icp.photometric.fallback.empty()) {
            ++out.fallback_frames;
            out.last_fallback = report->icp.photometric.fallback;
        }
        // The world frame is the first camera's.
        const Eigen::Isometry3d T_W_C_true = slidePose(0, kFrames, 1.0).inverse() * T_true;
        out.max_error_m = std::max(
            out.max_error_m, (builder.T_W_C().translation() - T_W_C_true.translation()).norm());
    }
    return out;
}

TEST(Photometric, ASlideOfOneMetreAlongATexturedWallStaysWithinOneCentimetre) {
    const Slide depth_only = slideAlongWall(false, testing::texture);
    const Slide rgbd = slideAlongWall(true, testing::texture);
    EXPECT_GT(depth_only.max_error_m, 0.10);
    EXPECT_LT(rgbd.max_error_m, 0.01);
    EXPECT_EQ(rgbd.photometric_frames, 99);  // every frame after the first
    EXPECT_EQ(rgbd.fallback_frames, 0) << rgbd.last_fallback;
}

TEST(Photometric, ASlideAlongAPlainWallTracksByDepthOnlyAndSaysSo) {
    const Slide plain = slideAlongWall(true, nullptr);
    EXPECT_EQ(plain.photometric_frames, 0);
    EXPECT_EQ(plain.fallback_frames, 99);
    EXPECT_NE(plain.last_fallback.find("too little texture"), std::string::npos)
        << plain.last_fallback;
    EXPECT_GT(plain.max_error_m, 0.10);  // as depth only: the slide is not observed
}

}  // namespace
}  // namespace plumb::device
