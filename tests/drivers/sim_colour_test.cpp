// SPDX-License-Identifier: Apache-2.0
// The simulator's colour camera: textures, shading, noise, exposure (issue 27, reference §7b).
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "drivers/sim/colour.hpp"
#include "drivers/sim/render.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/sim/texture.hpp"
#include "drivers/sim/trajectory.hpp"

namespace plumb::sim {
namespace {

// An empty 8 m x 6 m room; wall 1 is the plane x = 8, running from (8, 0) to (8, 6).
Scene emptyRoom() {
    Scene s;
    s.name = "empty";
    s.polygon = {{0, 0}, {8, 0}, {8, 6}, {0, 6}};
    s.height_m = 3.0;
    return s;
}

// Camera at `p` looking along +x (fronto-parallel to wall 1).
Eigen::Isometry3d facingWall1(const Eigen::Vector3d& p) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = cameraRotation(0.0, 0.0, 0.0);
    T.translation() = p;
    return T;
}

// Central-difference intensity gradient magnitude, intensity in [0, 1] per pixel; 0 at the
// border.
Image<float> gradientMagnitude(const ColourImage& colour) {
    const Image<float> I = toIntensity(colour);
    Image<float> g(I.width(), I.height(), 0.0F);
    for (int v = 1; v + 1 < I.height(); ++v) {
        for (int u = 1; u + 1 < I.width(); ++u) {
            const float gx = 0.5F * (I(u + 1, v) - I(u - 1, v));
            const float gy = 0.5F * (I(u, v + 1) - I(u, v - 1));
            g(u, v) = std::sqrt(gx * gx + gy * gy);
        }
    }
    return g;
}

// Fraction of the interior pixels labelled `label` (with the same label in their 3x3
// neighbourhood) whose gradient magnitude exceeds `threshold`.
double fractionAbove(const Image<float>& grad, const Image<int16_t>& label, int wanted,
                     float threshold, size_t* counted = nullptr) {
    size_t n = 0, above = 0;
    for (int v = 1; v + 1 < grad.height(); ++v) {
        for (int u = 1; u + 1 < grad.width(); ++u) {
            bool same = true;
            for (int dv = -1; dv <= 1; ++dv) {
                for (int du = -1; du <= 1; ++du) same &= label(u + du, v + dv) == wanted;
            }
            if (!same) continue;
            ++n;
            above += grad(u, v) > threshold;
        }
    }
    if (counted != nullptr) *counted = n;
    return n == 0 ? 0.0 : static_cast<double>(above) / n;
}

double meanIntensity(const ColourImage& c, const Image<int16_t>& label) {
    double sum = 0.0;
    size_t n = 0;
    for (size_t i = 0; i < c.size(); ++i) {
        if (label.data()[i] == kNoPrimitive) continue;
        sum += intensity(c.data()[i]);
        ++n;
    }
    return sum / n;
}

SimConfig smallConfig() {
    SimConfig c;
    c.scene = "living_room";
    c.camera = *cameraPreset("ci");
    c.trajectory.num_frames = 12;
    c.noise.distortion = DistortionKind::kParametric;  // no shared data needed
    c.seed = 5;
    return c;
}

TEST(SimColour, FramesAreDeterministicAndIndependentOfThreadCount) {
    SimConfig config = smallConfig();
    config.camera = PinholeCamera{};  // 640x480: several TBB tasks per image
    auto a = SimSource::create(config);
    auto b = SimSource::create(config);
    ASSERT_TRUE(a.isOk() && b.isOk()) << a.status().toString();
    auto fa = (*a)->render(4);
    auto fa_again = (*a)->render(4);
    auto fb = (*b)->render(4);
    ASSERT_TRUE(fa.isOk() && fa_again.isOk() && fb.isOk());
    ASSERT_EQ(fa->frame.colour.width(), 640);
    ASSERT_EQ(fa->frame.colour.height(), 480);
    EXPECT_TRUE(fa->frame.colour == fa_again->frame.colour);
    EXPECT_TRUE(fa->frame.colour == fb->frame.colour);
    EXPECT_TRUE(fa->view.colour == fb->view.colour);
    {
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        auto single = (*a)->render(4);
        ASSERT_TRUE(single.isOk());
        EXPECT_TRUE(single->frame.colour == fa->frame.colour);
        EXPECT_TRUE(single->view.colour == fa->view.colour);
    }
    // Another noise seed: other noise on the same clean (textured) image.
    SimConfig other = config;
    other.seed = 6;
    auto c = SimSource::create(other);
    ASSERT_TRUE(c.isOk());
    auto fc = (*c)->render(4);
    ASSERT_TRUE(fc.isOk());
    EXPECT_TRUE(fc->view.colour == fa->view.colour);
    EXPECT_FALSE(fc->frame.colour == fa->frame.colour);
}

TEST(SimColour, ColourLeavesDepthAndGreyUntouched) {
    SimConfig with = smallConfig();
    SimConfig without = smallConfig();
    without.colour.enabled = false;
    auto a = SimSource::create(with);
    auto b = SimSource::create(without);
    ASSERT_TRUE(a.isOk() && b.isOk());
    for (size_t k = 0; k < 12; k += 5) {
        auto fa = (*a)->render(k);
        auto fb = (*b)->render(k);
        ASSERT_TRUE(fa.isOk() && fb.isOk());
        EXPECT_TRUE(fa->frame.depth == fb->frame.depth) << k;
        EXPECT_TRUE(fa->frame.gray == fb->frame.gray) << k;
        EXPECT_TRUE(fa->view.depth == fb->view.depth) << k;
        EXPECT_FALSE(fa->frame.colour.empty());
        EXPECT_TRUE(fb->frame.colour.empty());
        EXPECT_TRUE(fb->view.colour.empty());
    }
}

TEST(SimColour, TexturedWallHasStrongGradientsPlainWallHasNone) {
    // A camera sliding parallel to a wall 1-2 m away: the textured wall shows intensity
    // gradients above 0.005 per pixel (1.3 grey levels) over most of the image, the plaster alone
    // (no pictures) over much of it; a plain wall over (almost) none.
    const PinholeCamera camera;  // 640x480, fx = 525
    Scene textured = emptyRoom();
    Scene plaster = emptyRoom();
    plaster.pictures_per_wall = 0;
    Scene plain = emptyRoom();
    plain.texture = TextureMode::kPlain;
    const Renderer r_textured(textured, camera), r_plaster(plaster, camera), r_plain(plain, camera);
    RenderedView view;
    for (const double dist : {1.0, 1.5, 2.0}) {
        for (const double y : {1.5, 3.0, 4.5}) {
            const Eigen::Isometry3d T_W_C = facingWall1({8.0 - dist, y, 1.5});
            size_t n = 0;
            r_textured.render(T_W_C, &view);
            const double f_textured =
                fractionAbove(gradientMagnitude(view.colour), view.label, wallLabel(1), 0.005F, &n);
            ASSERT_GT(n, 200000U);
            const double f_textured_strong =
                fractionAbove(gradientMagnitude(view.colour), view.label, wallLabel(1), 0.01F);
            r_plaster.render(T_W_C, &view);
            const double f_plaster =
                fractionAbove(gradientMagnitude(view.colour), view.label, wallLabel(1), 0.005F);
            r_plain.render(T_W_C, &view);
            const double f_plain =
                fractionAbove(gradientMagnitude(view.colour), view.label, wallLabel(1), 0.005F);
            std::printf(
                "[colour] wall at %.1f m, y = %.1f: |grad I| > 0.005: textured %.1f%% (> 0.01: "
                "%.1f%%), plaster only %.1f%%; plain %.2f%%\n",
                dist, y, 100.0 * f_textured, 100.0 * f_textured_strong, 100.0 * f_plaster,
                100.0 * f_plain);
            EXPECT_GT(f_textured, 0.45) << dist << " m, y " << y;
            EXPECT_GT(f_plaster, 0.55) << dist << " m, y " << y;
            EXPECT_LT(f_plain, 0.001) << dist << " m, y " << y;
        }
    }
}

}  // namespace
}  // namespace plumb::sim
