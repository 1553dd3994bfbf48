// SPDX-License-Identifier: Apache-2.0
// The simulator's colour camera: textures, shading, noise, exposure (issue 27, reference §7b).
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#if PLUMB_TEST_HAVE_OPENCV
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#endif

#include "common/camera/pinhole.hpp"
#include "drivers/sim/colour.hpp"
#include "drivers/sim/render.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/sim/texture.hpp"
#include "drivers/sim/trajectory.hpp"
#include "tests/testing/shared_data.hpp"

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
    // gradients above 0.005 per pixel (1.3 grey levels; the noise-free image) over about half of
    // the wall at 1 m and three quarters at 2 m, the plaster alone (no pictures) over two thirds
    // or more; a plain wall over none (its shading changes by less than that).
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

// The colour of pixel (u, v) in a plain room: the surface the depth pixel (u, v) sees, shaded by
// the cosine of the depth render: round(255 rho (ambient + (1 - ambient) cos)).
Rgb8 expectedPlainColour(const Scene& s, int label, float cosv, float ambient) {
    Colour rho = s.wall_colour;
    const int nw = s.numWalls(), nb = static_cast<int>(s.boxes.size());
    if (label == floorLabel()) {
        rho = s.floor_colour;
    } else if (label == ceilingLabel()) {
        rho = s.ceiling_colour;
    } else if (label >= 2 + nw + nb) {
        rho = s.cylinders[label - 2 - nw - nb].colour;
    } else if (label >= 2 + nw) {
        rho = s.boxes[label - 2 - nw].colour;
    }
    const float light = 255.0F * ambient + 255.0F * (1.0F - ambient) * cosv;
    auto level = [&](float r) { return static_cast<uint8_t>(std::min(255.0F, r * light) + 0.5F); };
    return {level(rho.x()), level(rho.y()), level(rho.z())};
}

TEST(SimColour, PlainColourIsTheSurfaceTheDepthPixelSees) {
    // Registration, pixel by pixel: in a plain room every colour pixel is the shaded base colour
    // of the primitive in the label image at the same pixel, so colour edges fall exactly on the
    // depth render's edges; no pixel with depth lacks colour and none without has any.
    for (const char* name : {"living_room", "l_shape"}) {
        Scene scene = *builtinScene(name);
        scene.texture = TextureMode::kPlain;
        const PinholeCamera camera;
        const Renderer renderer(scene, camera);
        TrajectoryConfig tc;
        tc.num_frames = 200;
        const io::Trajectory traj = *generateTrajectory(scene, tc);
        RenderedView view;
        size_t mismatched = 0, hit = 0, label_edges = 0, colour_jumps_at_edges = 0;
        for (size_t k = 0; k < traj.size(); k += 40) {
            renderer.render(traj[k].T_W_C, &view);
            for (int v = 0; v < camera.height; ++v) {
                for (int u = 0; u < camera.width; ++u) {
                    const int label = view.label(u, v);
                    const Rgb8 c = view.colour(u, v);
                    if (label == kNoPrimitive) {
                        mismatched += !(c == Rgb8{}) || view.depth(u, v) != 0.0F;
                        continue;
                    }
                    ++hit;
                    const Rgb8 e = expectedPlainColour(scene, label, view.cos_view(u, v),
                                                       RenderConfig{}.ambient);
                    mismatched += std::abs(c.r - e.r) > 1 || std::abs(c.g - e.g) > 1 ||
                                  std::abs(c.b - e.b) > 1;
                    // Where the label changes between horizontal neighbours of different base
                    // colours, the colour changes between the same two pixels.
                    if (u + 1 < camera.width && view.label(u + 1, v) != label &&
                        view.label(u + 1, v) != kNoPrimitive) {
                        const Rgb8 e1 =
                            expectedPlainColour(scene, view.label(u + 1, v), 1.0F, 1.0F);
                        const Rgb8 e0 = expectedPlainColour(scene, label, 1.0F, 1.0F);
                        if (e0 == e1) continue;
                        ++label_edges;
                        colour_jumps_at_edges += !(view.colour(u + 1, v) == c);
                    }
                }
            }
        }
        EXPECT_GT(hit, 1000000U) << name;
        EXPECT_EQ(mismatched, 0U) << name;
        EXPECT_GT(label_edges, 1000U) << name;
        EXPECT_GT(colour_jumps_at_edges, 0.99 * label_edges) << name;
    }
}

TEST(SimColour, TextureMovesWithTheSurface) {
    // Two views of a textured wall 1.5 m away from positions 3 cm apart: warping the first into
    // the second with the clean depth and the true poses lands every wall pixel on the same
    // albedo (shading divided out), at the 8-bit quantisation level. The same warp one pixel off
    // is several times worse: the colour is registered to the geometry to well under a pixel.
    Scene scene = emptyRoom();
    const PinholeCamera camera;
    const Renderer renderer(scene, camera);
    const Eigen::Isometry3d T_W_a = facingWall1({6.5, 3.0, 1.5});
    const Eigen::Isometry3d T_W_b = facingWall1({6.5, 3.03, 1.51});
    RenderedView a, b;
    renderer.render(T_W_a, &a);
    renderer.render(T_W_b, &b);
    const float ambient = RenderConfig{}.ambient;
    auto albedoImage = [&](const RenderedView& view) {
        Image<float> out = toIntensity(view.colour);
        for (size_t i = 0; i < out.size(); ++i) {
            out.data()[i] /= ambient + (1.0F - ambient) * view.cos_view.data()[i];
        }
        return out;
    };
    const Image<float> A = albedoImage(a), B = albedoImage(b);
    auto bilinear = [](const Image<float>& img, double x, double y) {
        const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
        const double fx = x - x0, fy = y - y0;
        return (1 - fy) * ((1 - fx) * img(x0, y0) + fx * img(x0 + 1, y0)) +
               fy * ((1 - fx) * img(x0, y0 + 1) + fx * img(x0 + 1, y0 + 1));
    };
    const Eigen::Isometry3d T_b_a = T_W_b.inverse() * T_W_a;
    std::vector<double> err, err_shifted;
    for (int v = 20; v < camera.height - 20; ++v) {
        for (int u = 20; u < camera.width - 20; ++u) {
            if (a.label(u, v) != wallLabel(1)) continue;
            const Eigen::Vector2d px =
                camera.project(T_b_a * camera.unproject(u, v, a.depth(u, v)));
            if (px.x() < 2 || px.y() < 2 || px.x() > camera.width - 3 ||
                px.y() > camera.height - 3) {
                continue;
            }
            err.push_back(std::abs(A(u, v) - bilinear(B, px.x(), px.y())));
            err_shifted.push_back(std::abs(A(u, v) - bilinear(B, px.x() + 1.0, px.y())));
        }
    }
    ASSERT_GT(err.size(), 200000U);
    auto median = [](std::vector<double> x) {
        std::nth_element(x.begin(), x.begin() + x.size() / 2, x.end());
        return x[x.size() / 2];
    };
    const double m = median(err), m_shifted = median(err_shifted);
    std::printf("[colour] warped albedo: median |error| %.4f (%.2f levels); one pixel off %.4f\n",
                m, 255.0 * m, m_shifted);
    EXPECT_LT(m, 1.0 / 255.0);
    EXPECT_GT(m_shifted, 2.5 * m);
}

TEST(SimColour, PictureEdgesProjectWhereTheGeometrySaysTheyAre) {
    // The first picture on wall 1, seen from 1.5 m with its left edge (a world point on the wall)
    // projecting to x = 424.3: pixel 423 is all frame, 425 all plaster, and 424 (whose footprint,
    // 1.02 px wide, reaches from 423.49 to 424.51) 79 % frame: the colour edge sits where the
    // geometry puts it, to a fraction of a pixel.
    const Scene scene = emptyRoom();
    const PinholeCamera camera;
    const Renderer renderer(scene, camera);
    ASSERT_FALSE(renderer.textures().pictures(1).empty());
    const Picture& pic = renderer.textures().pictures(1).front();
    const double z_mid = 0.5 * (pic.z_min_m + pic.z_max_m);
    const double x_edge = 424.3;
    // Wall 1 runs from (8, 0) to (8, 6): s is y, and image x runs along -y.
    const double offset = (x_edge - camera.cx) * 1.5 / camera.fx;
    const Eigen::Isometry3d T_W_C = facingWall1({6.5, pic.s_min_m + offset, z_mid});
    RenderedView view;
    renderer.render(T_W_C, &view);
    const Eigen::Vector2d edge =
        camera.project(T_W_C.inverse() * Eigen::Vector3d(8.0, pic.s_min_m, z_mid));
    ASSERT_NEAR(edge.x(), x_edge, 1e-6);
    const double fp_px = 1.0 / view.cos_view(424, 240);  // z / (f cos) in pixels of z / f
    const double frame_share = (x_edge - (424.0 - 0.5 * fp_px)) / fp_px;
    EXPECT_NEAR(frame_share, 0.79, 0.01);
    int rows = 0;
    for (int v = static_cast<int>(edge.y()) - 20; v <= static_cast<int>(edge.y()) + 20; ++v) {
        const float light = 255.0F * (0.1F + 0.9F * view.cos_view(423, v));
        const Rgb8 frame = view.colour(423, v);
        EXPECT_NEAR(frame.r, pic.frame.x() * light, 1.0) << v;
        EXPECT_NEAR(frame.g, pic.frame.y() * light, 1.0) << v;
        EXPECT_NEAR(frame.b, pic.frame.z() * light, 1.0) << v;
        const float i_frame = intensity(frame), i_wall = intensity(view.colour(425, v));
        EXPECT_GT(i_wall, i_frame + 0.15F) << v;
        const double blend = frame_share * i_frame + (1.0 - frame_share) * i_wall;
        EXPECT_NEAR(intensity(view.colour(424, v)), blend, 0.02) << v;
        ++rows;
    }
    EXPECT_EQ(rows, 41);
}

TEST(SimColour, NoiseStdMatchesTheConfiguration) {
    // The colour noise is round(sigma z) per channel: std sqrt(sigma^2 + 1/12) levels, zero
    // mean, independent channels and frames.
    for (const double sigma : {2.0, 6.0}) {
        SimConfig config = smallConfig();
        config.camera = PinholeCamera{};
        config.colour.noise_std_levels = sigma;
        auto source = SimSource::create(config);
        ASSERT_TRUE(source.isOk());
        auto f = (*source)->render(3);
        auto g = (*source)->render(4);
        ASSERT_TRUE(f.isOk() && g.isOk());
        double sum[3] = {0, 0, 0}, sq[3] = {0, 0, 0}, rg = 0.0, across = 0.0;
        size_t n = 0;
        for (size_t i = 0; i < f->frame.colour.size(); ++i) {
            const Rgb8 c = f->view.colour.data()[i], c2 = g->view.colour.data()[i];
            if (std::min({c.r, c.g, c.b, c2.r}) < 30 || std::max({c.r, c.g, c.b, c2.r}) > 225) {
                continue;
            }
            const Rgb8 o = f->frame.colour.data()[i];
            const double d[3] = {o.r - c.r + 0.0, o.g - c.g + 0.0, o.b - c.b + 0.0};
            for (int ch = 0; ch < 3; ++ch) {
                sum[ch] += d[ch];
                sq[ch] += d[ch] * d[ch];
            }
            rg += d[0] * d[1];
            across += d[0] * (g->frame.colour.data()[i].r - c2.r);
            ++n;
        }
        ASSERT_GT(n, 100000U);
        const double expected = std::sqrt(sigma * sigma + 1.0 / 12.0);
        for (int ch = 0; ch < 3; ++ch) {
            const double mean = sum[ch] / n;
            const double std = std::sqrt(sq[ch] / n - mean * mean);
            EXPECT_NEAR(std, expected, 0.03 * expected) << "sigma " << sigma << " channel " << ch;
            EXPECT_LT(std::abs(mean), 0.03 * sigma) << "sigma " << sigma << " channel " << ch;
        }
        const double var = sq[0] / n;
        EXPECT_LT(std::abs(rg / n) / var, 0.02) << "red and green noise correlate";
        EXPECT_LT(std::abs(across / n) / var, 0.02) << "consecutive frames' noise correlates";
    }
    // No noise and constant exposure: the camera delivers the clean render.
    SimConfig quiet = smallConfig();
    quiet.colour.noise_std_levels = 0.0;
    auto source = SimSource::create(quiet);
    ASSERT_TRUE(source.isOk());
    auto f = (*source)->render(2);
    ASSERT_TRUE(f.isOk());
    EXPECT_TRUE(f->frame.colour == f->view.colour);
}

TEST(SimColour, ExposureJumpScalesTheMeanIntensityByItsFactor) {
    SimConfig steady = smallConfig();
    SimConfig jumpy = smallConfig();
    jumpy.colour.exposure_jumps = {{6, 0.6}, {9, 1.25}};
    auto a = SimSource::create(steady);
    auto b = SimSource::create(jumpy);
    ASSERT_TRUE(a.isOk() && b.isOk());
    for (const auto& [k, factor] :
         std::vector<std::pair<size_t, double>>{{5, 1.0}, {6, 0.6}, {8, 0.6}, {9, 0.75}}) {
        auto fa = (*a)->render(k);
        auto fb = (*b)->render(k);
        ASSERT_TRUE(fa.isOk() && fb.isOk());
        EXPECT_DOUBLE_EQ(fb->exposure_gain, factor) << k;
        EXPECT_DOUBLE_EQ(fa->exposure_gain, 1.0) << k;
        EXPECT_TRUE(fa->view.colour == fb->view.colour) << "the clean render is unchanged";
        const double ratio = meanIntensity(fb->frame.colour, fb->view.label) /
                             meanIntensity(fa->frame.colour, fa->view.label);
        std::printf("[colour] frame %zu: exposure %.2f, mean intensity ratio %.4f\n", k, factor,
                    ratio);
        EXPECT_NEAR(ratio, factor, 0.01 * factor) << "frame " << k;
        if (factor == 1.0) {
            EXPECT_TRUE(fa->frame.colour == fb->frame.colour) << k;
        }
    }
}

TEST(SimColour, ExposureDriftIsSmoothWithTheConfiguredSpread) {
    ColourConfig c;
    for (uint64_t k = 0; k < 1000; k += 7) EXPECT_EQ(exposureGain(c, 3, k), 1.0);
    c.exposure_log_std = 0.2;
    c.exposure_period_frames = 30.0;
    double sum = 0.0, sq = 0.0, max_step = 0.0, sum_step = 0.0;
    const int n = 300000;
    double prev = std::log(exposureGain(c, 3, 0));
    for (int k = 0; k < n; ++k) {
        const double lg = std::log(exposureGain(c, 3, k));
        sum += lg;
        sq += lg * lg;
        max_step = std::max(max_step, std::abs(lg - prev));
        sum_step += std::abs(lg - prev);
        prev = lg;
    }
    const double mean = sum / n, std = std::sqrt(sq / n - mean * mean);
    EXPECT_NEAR(std, 0.2, 0.01);
    EXPECT_LT(std::abs(mean), 0.01);
    // Smooth: a step is at most about sigma sqrt(2) 1.5 / period |z1 - z0| (< 0.1 here), a
    // typical one a few thousandths.
    EXPECT_LT(max_step, 0.1);
    EXPECT_LT(sum_step / n, 0.01);
    EXPECT_GT(max_step, 0.0);
    EXPECT_EQ(exposureGain(c, 3, 1234), exposureGain(c, 3, 1234));
    EXPECT_NE(exposureGain(c, 3, 1234), exposureGain(c, 4, 1234));
    // The frames carry the drift: their mean intensity follows the gain.
    SimConfig drifting = smallConfig();
    drifting.colour = c;
    SimConfig steady = smallConfig();
    auto a = SimSource::create(drifting);
    auto b = SimSource::create(steady);
    ASSERT_TRUE(a.isOk() && b.isOk());
    auto fa = (*a)->render(10);
    auto fb = (*b)->render(10);
    ASSERT_TRUE(fa.isOk() && fb.isOk());
    const double gain = exposureGain(c, drifting.seed, 10);
    EXPECT_DOUBLE_EQ(fa->exposure_gain, gain);
    if (gain < 1.0) {  // no clipping at the top: the ratio is the gain
        EXPECT_NEAR(meanIntensity(fa->frame.colour, fa->view.label) /
                        meanIntensity(fb->frame.colour, fb->view.label),
                    gain, 0.01 * gain);
    }
}

TEST(SimColour, BadColourSettingsAreErrorsThatNameTheField) {
    SimConfig c = smallConfig();
    c.colour.noise_std_levels = -1.0;
    auto bad = SimSource::create(c);
    ASSERT_FALSE(bad.isOk());
    EXPECT_NE(bad.status().message().find("noise_std_levels"), std::string::npos);
    c = smallConfig();
    c.colour.exposure_jumps = {{3, 0.0}};
    bad = SimSource::create(c);
    ASSERT_FALSE(bad.isOk());
    EXPECT_NE(bad.status().message().find("frame 3"), std::string::npos) << bad.status().message();
    c = smallConfig();
    c.colour.exposure_period_frames = 0.0;
    EXPECT_FALSE(SimSource::create(c).isOk());
}

TEST(SimColour, TextureOverrideAndPictures) {
    // Built-in rooms are textured; the override makes them plain (no pictures, one colour per
    // surface). Pictures sit inside their walls, clear of openings and of each other.
    for (const std::string& name : builtinSceneNames()) {
        SimConfig c = smallConfig();
        c.scene = name;
        auto textured = SimSource::create(c);
        ASSERT_TRUE(textured.isOk());
        EXPECT_EQ((*textured)->scene().texture, TextureMode::kTextured) << name;
        const Scene& s = (*textured)->scene();
        size_t pictures = 0;
        for (int k = 0; k < s.numWalls(); ++k) {
            const auto& pics = (*textured)->renderer().textures().pictures(k);
            pictures += pics.size();
            const double len = (s.polygon[(k + 1) % s.numWalls()] - s.polygon[k]).norm();
            for (size_t i = 0; i < pics.size(); ++i) {
                const Picture& p = pics[i];
                EXPECT_GE(p.s_min_m, 0.0);
                EXPECT_LE(p.s_max_m, len);
                EXPECT_GT(p.z_min_m, 0.0);
                EXPECT_LT(p.z_max_m, s.height_m);
                for (const Opening& o : s.openings) {
                    if (o.wall != k) continue;
                    const bool apart = p.s_max_m < o.offset_m ||
                                       p.s_min_m > o.offset_m + o.width_m ||
                                       p.z_max_m < o.z_min_m || p.z_min_m > o.z_max_m;
                    EXPECT_TRUE(apart) << name << " wall " << k << " picture " << i;
                }
                for (size_t j = 0; j < i; ++j) {
                    const Picture& q = pics[j];
                    EXPECT_TRUE(p.s_max_m < q.s_min_m || q.s_max_m < p.s_min_m ||
                                p.z_max_m < q.z_min_m || q.z_max_m < p.z_min_m)
                        << name << " wall " << k << " pictures " << j << ", " << i;
                }
            }
        }
        EXPECT_GE(pictures, static_cast<size_t>(s.numWalls())) << name;
        c.texture = TextureMode::kPlain;
        auto plain = SimSource::create(c);
        ASSERT_TRUE(plain.isOk());
        EXPECT_EQ((*plain)->scene().texture, TextureMode::kPlain);
        for (int k = 0; k < s.numWalls(); ++k) {
            EXPECT_TRUE((*plain)->renderer().textures().pictures(k).empty());
        }
        EXPECT_NE((*plain)->description().find("colour plain"), std::string::npos);
    }
}

TEST(SimScene, TomlColourKeysAndErrors) {
    const std::string text = R"(
name = "studio"
height_m = 2.7
polygon = [[0, 0], [5, 0], [5, 4], [0, 4]]
texture = "plain"
texture_seed = 7
wall_colour = [0.9, 0.5, 0.1]
floor_colour = [0.2, 0.2, 0.2]
ceiling_colour = [1, 1, 1]
floor_pattern = "tiles"
pictures_per_wall = 0
[[box]]
center = [2.5, 2.0, 0.4]
size = [1.0, 0.6, 0.8]
colour = [0.1, 0.6, 0.3]
pattern = "checker"
[[box]]
center = [1.0, 1.0, 0.4]
size = [0.5, 0.5, 0.8]
albedo = 0.3
[[cylinder]]
center = [4, 3]
radius_m = 0.3
z_max_m = 1.2
pattern = "stripes"
)";
    auto scene = parseSceneToml(text, "studio.toml");
    ASSERT_TRUE(scene.isOk()) << scene.status().toString();
    EXPECT_EQ(scene->texture, TextureMode::kPlain);
    EXPECT_EQ(scene->texture_seed, 7U);
    EXPECT_EQ(scene->wall_colour, Colour(0.9F, 0.5F, 0.1F));
    EXPECT_EQ(scene->ceiling_colour, Colour(1.0F, 1.0F, 1.0F));
    EXPECT_EQ(scene->floor_pattern, FloorPattern::kTiles);
    EXPECT_EQ(scene->pictures_per_wall, 0);
    ASSERT_EQ(scene->boxes.size(), 2U);
    EXPECT_EQ(scene->boxes[0].colour, Colour(0.1F, 0.6F, 0.3F));
    EXPECT_EQ(scene->boxes[0].pattern, FurniturePattern::kChecker);
    EXPECT_EQ(scene->boxes[1].colour, Colour::Constant(0.3F)) << "colour defaults to the albedo";
    EXPECT_EQ(scene->boxes[1].pattern, FurniturePattern::kSolid);
    EXPECT_EQ(scene->cylinders[0].pattern, FurniturePattern::kStripes);
    // Defaults: textured, wood floor, three pictures per wall.
    auto defaults = parseSceneToml("height_m = 2.5\npolygon = [[0,0],[3,0],[3,3],[0,3]]\n", "d");
    ASSERT_TRUE(defaults.isOk());
    EXPECT_EQ(defaults->texture, TextureMode::kTextured);
    EXPECT_EQ(defaults->floor_pattern, FloorPattern::kWood);
    EXPECT_EQ(defaults->pictures_per_wall, 3);

    // Each bad value: an error naming the source, the line, the key and the bad value.
    const std::string room = "height_m = 2.5\npolygon = [[0,0],[3,0],[3,3],[0,3]]\n";
    struct Bad {
        std::string text, where, key, detail;
    };
    const std::vector<Bad> bad = {
        {room + "texture = \"fancy\"\n", "bad.toml:3", "texture", "fancy"},
        {room + "texture = 1\n", "bad.toml:3", "texture", "plain"},
        {room + "floor_pattern = \"carpet\"\n", "bad.toml:3", "floor_pattern", "carpet"},
        {room + "wall_colour = [1.2, 0, 0]\n", "bad.toml:3", "wall_colour", "[0, 1]"},
        {room + "ceiling_colour = [1, 1]\n", "bad.toml:3", "ceiling_colour", "3 numbers"},
        {room + "pictures_per_wall = 40\n", "bad.toml:3", "pictures_per_wall", "12"},
        {room + "texture_seed = -2\n", "bad.toml:3", "texture_seed", "integer"},
        {room + "[[box]]\ncenter = [1, 1, 0.5]\nsize = [1, 1, 1]\npattern = \"dots\"\n",
         "bad.toml:6", "pattern", "dots"},
        {room + "[[cylinder]]\ncenter = [1, 1]\nradius_m = 0.2\nz_max_m = 1\ncolour = [0, -1, 0]\n",
         "bad.toml:7", "colour", "cylinder[0]"},
    };
    for (const Bad& b : bad) {
        auto r = parseSceneToml(b.text, "bad.toml");
        ASSERT_FALSE(r.isOk()) << b.text;
        const std::string& m = r.status().message();
        EXPECT_NE(m.find(b.where), std::string::npos) << m;
        EXPECT_NE(m.find("'" + b.key + "'"), std::string::npos) << m;
        EXPECT_NE(m.find(b.detail), std::string::npos) << m;
    }
}

std::string slurpFile(const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Non-comment lines of a TUM list.
std::vector<std::string> listLines(const std::filesystem::path& p) {
    std::istringstream in(slurpFile(p));
    std::vector<std::string> out;
    for (std::string line; std::getline(in, line);) {
        if (!line.empty() && line[0] != '#') out.push_back(line);
    }
    return out;
}

TEST(SimDataset, WritesRgbPngsAndListThatReadBack) {
    const auto dir = testing::freshTempDir("sim_dataset_rgb");
    auto source = SimSource::create(smallConfig());
    ASSERT_TRUE(source.isOk());
    SimDatasetOptions options;
    options.gt_spacing_m = 0.1;
    options.write_clean = false;
    ASSERT_TRUE(writeSimDataset(**source, dir, options).isOk());
    // rgb.txt: comments, then "timestamp rgb/NNNNN.png" at the depth timestamps.
    const std::string rgb_txt = slurpFile(dir / "rgb.txt");
    EXPECT_EQ(rgb_txt.rfind("# ", 0), 0U);
    const std::vector<std::string> rgb = listLines(dir / "rgb.txt");
    const std::vector<std::string> depth = listLines(dir / "depth.txt");
    ASSERT_EQ(rgb.size(), 12U);
    ASSERT_EQ(depth.size(), 12U);
    for (size_t k = 0; k < rgb.size(); ++k) {
        char name[32];
        std::snprintf(name, sizeof(name), "%05zu.png", k);
        EXPECT_EQ(rgb[k], depth[k].substr(0, depth[k].find(' ')) + " rgb/" + name);
        // An 8-bit RGB PNG (IHDR: bit depth 8, colour type 2).
        const std::string png = slurpFile(dir / "rgb" / name);
        ASSERT_GT(png.size(), 26U);
        EXPECT_EQ(png.substr(12, 4), "IHDR");
        EXPECT_EQ(static_cast<int>(png[24]), 8);
        EXPECT_EQ(static_cast<int>(png[25]), 2);
    }
#if PLUMB_TEST_HAVE_OPENCV
    for (const size_t k : {0UL, 7UL}) {
        char name[32];
        std::snprintf(name, sizeof(name), "%05zu.png", k);
        const cv::Mat bgr = cv::imread((dir / "rgb" / name).string(), cv::IMREAD_UNCHANGED);
        ASSERT_EQ(bgr.type(), CV_8UC3);
        auto f = (*source)->render(k);
        ASSERT_TRUE(f.isOk());
        ASSERT_EQ(bgr.cols, f->frame.colour.width());
        ASSERT_EQ(bgr.rows, f->frame.colour.height());
        size_t differ = 0;
        for (int v = 0; v < bgr.rows; ++v) {
            for (int u = 0; u < bgr.cols; ++u) {
                const cv::Vec3b p = bgr.at<cv::Vec3b>(v, u);
                const Rgb8 c = f->frame.colour(u, v);
                differ += p[2] != c.r || p[1] != c.g || p[0] != c.b;
            }
        }
        EXPECT_EQ(differ, 0U) << name;
    }
#endif
    // sim.json records the colour settings.
    const std::string meta = slurpFile(dir / "sim.json");
    for (const char* key : {"\"colour\"", "\"texture\": \"textured\"", "\"noise_std_levels\": 2.0",
                            "\"exposure_log_std\"", "\"exposure_jumps\"", "\"ambient\""}) {
        EXPECT_NE(meta.find(key), std::string::npos) << key << " missing from\n" << meta;
    }
    // No colour written when asked not to, or when the source renders none.
    const auto none = testing::freshTempDir("sim_dataset_no_rgb");
    options.write_rgb = false;
    ASSERT_TRUE(writeSimDataset(**source, none, options).isOk());
    EXPECT_FALSE(std::filesystem::exists(none / "rgb"));
    EXPECT_FALSE(std::filesystem::exists(none / "rgb.txt"));
    SimConfig off = smallConfig();
    off.colour.enabled = false;
    auto colourless = SimSource::create(off);
    ASSERT_TRUE(colourless.isOk());
    const auto none2 = testing::freshTempDir("sim_dataset_colour_off");
    options.write_rgb = true;
    ASSERT_TRUE(writeSimDataset(**colourless, none2, options).isOk());
    EXPECT_FALSE(std::filesystem::exists(none2 / "rgb.txt"));
    // The depth is the same with and without colour.
    EXPECT_EQ(slurpFile(dir / "depth/00004.png"), slurpFile(none2 / "depth/00004.png"));
}

}  // namespace
}  // namespace plumb::sim
