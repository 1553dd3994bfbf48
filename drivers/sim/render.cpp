// SPDX-License-Identifier: Apache-2.0
#include "drivers/sim/render.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace plumb::sim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kEps = 1e-9;

}  // namespace

RayCaster::RayCaster(const Scene& scene) : scene_(scene) {
    const int n = scene.numWalls();
    for (int k = 0; k < n; ++k) {
        Wall w;
        w.a = scene.polygon[k];
        w.e = scene.polygon[(k + 1) % n] - w.a;
        w.length = w.e.norm();
        w.normal = Eigen::Vector2d(-w.e.y(), w.e.x()) / w.length;
        for (const Opening& o : scene.openings) {
            if (o.wall == k) w.openings.push_back(o);
        }
        walls_.push_back(w);
    }
    for (const Box& b : scene.boxes) {
        boxes_.push_back({b.center_W, 0.5 * b.size_m, std::cos(b.yaw_rad), std::sin(b.yaw_rad)});
    }
}

RayHit RayCaster::cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
    double best = kInf;
    int label = kNoPrimitive;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    bool exits = false;  // the nearest room surface is an opening

    // Floor z = 0 and ceiling z = H.
    if (d.z() < 0.0) {
        best = -o.z() / d.z();
        label = floorLabel();
        normal = Eigen::Vector3d::UnitZ();
    } else if (d.z() > 0.0) {
        best = (scene_.height_m - o.z()) / d.z();
        label = ceilingLabel();
        normal = -Eigen::Vector3d::UnitZ();
    }
    // Walls: o_xy + t d_xy = a + s e with s in [0, 1].
    const Eigen::Vector2d o2 = o.head<2>();
    const Eigen::Vector2d d2 = d.head<2>();
    for (size_t k = 0; k < walls_.size(); ++k) {
        const Wall& w = walls_[k];
        const double denom = d2.x() * w.e.y() - d2.y() * w.e.x();
        if (std::abs(denom) < 1e-15) continue;
        const Eigen::Vector2d ao = w.a - o2;
        const double t = (ao.x() * w.e.y() - ao.y() * w.e.x()) / denom;
        if (t <= kEps || t >= best) continue;
        const double s = (ao.x() * d2.y() - ao.y() * d2.x()) / denom;
        if (s < 0.0 || s > 1.0) continue;
        best = t;
        label = wallLabel(static_cast<int>(k));
        normal = Eigen::Vector3d(w.normal.x(), w.normal.y(), 0.0);
        exits = false;
        if (!w.openings.empty()) {
            const double along = s * w.length;
            const double z = o.z() + t * d.z();
            for (const Opening& op : w.openings) {
                if (along > op.offset_m && along < op.offset_m + op.width_m && z > op.z_min_m &&
                    z < op.z_max_m) {
                    exits = true;
                }
            }
        }
    }
    if (exits) {
        best = kInf;
        label = kNoPrimitive;
    }
    // Yawed boxes: slab test in the box frame.
    for (size_t i = 0; i < boxes_.size(); ++i) {
        const BoxData& b = boxes_[i];
        const Eigen::Vector3d q = o - b.center;
        const Eigen::Vector3d ol(b.c * q.x() + b.s * q.y(), -b.s * q.x() + b.c * q.y(), q.z());
        const Eigen::Vector3d dl(b.c * d.x() + b.s * d.y(), -b.s * d.x() + b.c * d.y(), d.z());
        double t_near = -kInf, t_far = kInf;
        int axis = -1;
        bool miss = false;
        for (int a = 0; a < 3 && !miss; ++a) {
            if (std::abs(dl[a]) < 1e-15) {
                if (std::abs(ol[a]) > b.half[a]) miss = true;
                continue;
            }
            const double inv = 1.0 / dl[a];
            double t0 = (-b.half[a] - ol[a]) * inv;
            double t1 = (b.half[a] - ol[a]) * inv;
            if (t0 > t1) std::swap(t0, t1);
            if (t0 > t_near) {
                t_near = t0;
                axis = a;
            }
            t_far = std::min(t_far, t1);
            if (t_near > t_far || t_far <= 0.0 || t_near >= best) miss = true;
        }
        if (miss || axis < 0 || t_near <= kEps || t_near >= best) continue;
        best = t_near;
        label = boxLabel(scene_, static_cast<int>(i));
        Eigen::Vector3d nl = Eigen::Vector3d::Zero();
        nl[axis] = dl[axis] > 0.0 ? -1.0 : 1.0;
        normal = Eigen::Vector3d(b.c * nl.x() - b.s * nl.y(), b.s * nl.x() + b.c * nl.y(), nl.z());
    }
    // Vertical cylinders: side |o_xy + t d_xy - c|^2 = r^2, and flat caps.
    for (size_t i = 0; i < scene_.cylinders.size(); ++i) {
        const Cylinder& c = scene_.cylinders[i];
        const Eigen::Vector2d q = o2 - c.center_xy;
        const double A = d2.squaredNorm();
        if (A > 1e-18) {
            const double B = q.dot(d2);
            const double C = q.squaredNorm() - c.radius_m * c.radius_m;
            const double disc = B * B - A * C;
            if (disc >= 0.0) {
                const double t = (-B - std::sqrt(disc)) / A;
                if (t > kEps && t < best) {
                    const double z = o.z() + t * d.z();
                    if (z >= c.z_min_m && z <= c.z_max_m) {
                        best = t;
                        label = cylinderLabel(scene_, static_cast<int>(i));
                        const Eigen::Vector2d n2 = (q + t * d2) / c.radius_m;
                        normal = Eigen::Vector3d(n2.x(), n2.y(), 0.0);
                    }
                }
            }
        }
        if (std::abs(d.z()) > 1e-15) {
            const double cap_z = d.z() < 0.0 ? c.z_max_m : c.z_min_m;
            const double t = (cap_z - o.z()) / d.z();
            if (t > kEps && t < best && (q + t * d2).squaredNorm() <= c.radius_m * c.radius_m) {
                best = t;
                label = cylinderLabel(scene_, static_cast<int>(i));
                normal = Eigen::Vector3d(0.0, 0.0, d.z() < 0.0 ? 1.0 : -1.0);
            }
        }
    }
    RayHit hit;
    if (label != kNoPrimitive && std::isfinite(best)) {
        hit.t = best;
        hit.label = label;
        hit.normal_W = normal;
    }
    return hit;
}

Renderer::Renderer(const Scene& scene, const PinholeCamera& camera)
    : caster_(scene), camera_(camera) {
    const size_t n = static_cast<size_t>(camera.width) * camera.height;
    rays_C_.resize(n);
    inv_norm_.resize(n);
    for (int v = 0; v < camera.height; ++v) {
        for (int u = 0; u < camera.width; ++u) {
            const size_t i = static_cast<size_t>(v) * camera.width + u;
            rays_C_[i] = camera.ray(u, v);
            inv_norm_[i] = 1.0 / rays_C_[i].norm();
        }
    }
}

void Renderer::render(const Eigen::Isometry3d& T_W_C, RenderedView* view) const {
    const int w = camera_.width;
    const int h = camera_.height;
    if (view->depth.width() != w || view->depth.height() != h) {
        view->depth = DepthImage(w, h);
        view->cos_view = Image<float>(w, h);
        view->label = Image<int16_t>(w, h);
        view->gray = GrayImage(w, h);
    }
    const Eigen::Matrix3d R = T_W_C.linear();
    const Eigen::Vector3d o = T_W_C.translation();
    const Scene& scene = caster_.scene();
    const int num_walls = scene.numWalls();
    const int num_boxes = static_cast<int>(scene.boxes.size());
    tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
        for (int v = rows.begin(); v < rows.end(); ++v) {
            for (int u = 0; u < w; ++u) {
                const size_t i = static_cast<size_t>(v) * w + u;
                const Eigen::Vector3d d = R * rays_C_[i];
                const RayHit hit = caster_.cast(o, d);
                if (hit.label == kNoPrimitive) {
                    view->depth(u, v) = 0.0F;
                    view->cos_view(u, v) = 0.0F;
                    view->label(u, v) = static_cast<int16_t>(kNoPrimitive);
                    view->gray(u, v) = 0;
                    continue;
                }
                const double cosv = std::abs(hit.normal_W.dot(d)) * inv_norm_[i];
                view->depth(u, v) = static_cast<float>(hit.t);
                view->cos_view(u, v) = static_cast<float>(cosv);
                view->label(u, v) = static_cast<int16_t>(hit.label);
                float albedo = scene.wall_albedo;
                if (hit.label == floorLabel()) {
                    albedo *= 0.6F;
                } else if (hit.label == ceilingLabel()) {
                    albedo *= 0.9F;
                } else if (hit.label >= 2 + num_walls + num_boxes) {
                    albedo = scene.cylinders[hit.label - 2 - num_walls - num_boxes].albedo;
                } else if (hit.label >= 2 + num_walls) {
                    albedo = scene.boxes[hit.label - 2 - num_walls].albedo;
                }
                const float shade = 20.0F + 235.0F * albedo * static_cast<float>(cosv);
                view->gray(u, v) = static_cast<uint8_t>(std::min(255.0F, shade));
            }
        }
    });
}

}  // namespace plumb::sim
