// SPDX-License-Identifier: Apache-2.0
#pragma once

// Analytic scenes for the device tests: planes and spheres with closed-form ray hits, rendered to
// exact depth (optionally with seeded axial noise), and their exact point-to-surface distance.

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/geometry/lie.hpp"
#include "common/image/image.hpp"

namespace plumb::testing {

struct ScenePlane {
    Eigen::Vector3d n;  ///< unit normal, pointing into the room
    double d;           ///< n.x + d = 0
};
struct SceneSphere {
    Eigen::Vector3d c;
    double r;
};

struct Scene {
    std::vector<ScenePlane> planes;
    std::vector<SceneSphere> spheres;

    /// First hit along o + t r (t = z-depth when r has unit camera z), or nullopt.
    std::optional<double> hit(const Eigen::Vector3d& o, const Eigen::Vector3d& r) const {
        double best = std::numeric_limits<double>::infinity();
        for (const auto& p : planes) {
            const double den = p.n.dot(r);
            if (std::abs(den) < 1e-12) continue;
            const double t = -(p.n.dot(o) + p.d) / den;
            if (t > 1e-9) best = std::min(best, t);
        }
        for (const auto& s : spheres) {
            const Eigen::Vector3d oc = o - s.c;
            const double a = r.squaredNorm(), b = 2.0 * oc.dot(r), c = oc.squaredNorm() - s.r * s.r;
            const double disc = b * b - 4 * a * c;
            if (disc < 0.0) continue;
            const double t = (-b - std::sqrt(disc)) / (2 * a);
            if (t > 1e-9) best = std::min(best, t);
        }
        if (!std::isfinite(best)) return std::nullopt;
        return best;
    }

    /// Distance from p to the closest surface (planes bound a convex room containing p).
    double distance(const Eigen::Vector3d& p) const {
        double best = std::numeric_limits<double>::infinity();
        for (const auto& pl : planes) best = std::min(best, std::abs(pl.n.dot(p) + pl.d));
        for (const auto& s : spheres) best = std::min(best, std::abs((p - s.c).norm() - s.r));
        return best;
    }

    /// Depth image seen from T_W_C; `noise_seed` > 0 adds axial noise
    /// sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2 (Nguyen et al. 2012).
    DepthImage render(const PinholeCamera& cam, const Eigen::Isometry3d& T_W_C,
                      uint64_t noise_seed = 0, double max_depth_m = 4.0) const {
        DepthImage depth(cam.width, cam.height, 0.0f);
        std::mt19937_64 rng(noise_seed);
        std::normal_distribution<double> gauss(0.0, 1.0);
        for (int v = 0; v < cam.height; ++v) {
            for (int u = 0; u < cam.width; ++u) {
                const Eigen::Vector3d r = T_W_C.linear() * cam.ray(u, v);
                const std::optional<double> t = hit(T_W_C.translation(), r);
                if (!t || *t > max_depth_m) continue;
                double z = *t;
                if (noise_seed > 0) z += (0.0012 + 0.0019 * (z - 0.4) * (z - 0.4)) * gauss(rng);
                depth(u, v) = static_cast<float>(z);
            }
        }
        return depth;
    }
};

/// A smooth albedo in [0.15, 0.85] of a world point: sinusoids of 7 to 31 cm wavelength (strong
/// gradients at 1-3 m without aliasing at 320 px).
inline double texture(const Eigen::Vector3d& p) {
    constexpr double k = 2.0 * 3.14159265358979323846;
    return 0.5 + 0.2 * std::sin(k * p.x() / 0.23) * std::sin(k * (p.y() + 0.5 * p.z()) / 0.17) +
           0.1 * std::sin(k * (p.x() + 0.7 * p.y() - 0.4 * p.z()) / 0.07) +
           0.05 * std::cos(k * (p.z() - p.x()) / 0.31);
}

/// Colour image of `scene` seen from T_W_C: grey `albedo(p)` at the hit point p (uniform 0.5
/// when `albedo` is null), times `gain`.
inline ColourImage renderColour(const Scene& scene, const PinholeCamera& cam,
                                const Eigen::Isometry3d& T_W_C,
                                double (*albedo)(const Eigen::Vector3d&) = texture,
                                double gain = 1.0) {
    ColourImage out(cam.width, cam.height);
    for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
            const Eigen::Vector3d r = T_W_C.linear() * cam.ray(u, v);
            const std::optional<double> t = scene.hit(T_W_C.translation(), r);
            if (!t) continue;
            const double a = albedo != nullptr ? albedo(T_W_C.translation() + *t * r) : 0.5;
            const auto g = static_cast<uint8_t>(std::clamp(255.0 * a * gain + 0.5, 0.0, 255.0));
            out(u, v) = {g, g, g};
        }
    }
    return out;
}

/// Camera at `eye` looking at `target` (z forward; x chosen perpendicular to world y or x).
inline Eigen::Isometry3d lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
    const Eigen::Vector3d z = (target - eye).normalized();
    const Eigen::Vector3d up =
        std::abs(z.y()) < 0.9 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitX();
    const Eigen::Vector3d x = up.cross(z).normalized();
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear().col(0) = x;
    T.linear().col(1) = z.cross(x);
    T.linear().col(2) = z;
    T.translation() = eye;
    return T;
}

/// A 4 x 2.6 x 5 m box room (camera y points down to the floor) with two spheres in it.
inline Scene boxRoom() {
    Scene s;
    s.planes = {{{1, 0, 0}, 2.0}, {{-1, 0, 0}, 2.0}, {{0, -1, 0}, 1.3},
                {{0, 1, 0}, 1.3}, {{0, 0, 1}, 1.5},  {{0, 0, -1}, 3.5}};
    s.spheres = {{{0.6, 0.5, 2.2}, 0.35}, {{-0.9, -0.2, 2.6}, 0.5}};
    return s;
}

/// Smooth hand-held trajectory through boxRoom(): about 1 cm and 0.5 deg per frame.
inline Eigen::Isometry3d handheldPose(int k) {
    const double t = static_cast<double>(k);
    Vector6d xi;
    xi << 0.10 * std::sin(0.05 * t), 0.25 * std::sin(0.031 * t), 0.05 * std::sin(0.043 * t),
        0.25 * std::sin(0.04 * t), 0.10 * std::sin(0.06 * t), 0.30 * std::sin(0.025 * t);
    return lie::expSE3(xi);
}

}  // namespace plumb::testing
