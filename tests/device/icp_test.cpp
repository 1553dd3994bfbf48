// SPDX-License-Identifier: Apache-2.0
// Frame-to-model ICP on an analytic room corner: convergence from 2 cm / 2 deg offsets and failure
// detection on degenerate or empty frames, and a single plane tracked along its normal only.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "common/core/simd.hpp"
#include "common/tsdf/tsdf_volume.hpp"
#include "device/tracking/icp.hpp"
#include "tests/device/room_scene.hpp"

namespace plumb::device {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

struct Setup {
    PinholeCamera cam;
    tsdf::TsdfVolume volume;
    Eigen::Isometry3d T_M_ref;
};

/// Three planes meeting in a corner in front of the camera, fused from the reference view.
testing::Scene corner() {
    testing::Scene s;
    s.planes = {{{1, 0, 0}, 0.7}, {{0, -1, 0}, 0.6}, {{0, 0, -1}, 2.0}};
    return s;
}

tsdf::TsdfConfig volumeConfig() {
    tsdf::TsdfConfig c;
    c.voxel_size_m = 0.01f;
    c.truncation_m = 0.04f;
    c.allocation_stride_px = 1;
    return c;
}

/// Looking into the corner, so that each plane fills about a third of the image.
Eigen::Isometry3d referencePose() {
    return testing::lookAt(Eigen::Vector3d(0.1, -0.1, 0.0), Eigen::Vector3d(-0.7, 0.6, 2.0));
}

IcpResult alignWithOffset(const testing::Scene& scene, const Vector6d& offset,
                          Eigen::Isometry3d* T_true, const IcpConfig& config = {},
                          int model_level = 0) {
    const PinholeCamera cam = cameraPreset("primesense").value().scaled(0.5);
    const Eigen::Isometry3d T_M_ref = referencePose();
    tsdf::TsdfVolume volume(volumeConfig());
    EXPECT_TRUE(volume.integrate(scene.render(cam, T_M_ref), cam, T_M_ref).isOk());
    *T_true = lie::expSE3(offset) * T_M_ref;
    const FramePyramid frame =
        preprocess(scene.render(cam, *T_true), cam, PreprocessConfig{}).value();
    const std::vector<ModelLevel> model =
        predictModel(volume, frame, T_M_ref, tsdf::RaycastConfig{}, model_level);
    return alignFrameToModel(frame, model, T_M_ref, T_M_ref, config);
}

TEST(Icp, ConvergesFromTwoCentimetresAndTwoDegrees) {
    const double a = 2.0 * kDeg / std::sqrt(3.0), t = 0.02 / std::sqrt(3.0);
    const Vector6d offsets[] = {
        (Vector6d() << a, a, a, t, t, t).finished(),
        (Vector6d() << -a, a, -a, t, -t, -t).finished(),
        (Vector6d() << 2.0 * kDeg, 0, 0, 0, 0.02, 0).finished(),
        (Vector6d() << 0, 0, -2.0 * kDeg, -0.02, 0, 0).finished(),
    };
    for (const Vector6d& offset : offsets) {
        Eigen::Isometry3d T_true;
        const IcpResult r = alignWithOffset(corner(), offset, &T_true);
        EXPECT_TRUE(r.ok) << r.failure;
        const Eigen::Isometry3d err = T_true.inverse() * r.T_M_C;
        EXPECT_LT(err.translation().norm(), 0.001) << offset.transpose();
        EXPECT_LT(lie::rotationAngle(err), 0.05 * kDeg) << offset.transpose();
        EXPECT_GT(r.inlier_fraction, 0.8);
        EXPECT_LT(r.rmse_m, 0.001);
    }
}

TEST(Icp, AHalfResolutionModelServesEveryLevel) {
    // The model raycast at level 1 only: level 0 associates against the same (coarser) image,
    // level 2 against its 2x2 average. The corner still converges to sub-millimetre.
    const double a = 2.0 * kDeg / std::sqrt(3.0), t = 0.02 / std::sqrt(3.0);
    const Vector6d offset = (Vector6d() << a, -a, a, -t, t, t).finished();
    Eigen::Isometry3d T_true;
    const IcpResult r = alignWithOffset(corner(), offset, &T_true, {}, /*model_level=*/1);
    ASSERT_TRUE(r.ok) << r.failure;
    const Eigen::Isometry3d err = T_true.inverse() * r.T_M_C;
    EXPECT_LT(err.translation().norm(), 0.001);
    EXPECT_LT(lie::rotationAngle(err), 0.05 * kDeg);
    EXPECT_GT(r.inlier_fraction, 0.8);

    const PinholeCamera cam = cameraPreset("primesense").value().scaled(0.5);
    tsdf::TsdfVolume volume(volumeConfig());
    ASSERT_TRUE(
        volume.integrate(corner().render(cam, referencePose()), cam, referencePose()).isOk());
    const FramePyramid frame = preprocess(corner().render(cam, referencePose()), cam, {}).value();
    const std::vector<ModelLevel> model = predictModel(volume, frame, referencePose(), {}, 1);
    ASSERT_EQ(model.size(), frame.levels.size());
    EXPECT_EQ(model[0].camera.width, frame.levels[1].camera.width);  // level 0 uses level 1's rays
    for (size_t l = 1; l < model.size(); ++l)
        EXPECT_EQ(model[l].camera.width, frame.levels[l].camera.width);
}

TEST(Icp, ASinglePlaneKeepsThePredictionAlongItOrFailsWhenAskedTo) {
    testing::Scene plane;
    plane.planes = {{{0, 0, -1}, 1.5}};  // a wall filling the view
    // The camera is 1 cm along the wall and 1 cm closer to it than predicted (the model pose).
    const Vector6d offset = (Vector6d() << 0, 0, 0, 0.01, 0, -0.01).finished();
    Eigen::Isometry3d T_true;
    const IcpResult tracked = alignWithOffset(plane, offset, &T_true);
    ASSERT_TRUE(tracked.ok) << tracked.failure;  // default: up to 2 free translations
    EXPECT_EQ(tracked.num_degenerate_directions, 2);
    // Depth observes the distance to the wall: corrected. It cannot see the slide along the wall:
    // that stays near the prediction (the reference pose; the small rotations the oblique view
    // does constrain move it by a few mm) instead of following noise.
    const Eigen::Vector3d n_W = Eigen::Vector3d(0, 0, -1);
    const Eigen::Vector3d predicted = referencePose().translation();
    const Eigen::Vector3d estimated = tracked.T_M_C.translation();
    EXPECT_NEAR(n_W.dot(estimated), n_W.dot(T_true.translation()), 0.002);
    const Eigen::Vector3d along = (estimated - predicted) - n_W * n_W.dot(estimated - predicted);
    EXPECT_LT(along.norm(), 0.005);

    IcpConfig strict;
    strict.max_degenerate_directions = 1;
    const IcpResult r = alignWithOffset(plane, offset, &T_true, strict);
    EXPECT_FALSE(r.ok) << r.condition_number;
    EXPECT_NE(r.failure.find("degenerate"), std::string::npos) << r.failure;
}

TEST(Icp, ACorridorKeepsThePredictionAlongItsAxis) {
    // Looking down a corridor (walls, floor and ceiling parallel to z; its far end beyond the
    // 4 m range): only a ball 2 m ahead faces the camera, under 1 % of the pixels. The ball has
    // rolled 5 cm away since the model was fused, and the camera moved 1 cm sideways.
    testing::Scene corridor;
    corridor.planes = {{{1, 0, 0}, 0.8}, {{-1, 0, 0}, 0.8}, {{0, 1, 0}, 0.6}, {{0, -1, 0}, 0.7}};
    testing::Scene moved = corridor;
    corridor.spheres = {{{0.2, 0.1, 2.0}, 0.05}};
    moved.spheres = {{{0.2, 0.1, 2.05}, 0.05}};
    const PinholeCamera cam = cameraPreset("primesense").value().scaled(0.5);
    const Eigen::Isometry3d T_ref = Eigen::Isometry3d::Identity();
    tsdf::TsdfVolume volume(volumeConfig());
    ASSERT_TRUE(volume.integrate(corridor.render(cam, T_ref), cam, T_ref).isOk());
    const Eigen::Isometry3d T_true = Eigen::Translation3d(0.01, 0.0, 0.0) * T_ref;
    const FramePyramid frame = preprocess(moved.render(cam, T_true), cam, {}).value();
    const std::vector<ModelLevel> model = predictModel(volume, frame, T_ref, {});

    // The axis counts as unconstrained (mean (n.z)^2 below min_normal_spread): the pose keeps the
    // prediction along it instead of following the ball; the sideways step is corrected.
    const IcpResult r = alignFrameToModel(frame, model, T_ref, T_ref, {});
    ASSERT_TRUE(r.ok) << r.failure;
    EXPECT_EQ(r.num_degenerate_directions, 1) << r.translation_spread.transpose();
    EXPECT_LT(r.translation_spread(0), IcpConfig{}.min_normal_spread);
    EXPECT_GT(std::abs(r.translation_axes_M.col(0).z()), 0.99);
    EXPECT_NEAR(r.T_M_C.translation().x(), 0.01, 0.002);
    EXPECT_NEAR(r.T_M_C.translation().z(), 0.0, 0.002);

    // With the threshold at zero the ball is the only constraint along the axis and drags the
    // camera with it: the data do carry that (wrong) signal, the remapping is what ignores it.
    IcpConfig follow;
    follow.min_normal_spread = 0.0;
    const IcpResult f = alignFrameToModel(frame, model, T_ref, T_ref, follow);
    EXPECT_LT(f.T_M_C.translation().z(), -0.02);  // backwards, to keep its distance
}

TEST(Icp, DetectsEmptyFrame) {
    const PinholeCamera cam = cameraPreset("ci").value();
    tsdf::TsdfVolume volume(volumeConfig());
    const Eigen::Isometry3d T = referencePose();
    ASSERT_TRUE(volume.integrate(corner().render(cam, T), cam, T).isOk());
    const FramePyramid frame =
        preprocess(DepthImage(cam.width, cam.height, 0.0f), cam, PreprocessConfig{}).value();
    const IcpResult r = alignFrameToModel(frame, predictModel(volume, frame, T, {}), T, T, {});
    EXPECT_FALSE(r.ok);
    EXPECT_NE(r.failure.find("too few inliers"), std::string::npos) << r.failure;
}

TEST(Icp, CorrespondenceKernelsAgreeBitForBit) {
    // The AVX2 correspondence search (8 pixels in lanes) must pass exactly the pixels the scalar
    // loop passes, so the whole result is identical: noisy depth with holes, 2 cm / 2 deg off,
    // an image width that is not a multiple of 8 (the scalar tail), and a half-resolution model.
    if (simd::best() != simd::Level::kAvx2) GTEST_SKIP() << "this CPU has no AVX2";
    PinholeCamera cam = cameraPreset("primesense").value().scaled(0.5);
    cam.width = 300;  // 300, 150 and 75 px levels: none a multiple of 8
    const Eigen::Isometry3d T_ref = referencePose();
    tsdf::TsdfVolume volume(volumeConfig());
    ASSERT_TRUE(volume.integrate(corner().render(cam, T_ref, 3), cam, T_ref).isOk());
    const Eigen::Isometry3d T_true =
        lie::expSE3((Vector6d() << 0.02, -0.02, 0.01, 0.015, -0.01, 0.01).finished()) * T_ref;
    DepthImage depth = corner().render(cam, T_true, 5);
    for (int v = 0; v < depth.height(); ++v) {
        for (int u = 0; u < depth.width(); ++u) {
            if ((u / 4 + v / 3) % 9 == 0) depth(u, v) = 0.0f;  // holes
        }
    }
    const FramePyramid frame = preprocess(depth, cam, {}).value();
    for (const int model_level : {0, 1}) {
        const auto model = predictModel(volume, frame, T_ref, {}, model_level);
        IcpResult a, b;
        {
            const simd::ScopedLevel portable(simd::Level::kPortable);
            a = alignFrameToModel(frame, model, T_ref, T_ref, {});
        }
        b = alignFrameToModel(frame, model, T_ref, T_ref, {});
        ASSERT_TRUE(a.ok) << a.failure;
        EXPECT_GT(a.num_inliers, 10000u);
        EXPECT_EQ(a.T_M_C.matrix(), b.T_M_C.matrix()) << "model level " << model_level;
        EXPECT_EQ(a.information, b.information);
        EXPECT_EQ(a.num_inliers, b.num_inliers);
        EXPECT_EQ(a.rmse_m, b.rmse_m);
        EXPECT_EQ(a.iterations, b.iterations);
    }
}

TEST(Icp, ResultDoesNotDependOnThreadCount) {
    const PinholeCamera cam = cameraPreset("ci").value();
    const Eigen::Isometry3d T_ref = referencePose();
    tsdf::TsdfVolume volume(volumeConfig());
    ASSERT_TRUE(volume.integrate(corner().render(cam, T_ref), cam, T_ref).isOk());
    const Eigen::Isometry3d T_true =
        lie::expSE3((Vector6d() << 0.01, 0.02, 0, 0.01, 0, 0.01).finished()) * T_ref;
    const FramePyramid frame = preprocess(corner().render(cam, T_true), cam, {}).value();
    const auto model = predictModel(volume, frame, T_ref, {});
    IcpConfig one, two;
    one.num_threads = 1;
    two.num_threads = 2;
    const IcpResult a = alignFrameToModel(frame, model, T_ref, T_ref, one);
    const IcpResult b = alignFrameToModel(frame, model, T_ref, T_ref, two);
    EXPECT_EQ(a.T_M_C.matrix(), b.T_M_C.matrix());
    EXPECT_EQ(a.num_inliers, b.num_inliers);
}

}  // namespace
}  // namespace plumb::device
