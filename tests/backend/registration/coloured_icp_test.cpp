// SPDX-License-Identifier: Apache-2.0
// Coloured ICP (Park, Zhou, Koltun ICCV 2017): the colour residual's Jacobian against finite
// differences, the tangent-plane intensity gradients on an exact ramp, a textured corridor
// whose slide along its axis only colour observes, and the point-to-plane fallback without
// colour.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "backend/registration/coloured_icp.hpp"
#include "backend/registration/pair_registration.hpp"
#include "backend/registration/prepared_fragment.hpp"
#include "common/geometry/lie.hpp"

#ifdef PLUMB_HAVE_OPEN3D
#include <open3d/geometry/PointCloud.h>
#include <open3d/pipelines/registration/ColoredICP.h>
#include <open3d/pipelines/registration/Registration.h>
#include <open3d/utility/Logging.h>
#endif

namespace plumb::registration {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

TEST(ColouredIcp, ColourJacobianMatchesFiniteDifferences) {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const auto random3 = [&] { return Eigen::Vector3d(u(rng), u(rng), u(rng)); };
    double worst = 0.0;
    for (int trial = 0; trial < 50; ++trial) {
        const Eigen::Vector3d p = 2.0 * random3();
        const Eigen::Vector3d n = random3().normalized();
        // A gradient on p's tangent plane, a few intensity units per metre.
        const Eigen::Vector3d raw = 5.0 * random3();
        const Eigen::Vector3d d = raw - raw.dot(n) * n;
        const double c_p = 0.5 + 0.3 * u(rng), c_q = 0.5 + 0.3 * u(rng);
        const Eigen::Isometry3d T =
            lie::expSE3((Vector6d() << 0.3 * random3(), random3()).finished());
        const Eigen::Vector3d q = p + 0.05 * random3();
        Eigen::Matrix<double, 1, 6> J;
        colourResidual(p, n, c_p, d, T * q, c_q, &J);
        constexpr double h = 1e-6;
        for (int k = 0; k < 6; ++k) {
            const Vector6d step = Vector6d::Unit(k) * h;
            const double plus =
                colourResidual(p, n, c_p, d, lie::expSE3(step) * T * q, c_q, nullptr);
            const double minus =
                colourResidual(p, n, c_p, d, lie::expSE3(-step) * T * q, c_q, nullptr);
            const double fd = (plus - minus) / (2.0 * h);
            worst = std::max(worst, std::abs(fd - J(k)) / std::max(1.0, std::abs(J(k))));
        }
    }
    EXPECT_LT(worst, 1e-6);
    // The residual itself: C(p) + d·(f(x) - p) - C(q), f the projection onto the tangent plane.
    const Eigen::Vector3d p(0.0, 0.0, 1.0), n(0.0, 0.0, -1.0), d(2.0, -1.0, 0.0);
    const Eigen::Vector3d x(0.01, 0.02, 0.9);  // 10 cm in front of the plane
    EXPECT_NEAR(colourResidual(p, n, 0.6, d, x, 0.5, nullptr), 0.6 + 0.02 - 0.02 - 0.5, 1e-12);
}

TEST(ColouredIcp, GradientsRecoverALinearRampOnAPlane) {
    // A tilted plane sampled on a 1 cm grid with intensity I(p) = 0.4 + a·p: Eq. (6) fitted
    // exactly gives d_p = a projected onto the plane, at every point with a 2-D neighbourhood.
    const Eigen::Vector3d normal = Eigen::Vector3d(0.2, -0.3, 1.0).normalized();
    const Eigen::Vector3d e1 = normal.cross(Eigen::Vector3d::UnitX()).normalized();
    const Eigen::Vector3d e2 = normal.cross(e1);
    const Eigen::Vector3d a(1.5, -0.8, 2.0);  // has a component along the normal
    const Eigen::Vector3d expected = a - a.dot(normal) * normal;
    PointCloud cloud;
    std::vector<float> intensity;
    const Eigen::Vector3d origin(0.1, -0.2, 1.5);
    for (int i = 0; i < 30; ++i) {
        for (int j = 0; j < 30; ++j) {
            const Eigen::Vector3d p = origin + 0.01 * (i - 15) * e1 + 0.01 * (j - 15) * e2;
            cloud.points.push_back(p.cast<float>());
            cloud.normals.push_back(normal.cast<float>());
            intensity.push_back(static_cast<float>(0.4 + 0.1 * a.dot(p - origin)));
        }
    }
    // A line of points: no 2-D neighbourhood, no gradient.
    for (int i = 0; i < 10; ++i) {
        cloud.points.emplace_back(5.0f + 0.01f * static_cast<float>(i), 0.0f, 0.0f);
        cloud.normals.emplace_back(0.0f, 0.0f, 1.0f);
        intensity.push_back(0.1f * static_cast<float>(i));
    }
    const std::vector<Eigen::Vector3f> g = intensityGradients(cloud, intensity, 0.035, 30, 0);
    ASSERT_EQ(g.size(), cloud.size());
    double worst = 0.0, worst_normal = 0.0;
    for (size_t i = 0; i < 900; ++i) {
        worst = std::max(worst, (g[i].cast<double>() - 0.1 * expected).norm());
        worst_normal = std::max(worst_normal, std::abs(g[i].cast<double>().dot(normal)));
    }
    EXPECT_LT(worst, 1e-3 * 0.1 * expected.norm());
    EXPECT_LT(worst_normal, 1e-6);
    for (size_t i = 900; i < cloud.size(); ++i) EXPECT_EQ(g[i], Eigen::Vector3f::Zero()) << i;
    // Thread count does not matter, nor whose k-d tree finds the neighbours.
    EXPECT_EQ(g, intensityGradients(cloud, intensity, 0.035, 30, 1));
    EXPECT_EQ(g, intensityGradients(IndexedCloud(cloud), intensity, 0.035, 30, 0));
}

/// Texture of the corridor surfaces in [0.1, 0.9]: smooth stripes along and across, wavelengths
/// 0.23-0.45 m (the coarse 5 cm level still sees them).
double corridorIntensity(double s, double z, double phase) {
    return 0.5 +
           0.22 * std::sin(2.0 * std::numbers::pi * z / 0.45 + phase) *
               std::cos(2.0 * std::numbers::pi * s / 0.37 + 2.0 * phase) +
           0.12 * std::sin(2.0 * std::numbers::pi * (z + 0.6 * s) / 0.23 + 3.0 * phase);
}

/// A corridor seen from inside, in world coordinates: walls x = ±0.8 (y in [-0.6, 0.6]) and the
/// floor y = 0.6, z in [z0, z1], sampled on a jittered 8 mm grid with 1 mm noise along the
/// normal, fused-like normals tilted by up to ~1 degree, and colours of the texture (a tinted
/// grey, 8-bit, with ±2 levels of noise). Translation along z is what the geometry leaves free.
Fragment corridor(uint32_t id, double z0, double z1, uint64_t seed, bool with_colour,
                  const Eigen::Isometry3d& T_F_W) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> jitter(-0.004, 0.004), tilt(-0.015, 0.015);
    std::normal_distribution<double> noise(0.0, 0.001);
    std::uniform_int_distribution<int> colour_noise(-2, 2);
    Fragment f;
    f.id = id;
    PointCloud& c = f.points_F;
    const auto add = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& n, double intensity) {
        c.points.push_back((T_F_W * (p + noise(rng) * n)).cast<float>());
        const Eigen::Vector3d tilted =
            (n + Eigen::Vector3d(tilt(rng), tilt(rng), tilt(rng))).normalized();
        c.normals.push_back((T_F_W.rotation() * tilted).cast<float>());
        if (with_colour) {
            const auto level = [&](double v) {
                return static_cast<uint8_t>(
                    std::clamp(std::lround(255.0 * v) + colour_noise(rng), 0L, 255L));
            };
            c.colors.emplace_back(level(intensity), level(0.8 * intensity + 0.1),
                                  level(0.6 * intensity + 0.2));
        }
    };
    constexpr double kStep = 0.008;
    for (double z = z0; z < z1; z += kStep) {
        for (double s = -0.6; s < 0.6; s += kStep) {
            for (int side : {-1, 1}) {
                const double zj = z + jitter(rng), sj = s + jitter(rng);
                add(Eigen::Vector3d(0.8 * side, sj, zj), Eigen::Vector3d(-side, 0.0, 0.0),
                    corridorIntensity(sj, zj, side));
            }
        }
        for (double s = -0.8; s < 0.8; s += kStep) {
            const double zj = z + jitter(rng), sj = s + jitter(rng);
            add(Eigen::Vector3d(sj, 0.6, zj), Eigen::Vector3d(0.0, -1.0, 0.0),
                corridorIntensity(sj, zj, 0.0));
        }
    }
    return f;
}

struct CorridorPair {
    Fragment a, b;
    FragmentIndex ia, ib;
    Eigen::Isometry3d truth;  ///< T_a_b
};

/// Fragment a sees the corridor in world coordinates; b (a shorter stretch, sampled anew) sees
/// it from a pose turned by a few degrees and moved: T_source_target = T_a_b.
CorridorPair makeCorridorPair(bool colour_a, bool colour_b, const IcpConfig& icp) {
    CorridorPair p;
    const Eigen::Isometry3d T_W_b = lie::expSE3(
        (Vector6d() << 2.0 * kDeg, -3.0 * kDeg, 1.5 * kDeg, 0.05, -0.02, 0.3).finished());
    p.truth = T_W_b;  // a's frame is the world
    p.a = corridor(0, 0.5, 2.9, 1, colour_a, Eigen::Isometry3d::Identity());
    p.b = corridor(1, 0.8, 2.6, 2, colour_b, T_W_b.inverse());
    const PreparedFragment pa = prepareFragment(p.a, {}).value();
    const PreparedFragment pb = prepareFragment(p.b, {}).value();
    p.ia = buildFragmentIndex(p.a, pa, icp);
    p.ib = buildFragmentIndex(p.b, pb, icp);
    return p;
}

/// The start: the truth slid 4 cm along the corridor (z), plus small errors elsewhere.
Eigen::Isometry3d corridorStart(const Eigen::Isometry3d& truth) {
    return lie::expSE3(
               (Vector6d() << 0.4 * kDeg, -0.3 * kDeg, 0.3 * kDeg, 0.01, -0.008, 0.04).finished()) *
           truth;
}

/// Error of an estimate in the source (corridor) frame: E = T_est T_true^-1.
Eigen::Isometry3d errorOf(const PairResult& r, const Eigen::Isometry3d& truth) {
    return r.T_source_target * truth.inverse();
}

TEST(ColouredIcp, CorridorSlideIsRecoveredByColourAlone) {
    IcpConfig icp;
    const CorridorPair p = makeCorridorPair(true, true, icp);
    ASSERT_EQ(p.ia.level_colours.size(), icp.voxel_sizes_m.size());
    ASSERT_EQ(p.ib.level_colours.size(), icp.voxel_sizes_m.size());
    const Eigen::Isometry3d start = corridorStart(p.truth);
    for (const double spread : {0.0, 0.005}) {
        icp.min_normal_spread = spread;
        icp.colour = false;
        const PairResult plane = multiScaleIcp(p.ia, p.ib, start, icp);
        icp.colour = true;
        const PairResult coloured = multiScaleIcp(p.ia, p.ib, start, icp);
        ASSERT_TRUE(plane.success) << plane.reason;
        ASSERT_TRUE(coloured.success) << coloured.reason;
        const Eigen::Isometry3d ep = errorOf(plane, p.truth), ec = errorOf(coloured, p.truth);
        std::printf(
            "min_normal_spread %.3f: point-to-plane error (%.2f %.2f %.2f) mm %.3f deg; coloured "
            "(%.3f %.3f %.3f) mm %.4f deg, %d iterations\n",
            spread, 1e3 * ep.translation().x(), 1e3 * ep.translation().y(),
            1e3 * ep.translation().z(), lie::rotationAngle(ep) / kDeg, 1e3 * ec.translation().x(),
            1e3 * ec.translation().y(), 1e3 * ec.translation().z(), lie::rotationAngle(ec) / kDeg,
            coloured.iterations);
        // Point-to-plane corrects what the walls and the floor observe, not the slide: plain
        // Gauss-Newton follows the normals' noise along z, remapped it keeps the start.
        EXPECT_LT(std::abs(ep.translation().x()), 0.002);
        EXPECT_LT(std::abs(ep.translation().y()), 0.002);
        EXPECT_GT(std::abs(ep.translation().z()), 0.01);
        // Coloured ICP recovers all of it, to better than a millimetre.
        EXPECT_LT(ec.translation().norm(), 0.001);
        EXPECT_LT(lie::rotationAngle(ec), 0.05 * kDeg);
    }
    // With remapping the point-to-plane start is kept exactly along z (nothing is solved there).
    icp.min_normal_spread = 0.005;
    icp.colour = false;
    EXPECT_NEAR(errorOf(multiScaleIcp(p.ia, p.ib, start, icp), p.truth).translation().z(),
                (start * p.truth.inverse()).translation().z(), 1e-3);
}

TEST(ColouredIcp, AQuarterOfTheTargetPointsAlignsAsWellAsAll) {
    // icp.max_target_points: with a quarter of the finest level's target points (every fourth),
    // coloured ICP still recovers the corridor pose, within a millimetre and 0.05 degrees of what
    // all the points give; point-to-plane within a millimetre across the corridor (along it,
    // the slide nothing observes, plain Gauss-Newton follows the normals' noise either way).
    IcpConfig icp;
    const CorridorPair p = makeCorridorPair(true, true, icp);
    const size_t finest = p.ib.levels.back().size();
    ASSERT_GT(finest, 1000u);
    const Eigen::Isometry3d start = corridorStart(p.truth);
    for (const bool colour : {true, false}) {
        icp.colour = colour;
        icp.max_target_points = 0;
        const PairResult all = multiScaleIcp(p.ia, p.ib, start, icp);
        icp.max_target_points = static_cast<int>(finest / 4);
        const PairResult some = multiScaleIcp(p.ia, p.ib, start, icp);
        ASSERT_TRUE(all.success && some.success) << all.reason << some.reason;
        // The cap applied: the finest level matched no more target points than it allows.
        EXPECT_GT(all.num_correspondences, icp.max_target_points);
        EXPECT_LE(some.num_correspondences, icp.max_target_points);
        // Difference in the corridor's frame (z along the corridor), as errorOf.
        const Eigen::Isometry3d d = some.T_source_target * all.T_source_target.inverse();
        const double across = d.translation().head<2>().norm();
        EXPECT_LT(across, 0.001);
        EXPECT_LT(lie::rotationAngle(d), 0.05 * kDeg);
        if (colour) {
            EXPECT_LT(d.translation().norm(), 0.001);
            EXPECT_LT(errorOf(some, p.truth).translation().norm(), 0.001);
        }
        std::printf("%s: %d of %zu target points, difference %.3f mm (%.3f across) %.4f deg\n",
                    colour ? "coloured" : "point-to-plane", some.num_correspondences, finest,
                    1e3 * d.translation().norm(), 1e3 * across, lie::rotationAngle(d) / kDeg);
    }
}

#ifdef PLUMB_HAVE_OPEN3D
std::shared_ptr<open3d::geometry::PointCloud> toOpen3d(const PointCloud& cloud) {
    auto out = std::make_shared<open3d::geometry::PointCloud>();
    for (size_t i = 0; i < cloud.size(); ++i) {
        out->points_.push_back(cloud.points[i].cast<double>());
        out->normals_.push_back(cloud.normals[i].cast<double>());
        out->colors_.push_back(cloud.colors[i].cast<double>() / 255.0);
    }
    return out;
}
#endif

TEST(ColouredIcp, AgreesWithOpen3dOnTheCorridor) {
#ifndef PLUMB_HAVE_OPEN3D
    GTEST_SKIP() << "Open3D not available at build time";
#else
    // The oracle: Open3D 0.16's RegistrationColoredICP, level by level on our pyramids (its
    // source is our target), from the same start with the same distances and criteria. It
    // averages the channels into intensity and fits its gradients its own way, so the two agree
    // to a fraction of a millimetre, not bit for bit; both must find the truth.
    namespace o3reg = open3d::pipelines::registration;
    open3d::utility::SetVerbosityLevel(open3d::utility::VerbosityLevel::Error);
    const IcpConfig icp;
    const CorridorPair p = makeCorridorPair(true, true, icp);
    const Eigen::Isometry3d start = corridorStart(p.truth);
    const PairResult ours = multiScaleIcp(p.ia, p.ib, start, icp);
    ASSERT_TRUE(ours.success) << ours.reason;
    Eigen::Matrix4d coloured = start.matrix(), plane = start.matrix();
    for (size_t l = 0; l < icp.voxel_sizes_m.size(); ++l) {
        const auto source = toOpen3d(p.ia.levels[l].cloud());
        const auto target = toOpen3d(p.ib.levels[l].cloud());
        const double distance = icp.distance_factor * icp.voxel_sizes_m[l];
        const o3reg::ICPConvergenceCriteria criteria(icp.relative_change, icp.relative_change,
                                                     static_cast<int>(icp.iterations[l]));
        coloured = o3reg::RegistrationColoredICP(
                       *target, *source, distance, coloured,
                       o3reg::TransformationEstimationForColoredICP(icp.lambda_geometric), criteria)
                       .transformation_;
        plane = o3reg::RegistrationICP(*target, *source, distance, plane,
                                       o3reg::TransformationEstimationPointToPlane(), criteria)
                    .transformation_;
    }
    const Eigen::Isometry3d theirs(coloured), theirs_plane(plane);
    const Eigen::Isometry3d eo = errorOf(ours, p.truth), et = theirs * p.truth.inverse();
    const Eigen::Isometry3d diff = ours.T_source_target * theirs.inverse();
    std::printf("ours %.3f mm %.4f deg, Open3D %.3f mm %.4f deg from the truth, apart %.3f mm\n",
                1e3 * eo.translation().norm(), lie::rotationAngle(eo) / kDeg,
                1e3 * et.translation().norm(), lie::rotationAngle(et) / kDeg,
                1e3 * diff.translation().norm());
    EXPECT_LT(et.translation().norm(), 0.001);
    EXPECT_LT(lie::rotationAngle(et), 0.05 * kDeg);
    EXPECT_LT(diff.translation().norm(), 0.001);
    EXPECT_LT(lie::rotationAngle(diff), 0.05 * kDeg);
    // Open3D's point-to-plane ICP cannot see the slide either.
    EXPECT_GT(std::abs((theirs_plane * p.truth.inverse()).translation().z()), 0.01);
#endif
}

TEST(ColouredIcp, ResultsDoNotDependOnTheThreadCount) {
    IcpConfig icp;
    const CorridorPair p = makeCorridorPair(true, true, icp);
    const Eigen::Isometry3d start = corridorStart(p.truth);
    icp.num_threads = 1;
    const PairResult one = multiScaleIcp(p.ia, p.ib, start, icp);
    icp.num_threads = 2;
    const PairResult two = multiScaleIcp(p.ia, p.ib, start, icp);
    icp.num_threads = 0;
    const PairResult all = multiScaleIcp(p.ia, p.ib, start, icp);
    ASSERT_TRUE(one.success) << one.reason;
    EXPECT_TRUE(one.T_source_target.matrix() == two.T_source_target.matrix());
    EXPECT_TRUE(one.T_source_target.matrix() == all.T_source_target.matrix());
    EXPECT_EQ(one.iterations, two.iterations);
    // Index building (gradients) too.
    IcpConfig serial;
    serial.num_threads = 1;
    const PreparedFragment pa = prepareFragment(p.a, {}).value();
    const FragmentIndex again = buildFragmentIndex(p.a, pa, serial);
    ASSERT_EQ(again.level_colours.size(), p.ia.level_colours.size());
    for (size_t l = 0; l < again.level_colours.size(); ++l) {
        EXPECT_EQ(again.level_colours[l].intensity, p.ia.level_colours[l].intensity);
        EXPECT_EQ(again.level_colours[l].gradient, p.ia.level_colours[l].gradient);
    }
}

/// Today's multi-scale point-to-plane ICP, level by level (the oracle of the fallback).
PairResult pointToPlaneChain(const FragmentIndex& s, const FragmentIndex& t,
                             const Eigen::Isometry3d& init, const IcpConfig& c) {
    PairResult r;
    r.T_source_target = init;
    int iterations = 0;
    for (size_t l = 0; l < c.voxel_sizes_m.size(); ++l) {
        r = icpPointToPlane(s.levels[l], t.levels[l].cloud(), r.T_source_target,
                            c.distance_factor * c.voxel_sizes_m[l],
                            static_cast<int>(c.iterations[l]), c.relative_change,
                            c.min_normal_spread, c.num_threads);
        iterations += r.iterations;
        if (!r.success) break;
    }
    r.iterations = iterations;
    return r;
}

TEST(ColouredIcp, WithoutColourOnBothSidesItIsPointToPlane) {
    for (const auto& [colour_a, colour_b] :
         {std::pair{false, false}, std::pair{true, false}, std::pair{false, true}}) {
        const CorridorPair p = makeCorridorPair(colour_a, colour_b, IcpConfig{});
        EXPECT_EQ(p.ia.level_colours.empty(), !colour_a);
        EXPECT_EQ(p.ib.level_colours.empty(), !colour_b);
        const Eigen::Isometry3d start = corridorStart(p.truth);
        for (const double spread : {0.0, 0.005}) {
            IcpConfig icp;  // colour on
            icp.min_normal_spread = spread;
            icp.max_target_points = 0;  // the oracle below uses every target point
            const PairResult r = multiScaleIcp(p.ia, p.ib, start, icp);
            const PairResult oracle = pointToPlaneChain(p.ia, p.ib, start, icp);
            ASSERT_TRUE(r.success) << r.reason;
            EXPECT_TRUE(r.T_source_target.matrix() == oracle.T_source_target.matrix())
                << colour_a << colour_b << " " << spread;
            EXPECT_EQ(r.iterations, oracle.iterations);
            EXPECT_EQ(r.inlier_rmse_m, oracle.inlier_rmse_m);
            // And it does not recover the slide: with solution remapping it keeps the start's
            // 4 cm along the corridor. (Plain Gauss-Newton wanders along it on noise, by an
            // amount that depends on when a level stops: no figure to hold it to.)
            if (spread > 0.0) {
                EXPECT_GT(std::abs(errorOf(r, p.truth).translation().z()), 0.03);
            }
        }
    }
    // Colour switched off: no colour levels are built, and the answer is point-to-plane's.
    IcpConfig off;
    off.colour = false;
    off.max_target_points = 0;
    const CorridorPair p = makeCorridorPair(true, true, off);
    EXPECT_TRUE(p.ia.level_colours.empty());
    const Eigen::Isometry3d start = corridorStart(p.truth);
    EXPECT_TRUE(multiScaleIcp(p.ia, p.ib, start, off).T_source_target.matrix() ==
                pointToPlaneChain(p.ia, p.ib, start, off).T_source_target.matrix());
}

TEST(ColouredIcp, PreparedAndIcpLevelsAverageColours) {
    // Two points per 5 cm voxel with colours (10, 20, 30) and (21, 40, 61): the voxel keeps
    // their mean, rounded.
    Fragment f;
    for (int i = 0; i < 20; ++i) {
        const float x = 0.05f * static_cast<float>(i) + 0.01f;
        f.points_F.points.emplace_back(x, 0.01f, 0.01f);
        f.points_F.points.emplace_back(x + 0.02f, 0.02f, 0.01f);
        f.points_F.normals.emplace_back(0.0f, 0.0f, -1.0f);
        f.points_F.normals.emplace_back(0.0f, 0.0f, -1.0f);
        f.points_F.colors.emplace_back(10, 20, 30);
        f.points_F.colors.emplace_back(21, 40, 61);
    }
    const PreparedFragment prepared = prepareFragment(f, {}).value();
    ASSERT_EQ(prepared.points.size(), 20u);
    ASSERT_TRUE(prepared.points.hasColors());
    for (const Color3u8& c : prepared.points.colors) EXPECT_EQ(c, Color3u8(16, 30, 46));
    const FragmentIndex index = buildFragmentIndex(f, prepared, IcpConfig{});
    ASSERT_FALSE(index.level_colours.empty());
    EXPECT_EQ(index.levels[0].cloud().colors, prepared.points.colors);
    EXPECT_FLOAT_EQ(index.level_colours[0].intensity[0],
                    static_cast<float>((0.299 * 16 + 0.587 * 30 + 0.114 * 46) / 255.0));
}

TEST(ColouredIcp, BadInputFailsWithAReason) {
    PointCloud source_cloud;
    source_cloud.points.assign(10, Eigen::Vector3f::Zero());
    source_cloud.normals.assign(10, Eigen::Vector3f::UnitZ());
    const IndexedCloud source(source_cloud);
    const std::vector<float> intensity(10, 0.5f);
    const std::vector<Eigen::Vector3f> gradient(10, Eigen::Vector3f::Zero());
    const Eigen::Isometry3d I = Eigen::Isometry3d::Identity();
    PairResult r = icpColoured(source, intensity, gradient, source_cloud,
                               std::vector<float>(9, 0.5f), I, 0.1, 10, 1e-6, 0.968, 0.0, 1);
    EXPECT_FALSE(r.success);
    EXPECT_NE(r.reason.find("do not match"), std::string::npos) << r.reason;
    r = icpColoured(source, intensity, gradient, source_cloud, intensity, I, 0.1, 10, 1e-6, 0.0,
                    0.0, 1);
    EXPECT_FALSE(r.success);
    EXPECT_NE(r.reason.find("lambda_geometric"), std::string::npos) << r.reason;
    PointCloud far = source_cloud;
    for (auto& q : far.points) q.x() += 5.0f;
    r = icpColoured(source, intensity, gradient, far, intensity, I, 0.1, 10, 1e-6, 0.968, 0.0, 1);
    EXPECT_FALSE(r.success);
    EXPECT_NE(r.reason.find("fewer than 6"), std::string::npos) << r.reason;
}

}  // namespace
}  // namespace plumb::registration
