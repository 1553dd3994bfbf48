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
// Screen-space cull (Renderer::projectedRect): the nearest clipping plane, metres (a primitive
// that may be hit nearer the camera plane than this and reaches behind it covers the whole
// image), and the margin the rectangles grow by to absorb rounding in the projection and in the
// ray tests (both ~1e-12 px; any margin >= 1 px is exact).
constexpr double kNearPlaneM = 1e-6;
constexpr double kCullMarginPx = 2.0;
// Tile edge of the cull: each tile tests only the primitives whose rectangle overlaps it.
constexpr int kTilePx = 16;

// Distance from p to the vertical wall over the floor segment ab: at least that in the plane.
double distanceToSegment(const Eigen::Vector3d& p, const Eigen::Vector2d& a,
                         const Eigen::Vector2d& b) {
    const Eigen::Vector2d e = b - a;
    const double s = std::clamp((p.head<2>() - a).dot(e) / e.squaredNorm(), 0.0, 1.0);
    return (p.head<2>() - (a + s * e)).norm();
}

double distanceToBox(const Eigen::Vector3d& p, const Box& box) {
    const Eigen::Vector3d q = p - box.center_W;
    const double c = std::cos(box.yaw_rad), s = std::sin(box.yaw_rad);
    const Eigen::Vector3d local(c * q.x() + s * q.y(), -s * q.x() + c * q.y(), q.z());
    return (local.cwiseAbs() - 0.5 * box.size_m).cwiseMax(0.0).norm();
}

double distanceToCylinder(const Eigen::Vector3d& p, const Cylinder& cyl) {
    const double radial = std::max((p.head<2>() - cyl.center_xy).norm() - cyl.radius_m, 0.0);
    const double vertical = std::max({cyl.z_min_m - p.z(), p.z() - cyl.z_max_m, 0.0});
    return std::hypot(radial, vertical);
}

// Reallocates `image` unless it already holds w x h pixels (a moved-from image keeps its size
// but not its pixels), so that rendering into the same view reuses its buffers.
template <typename T>
void fitImage(int w, int h, Image<T>* image) {
    if (image->width() != w || image->height() != h ||
        image->size() != static_cast<size_t>(w) * h) {
        *image = Image<T>(w, h);
    }
}

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

struct RayCaster::Nearest {
    double best = kInf;
    int label = kNoPrimitive;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    bool exits = false;  // the nearest room surface is an opening
};

RayCaster::OriginTerms RayCaster::originTerms(const Eigen::Vector3d& o) const {
    OriginTerms terms;
    terms.o = o;
    const Eigen::Vector2d o2 = o.head<2>();
    for (const Wall& w : walls_) {
        const Eigen::Vector2d ao = w.a - o2;
        terms.wall_ao.push_back(ao);
        terms.wall_num.push_back(ao.x() * w.e.y() - ao.y() * w.e.x());
    }
    for (const BoxData& b : boxes_) {
        const Eigen::Vector3d q = o - b.center;
        terms.box_ol.emplace_back(b.c * q.x() + b.s * q.y(), -b.s * q.x() + b.c * q.y(), q.z());
    }
    for (const Cylinder& c : scene_.cylinders) {
        const Eigen::Vector2d q = o2 - c.center_xy;
        terms.cyl_q.push_back(q);
        terms.cyl_c.push_back(q.squaredNorm() - c.radius_m * c.radius_m);
    }
    return terms;
}

// Floor z = 0 and ceiling z = H.
inline void RayCaster::castFloorCeiling(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                                        Nearest* n) const {
    if (d.z() < 0.0) {
        n->best = -o.z() / d.z();
        n->label = floorLabel();
        n->normal = Eigen::Vector3d::UnitZ();
    } else if (d.z() > 0.0) {
        n->best = (scene_.height_m - o.z()) / d.z();
        n->label = ceilingLabel();
        n->normal = -Eigen::Vector3d::UnitZ();
    }
}

// Wall k: o_xy + t d_xy = a + s e with s in [0, 1]; ao = a - o_xy, num = ao x e.
inline void RayCaster::castWall(size_t k, const Eigen::Vector2d& ao, double num,
                                const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                                Nearest* n) const {
    const Wall& w = walls_[k];
    const double denom = d.x() * w.e.y() - d.y() * w.e.x();
    if (std::abs(denom) < 1e-15) return;
    const double t = num / denom;
    if (t <= kEps || t >= n->best) return;
    const double s = (ao.x() * d.y() - ao.y() * d.x()) / denom;
    if (s < 0.0 || s > 1.0) return;
    n->best = t;
    n->label = wallLabel(static_cast<int>(k));
    n->normal = Eigen::Vector3d(w.normal.x(), w.normal.y(), 0.0);
    n->exits = false;
    if (w.openings.empty()) return;
    const double along = s * w.length;
    const double z = o.z() + t * d.z();
    for (const Opening& op : w.openings) {
        if (along > op.offset_m && along < op.offset_m + op.width_m && z > op.z_min_m &&
            z < op.z_max_m) {
            n->exits = true;
        }
    }
}

// Yawed box i: slab test in the box frame; ol = the origin in the box frame.
inline void RayCaster::castBox(size_t i, const Eigen::Vector3d& ol, const Eigen::Vector3d& d,
                               Nearest* n) const {
    const BoxData& b = boxes_[i];
    const Eigen::Vector3d dl(b.c * d.x() + b.s * d.y(), -b.s * d.x() + b.c * d.y(), d.z());
    double t_near = -kInf, t_far = kInf;
    int axis = -1;
    for (int a = 0; a < 3; ++a) {
        if (std::abs(dl[a]) < 1e-15) {
            if (std::abs(ol[a]) > b.half[a]) return;
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
        if (t_near > t_far || t_far <= 0.0 || t_near >= n->best) return;
    }
    if (axis < 0 || t_near <= kEps || t_near >= n->best) return;
    n->best = t_near;
    n->label = boxLabel(scene_, static_cast<int>(i));
    Eigen::Vector3d nl = Eigen::Vector3d::Zero();
    nl[axis] = dl[axis] > 0.0 ? -1.0 : 1.0;
    n->normal = Eigen::Vector3d(b.c * nl.x() - b.s * nl.y(), b.s * nl.x() + b.c * nl.y(), nl.z());
}

// Vertical cylinder i: side |q + t d_xy|^2 = r^2 (q = o_xy - axis, c = |q|^2 - r^2), flat caps.
inline void RayCaster::castCylinder(size_t i, const Eigen::Vector2d& q, double c,
                                    const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                                    Nearest* n) const {
    const Cylinder& cyl = scene_.cylinders[i];
    const Eigen::Vector2d d2 = d.head<2>();
    const double A = d2.squaredNorm();
    if (A > 1e-18) {
        const double B = q.dot(d2);
        const double disc = B * B - A * c;
        if (disc >= 0.0) {
            const double t = (-B - std::sqrt(disc)) / A;
            if (t > kEps && t < n->best) {
                const double z = o.z() + t * d.z();
                if (z >= cyl.z_min_m && z <= cyl.z_max_m) {
                    n->best = t;
                    n->label = cylinderLabel(scene_, static_cast<int>(i));
                    const Eigen::Vector2d n2 = (q + t * d2) / cyl.radius_m;
                    n->normal = Eigen::Vector3d(n2.x(), n2.y(), 0.0);
                }
            }
        }
    }
    if (std::abs(d.z()) > 1e-15) {
        const double cap_z = d.z() < 0.0 ? cyl.z_max_m : cyl.z_min_m;
        const double t = (cap_z - o.z()) / d.z();
        if (t > kEps && t < n->best && (q + t * d2).squaredNorm() <= cyl.radius_m * cyl.radius_m) {
            n->best = t;
            n->label = cylinderLabel(scene_, static_cast<int>(i));
            n->normal = Eigen::Vector3d(0.0, 0.0, d.z() < 0.0 ? 1.0 : -1.0);
        }
    }
}

inline RayHit RayCaster::finish(const Nearest& n) {
    RayHit hit;
    if (n.label != kNoPrimitive && std::isfinite(n.best)) {
        hit.t = n.best;
        hit.label = n.label;
        hit.normal_W = n.normal;
    }
    return hit;
}

RayHit RayCaster::cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
    Nearest n;
    castFloorCeiling(o, d, &n);
    const Eigen::Vector2d o2 = o.head<2>();
    for (size_t k = 0; k < walls_.size(); ++k) {
        const Wall& w = walls_[k];
        const Eigen::Vector2d ao = w.a - o2;
        castWall(k, ao, ao.x() * w.e.y() - ao.y() * w.e.x(), o, d, &n);
    }
    if (n.exits) {
        n.best = kInf;
        n.label = kNoPrimitive;
    }
    for (size_t i = 0; i < boxes_.size(); ++i) {
        const BoxData& b = boxes_[i];
        const Eigen::Vector3d q = o - b.center;
        const Eigen::Vector3d ol(b.c * q.x() + b.s * q.y(), -b.s * q.x() + b.c * q.y(), q.z());
        castBox(i, ol, d, &n);
    }
    for (size_t i = 0; i < scene_.cylinders.size(); ++i) {
        const Cylinder& c = scene_.cylinders[i];
        const Eigen::Vector2d q = o2 - c.center_xy;
        castCylinder(i, q, q.squaredNorm() - c.radius_m * c.radius_m, o, d, &n);
    }
    return finish(n);
}

RayHit RayCaster::cast(const OriginTerms& terms, const Eigen::Vector3d& d,
                       const Candidates& candidates) const {
    Nearest n;
    castFloorCeiling(terms.o, d, &n);
    for (size_t j = 0; j < candidates.num_walls; ++j) {
        const size_t k = static_cast<size_t>(candidates.walls[j]);
        castWall(k, terms.wall_ao[k], terms.wall_num[k], terms.o, d, &n);
    }
    if (n.exits) {
        n.best = kInf;
        n.label = kNoPrimitive;
    }
    for (size_t j = 0; j < candidates.num_boxes; ++j) {
        const size_t i = static_cast<size_t>(candidates.boxes[j]);
        castBox(i, terms.box_ol[i], d, &n);
    }
    for (size_t j = 0; j < candidates.num_cylinders; ++j) {
        const size_t i = static_cast<size_t>(candidates.cylinders[j]);
        castCylinder(i, terms.cyl_q[i], terms.cyl_c[i], terms.o, d, &n);
    }
    return finish(n);
}

Renderer::Renderer(const Scene& scene, const PinholeCamera& camera, const RenderConfig& config)
    : caster_(scene), textures_(scene), config_(config), camera_(camera) {
    PLUMB_CHECK(config.ambient >= 0.0F && config.ambient <= 1.0F)
        << "RenderConfig::ambient = " << config.ambient;
    const size_t n = static_cast<size_t>(camera.width) * camera.height;
    rays_C_.resize(n);
    inv_norm_.resize(n);
    for (int v = 0; v < camera.height; ++v) {
        for (int u = 0; u < camera.width; ++u) {
            const size_t i = static_cast<size_t>(v) * camera.width + u;
            rays_C_[i] = camera.ray(u, v);
            inv_norm_[i] = 1.0 / rays_C_[i].norm();
            max_ray_norm_ = std::max(max_ray_norm_, rays_C_[i].norm());
        }
    }
    // Convex hulls for the screen-space cull: wall quads, box corners, cylinder bounding boxes.
    const int num_walls = scene.numWalls();
    for (int k = 0; k < num_walls; ++k) {
        const Eigen::Vector2d& a = scene.polygon[k];
        const Eigen::Vector2d& b = scene.polygon[(k + 1) % num_walls];
        const double top = scene.height_m;
        Hull hull{};
        hull.corners_W[0] = Eigen::Vector3d(a.x(), a.y(), 0.0);
        hull.corners_W[1] = Eigen::Vector3d(a.x(), a.y(), top);
        hull.corners_W[2] = Eigen::Vector3d(b.x(), b.y(), 0.0);
        hull.corners_W[3] = Eigen::Vector3d(b.x(), b.y(), top);
        hull.num_corners = 4;
        wall_hulls_.push_back(hull);
    }
    for (const Box& box : scene.boxes) {
        const double c = std::cos(box.yaw_rad), s = std::sin(box.yaw_rad);
        const Eigen::Vector3d half = 0.5 * box.size_m;
        Hull hull{};
        hull.num_corners = 8;
        for (int j = 0; j < 8; ++j) {
            const Eigen::Vector3d l((j & 1) ? half.x() : -half.x(), (j & 2) ? half.y() : -half.y(),
                                    (j & 4) ? half.z() : -half.z());
            hull.corners_W[j] =
                box.center_W + Eigen::Vector3d(c * l.x() - s * l.y(), s * l.x() + c * l.y(), l.z());
        }
        box_hulls_.push_back(hull);
    }
    for (const Cylinder& cyl : scene.cylinders) {
        Hull hull{};
        hull.num_corners = 8;
        for (int j = 0; j < 8; ++j) {
            hull.corners_W[j] =
                Eigen::Vector3d(cyl.center_xy.x() + ((j & 1) ? cyl.radius_m : -cyl.radius_m),
                                cyl.center_xy.y() + ((j & 2) ? cyl.radius_m : -cyl.radius_m),
                                (j & 4) ? cyl.z_max_m : cyl.z_min_m);
        }
        cylinder_hulls_.push_back(hull);
    }
}

// Culling rectangle of one primitive (reference: the perspective image of a convex set in front of
// the camera is the convex hull of its corners' images). A ray through a pixel hits at camera
// depth z = t, at a distance t |d_C| <= t max|d_C| from the camera, so no hit in the image is
// nearer the camera plane than z_clip = dist / max|d_C| (halved for safety), where `dist_m` is
// the distance from the camera to the primitive. The hull clipped to z >= z_clip is the convex
// hull of its corners beyond the plane and of the plane's crossings of the segments between
// corners; its image's bounding box plus a margin for rounding holds every pixel whose ray can hit
// the primitive. Without such a bound (the camera touches the primitive) a hull reaching behind
// the camera covers the whole image; a hull entirely behind it is never hit.
Renderer::PixelRect Renderer::projectedRect(const Hull& hull, const Eigen::Isometry3d& T_C_W,
                                            double dist_m) const {
    const PixelRect empty{0, 0, -1, -1};
    std::array<Eigen::Vector3d, 8> p_C;
    double z_min = kInf, z_max = -kInf;
    for (int j = 0; j < hull.num_corners; ++j) {
        p_C[j] = T_C_W * hull.corners_W[j];
        z_min = std::min(z_min, p_C[j].z());
        z_max = std::max(z_max, p_C[j].z());
    }
    double z_clip = 0.5 * dist_m / max_ray_norm_;
    if (!(z_clip >= kNearPlaneM)) {
        if (z_max < -kNearPlaneM) return empty;
        if (z_min <= kNearPlaneM) return {0, 0, camera_.width - 1, camera_.height - 1};
        z_clip = kNearPlaneM;  // every corner is beyond it: nothing is clipped
    }
    if (z_max < z_clip) return empty;
    double u_min = kInf, u_max = -kInf, v_min = kInf, v_max = -kInf;
    auto add = [&](const Eigen::Vector3d& p) {
        const double u = camera_.fx * p.x() / p.z() + camera_.cx;
        const double v = camera_.fy * p.y() / p.z() + camera_.cy;
        u_min = std::min(u_min, u);
        u_max = std::max(u_max, u);
        v_min = std::min(v_min, v);
        v_max = std::max(v_max, v);
    };
    for (int j = 0; j < hull.num_corners; ++j) {
        if (p_C[j].z() >= z_clip) add(p_C[j]);
        for (int k = j + 1; k < hull.num_corners; ++k) {
            if ((p_C[j].z() < z_clip) == (p_C[k].z() < z_clip)) continue;
            const double a = (z_clip - p_C[j].z()) / (p_C[k].z() - p_C[j].z());
            Eigen::Vector3d p = p_C[j] + a * (p_C[k] - p_C[j]);
            p.z() = z_clip;
            add(p);
        }
    }
    // Clamp in double first: points just beyond a tiny z_clip project far outside.
    auto lo = [](double x, int size) {
        return static_cast<int>(std::clamp(std::floor(x) - kCullMarginPx, 0.0, size + 0.0));
    };
    auto hi = [](double x, int size) {
        return static_cast<int>(std::clamp(std::ceil(x) + kCullMarginPx, -1.0, size - 1.0));
    };
    return {lo(u_min, camera_.width), lo(v_min, camera_.height), hi(u_max, camera_.width),
            hi(v_max, camera_.height)};
}

void Renderer::render(const Eigen::Isometry3d& T_W_C, RenderedView* view) const {
    const int w = camera_.width;
    const int h = camera_.height;
    fitImage(w, h, &view->depth);
    fitImage(w, h, &view->cos_view);
    fitImage(w, h, &view->label);
    fitImage(w, h, &view->gray);
    const bool colour = config_.colour;
    if (colour) {
        fitImage(w, h, &view->colour);
    } else {
        view->colour = ColourImage();
    }
    const Eigen::Matrix3d R = T_W_C.linear();
    // Per frame: the primitives' camera-relative terms and their screen rectangles.
    const RayCaster::OriginTerms terms = caster_.originTerms(T_W_C.translation());
    const Eigen::Isometry3d T_C_W = T_W_C.inverse();
    const Eigen::Vector3d o = T_W_C.translation();
    const Scene& scene = caster_.scene();
    std::vector<PixelRect> wall_rects, box_rects, cylinder_rects;
    for (size_t k = 0; k < wall_hulls_.size(); ++k) {
        const Eigen::Vector2d& a = scene.polygon[k];
        const Eigen::Vector2d& b = scene.polygon[(k + 1) % scene.polygon.size()];
        wall_rects.push_back(projectedRect(wall_hulls_[k], T_C_W, distanceToSegment(o, a, b)));
    }
    for (size_t i = 0; i < box_hulls_.size(); ++i) {
        box_rects.push_back(projectedRect(box_hulls_[i], T_C_W, distanceToBox(o, scene.boxes[i])));
    }
    for (size_t i = 0; i < cylinder_hulls_.size(); ++i) {
        cylinder_rects.push_back(
            projectedRect(cylinder_hulls_[i], T_C_W, distanceToCylinder(o, scene.cylinders[i])));
    }
    const int tiles_x = (w + kTilePx - 1) / kTilePx;
    const int tiles_y = (h + kTilePx - 1) / kTilePx;
    tbb::parallel_for(tbb::blocked_range<int>(0, tiles_y), [&](const tbb::blocked_range<int>& ty) {
        std::vector<int> walls, boxes, cylinders;
        std::array<TileHit, kTilePx * kTilePx> hits;
        // Ascending indices of the primitives whose rectangle overlaps the tile.
        auto gather = [](const std::vector<PixelRect>& all, const PixelRect& tile,
                         std::vector<int>* out) {
            out->clear();
            for (size_t i = 0; i < all.size(); ++i) {
                const PixelRect& r = all[i];
                if (r.u0 <= tile.u1 && r.u1 >= tile.u0 && r.v0 <= tile.v1 && r.v1 >= tile.v0) {
                    out->push_back(static_cast<int>(i));
                }
            }
        };
        for (int y = ty.begin(); y < ty.end(); ++y) {
            for (int x = 0; x < tiles_x; ++x) {
                const PixelRect tile{x * kTilePx, y * kTilePx, std::min(w, (x + 1) * kTilePx) - 1,
                                     std::min(h, (y + 1) * kTilePx) - 1};
                gather(wall_rects, tile, &walls);
                gather(box_rects, tile, &boxes);
                gather(cylinder_rects, tile, &cylinders);
                const RayCaster::Candidates candidates{walls.data(),     walls.size(),
                                                       boxes.data(),     boxes.size(),
                                                       cylinders.data(), cylinders.size()};
                renderTile(R, terms, candidates, tile, view, colour ? hits.data() : nullptr);
                if (colour) shadeTile(tile, hits.data(), view);
            }
        }
    });
}

void Renderer::renderTile(const Eigen::Matrix3d& R, const RayCaster::OriginTerms& terms,
                          const RayCaster::Candidates& candidates, const PixelRect& tile,
                          RenderedView* view, TileHit* hits) const {
    const int w = camera_.width;
    const Scene& scene = caster_.scene();
    const int num_walls = scene.numWalls();
    const int num_boxes = static_cast<int>(scene.boxes.size());
    const int tile_w = tile.u1 - tile.u0 + 1;
    for (int v = tile.v0; v <= tile.v1; ++v) {
        for (int u = tile.u0; u <= tile.u1; ++u) {
            const size_t i = static_cast<size_t>(v) * w + u;
            const Eigen::Vector3d d = R * rays_C_[i];
            const RayHit hit = caster_.cast(terms, d, candidates);
            if (hits != nullptr) {
                hits[(v - tile.v0) * tile_w + (u - tile.u0)] = {hit.t, terms.o + hit.t * d,
                                                                hit.normal_W};
            }
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
}

void Renderer::shadeTile(const PixelRect& tile, const TileHit* hits, RenderedView* view) const {
    const int tile_w = tile.u1 - tile.u0 + 1;
    // 255 (ambient + (1 - ambient) cos): the light at the camera plus ambient.
    const float shade_ambient = 255.0F * config_.ambient;
    const float shade_direct = 255.0F * (1.0F - config_.ambient);
    const double inv_focal = 2.0 / (camera_.fx + camera_.fy);
    // round(x) of x >= 0, clamped to 255 (the same as uint8(min(255, x) + 0.5)).
    auto level = [](float x) {
        return static_cast<uint8_t>(std::min(static_cast<int>(x + 0.5F), 255));
    };
    for (int v = tile.v0; v <= tile.v1; ++v) {
        // Row pointers: the compiler cannot hoist them past the colour stores itself.
        const int16_t* labels = &view->label(tile.u0, v);
        const float* cos_view = &view->cos_view(tile.u0, v);
        Rgb8* colour = &view->colour(tile.u0, v);
        const TileHit* row_hits = hits + (v - tile.v0) * tile_w;
        for (int j = 0; j < tile_w; ++j) {
            const int label = labels[j];
            if (label == kNoPrimitive) {
                colour[j] = Rgb8{};
                continue;
            }
            const TileHit& hit = row_hits[j];
            const float cosv = cos_view[j];
            // Footprint of the pixel on the surface, its longer side: z / (f cos(view angle))
            // (a pixel spans cos(a) / f radians across at angle a off the axis, at range z /
            // cos(a), stretched by 1 / cos on the surface); cos clamped so grazing views stay
            // finite.
            const double footprint_m = hit.t * inv_focal / std::max(static_cast<double>(cosv), 0.1);
            const Colour rho = textures_.albedo(label, hit.p_W, hit.normal_W, footprint_m);
            const float light = shade_ambient + shade_direct * cosv;
            colour[j] =
                Rgb8{level(rho.x() * light), level(rho.y() * light), level(rho.z() * light)};
        }
    }
}

}  // namespace plumb::sim
