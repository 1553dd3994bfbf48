// SPDX-License-Identifier: Apache-2.0
#include "common/tsdf/raycast.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "common/core/check.hpp"
#include "common/core/parallel.hpp"

namespace plumb::tsdf {
namespace {

/// Ray parameter where the ray o + t r leaves the block that contains o + t r.
float blockExit(const Eigen::Vector3f& o, const Eigen::Vector3f& r, const Eigen::Vector3f& p,
                float block_size) {
    float t_exit = std::numeric_limits<float>::infinity();
    for (int i = 0; i < 3; ++i) {
        if (r[i] == 0.0f) continue;
        const float cell = std::floor(p[i] / block_size);
        const float bound = (r[i] > 0.0f ? cell + 1.0f : cell) * block_size;
        t_exit = std::min(t_exit, (bound - o[i]) / r[i]);
    }
    return t_exit;
}

/// Per-tile (4x4 pixels) camera z-range of the allocated blocks (InfiniTAM's "range image"): rays
/// only march where some block projects, from the nearest to the farthest block corner of their
/// tile. The bounds are conservative (block corners, whole tiles), so no crossing is missed;
/// min/max are order-independent, so the result does not depend on the thread count.
struct RangeImage {
    static constexpr int kTile = 4;  ///< tile edge, pixels
    int tiles_x = 0, tiles_y = 0;
    std::vector<float> z_min, z_max;  ///< per tile; z_min > z_max = no block

    bool bounds(int u, int v, float* lo, float* hi) const {
        const size_t i = static_cast<size_t>((v / kTile) * tiles_x + u / kTile);
        *lo = z_min[i];
        *hi = z_max[i];
        return *lo <= *hi;
    }
};

RangeImage blockRanges(const TsdfVolume& volume, const PinholeCamera& camera,
                       const Eigen::Isometry3d& T_V_C, const RaycastConfig& config) {
    RangeImage r;
    r.tiles_x = (camera.width + RangeImage::kTile - 1) / RangeImage::kTile;
    r.tiles_y = (camera.height + RangeImage::kTile - 1) / RangeImage::kTile;
    const size_t num_tiles = static_cast<size_t>(r.tiles_x) * static_cast<size_t>(r.tiles_y);
    constexpr float kInf = std::numeric_limits<float>::infinity();
    const Eigen::Isometry3d T_C_V = T_V_C.inverse();
    const Eigen::Matrix3f R = T_C_V.linear().cast<float>();
    const Eigen::Vector3f t = T_C_V.translation().cast<float>();
    const float bs = volume.blockSize();
    const float fx = static_cast<float>(camera.fx), fy = static_cast<float>(camera.fy);
    const float cx = static_cast<float>(camera.cx), cy = static_cast<float>(camera.cy);
    const float z_near = std::max(config.min_depth_m, 1e-3f);
    const std::vector<BlockKey>& keys = volume.blockKeys();
    constexpr int kBlocksPerChunk = 2048;
    const int num_chunks = static_cast<int>((keys.size() + kBlocksPerChunk - 1) / kBlocksPerChunk);
    std::vector<std::vector<float>> lo(static_cast<size_t>(num_chunks));
    std::vector<std::vector<float>> hi(static_cast<size_t>(num_chunks));
    parallelFor(config.num_threads, num_chunks, [&](int c) {
        std::vector<float>& zl = lo[static_cast<size_t>(c)];
        std::vector<float>& zh = hi[static_cast<size_t>(c)];
        zl.assign(num_tiles, kInf);
        zh.assign(num_tiles, -kInf);
        const size_t end = std::min(keys.size(), static_cast<size_t>(c + 1) * kBlocksPerChunk);
        for (size_t b = static_cast<size_t>(c) * kBlocksPerChunk; b < end; ++b) {
            const Eigen::Vector3f origin = R * (keys[b].cast<float>() * bs) + t;
            float zmin = kInf, zmax = -kInf;
            float umin = kInf, umax = -kInf, vmin = kInf, vmax = -kInf;
            bool straddles = false;
            for (int k = 0; k < 8; ++k) {
                const Eigen::Vector3f p = origin + R.col(0) * (bs * static_cast<float>(k & 1)) +
                                          R.col(1) * (bs * static_cast<float>((k >> 1) & 1)) +
                                          R.col(2) * (bs * static_cast<float>((k >> 2) & 1));
                zmin = std::min(zmin, p.z());
                zmax = std::max(zmax, p.z());
                if (p.z() < z_near) {
                    straddles = true;
                    continue;
                }
                const float u = fx * p.x() / p.z() + cx, v = fy * p.y() / p.z() + cy;
                umin = std::min(umin, u);
                umax = std::max(umax, u);
                vmin = std::min(vmin, v);
                vmax = std::max(vmax, v);
            }
            if (zmax < z_near || zmin > config.max_depth_m) continue;
            int tu0 = 0, tu1 = r.tiles_x - 1, tv0 = 0, tv1 = r.tiles_y - 1;
            if (!straddles) {
                // Pixel (u, v) covers [u - 0.5, u + 0.5]; one pixel of margin for rounding.
                if (umax < -1.0f || vmax < -1.0f || umin > static_cast<float>(camera.width) ||
                    vmin > static_cast<float>(camera.height)) {
                    continue;
                }
                tu0 = std::max(0, static_cast<int>(std::floor(umin - 1.0f)) / RangeImage::kTile);
                tv0 = std::max(0, static_cast<int>(std::floor(vmin - 1.0f)) / RangeImage::kTile);
                tu1 = std::min(r.tiles_x - 1,
                               static_cast<int>(std::floor(umax + 1.0f)) / RangeImage::kTile);
                tv1 = std::min(r.tiles_y - 1,
                               static_cast<int>(std::floor(vmax + 1.0f)) / RangeImage::kTile);
            }
            for (int tv = tv0; tv <= tv1; ++tv) {
                for (int tu = tu0; tu <= tu1; ++tu) {
                    const size_t i = static_cast<size_t>(tv * r.tiles_x + tu);
                    zl[i] = std::min(zl[i], zmin);
                    zh[i] = std::max(zh[i], zmax);
                }
            }
        }
    });
    r.z_min.assign(num_tiles, kInf);
    r.z_max.assign(num_tiles, -kInf);
    for (int c = 0; c < num_chunks; ++c) {
        for (size_t i = 0; i < num_tiles; ++i) {
            r.z_min[i] = std::min(r.z_min[i], lo[static_cast<size_t>(c)][i]);
            r.z_max[i] = std::max(r.z_max[i], hi[static_cast<size_t>(c)][i]);
        }
    }
    return r;
}

/// Normals of the hits from their 4-neighbourhood (neighbourNormal), facing the camera at o;
/// hits without one are dropped (every returned hit has a normal).
void normalsFromNeighbours(const Eigen::Vector3f& o, const RaycastConfig& config,
                           RaycastResult* out) {
    const PointImage points = out->points_V;
    const DepthImage depth = out->depth;
    parallelFor(config.num_threads, depth.height(), [&](int v) {
        for (int u = 0; u < depth.width(); ++u) {
            if (!(depth(u, v) > 0.0f)) continue;
            Eigen::Vector3f n;
            if (neighbourNormal(points, depth, u, v, config.max_normal_depth_jump_m, &n)) {
                out->normals_V(u, v) = n.dot(o - points(u, v)) < 0.0f ? Eigen::Vector3f(-n) : n;
            } else {
                out->points_V(u, v) = invalidPoint();
                out->depth(u, v) = 0.0f;
            }
        }
    });
}

/// Cell normals smoothed: each hit's normal becomes the normalised sum of the cell gradients of
/// the hits in its 3x3 neighbourhood whose depth is within max_normal_depth_jump_m of its own
/// (the same surface), facing the camera as before.
void smoothCellNormals(const RaycastConfig& config, RaycastResult* out) {
    const PointImage gradients = out->normals_V;
    const DepthImage& depth = out->depth;
    const int w = depth.width(), h = depth.height();
    const float jump = config.max_normal_depth_jump_m;
    parallelFor(config.num_threads, h, [&](int v) {
        for (int u = 0; u < w; ++u) {
            const float z = depth(u, v);
            if (!(z > 0.0f)) continue;
            Eigen::Vector3f sum = Eigen::Vector3f::Zero();
            for (int y = std::max(0, v - 1); y <= std::min(h - 1, v + 1); ++y) {
                for (int x = std::max(0, u - 1); x <= std::min(w - 1, u + 1); ++x) {
                    const float zn = depth(x, y);
                    if (zn > 0.0f && std::abs(zn - z) <= jump) sum += gradients(x, y);
                }
            }
            const float len = sum.norm();
            if (len > 0.0f) out->normals_V(u, v) = sum / len;
        }
    });
}

/// Nearest valid depth of `hint` under ray (u, v) of a camera `scale` times coarser, widened by
/// `radius` hint pixels on every side; infinity when there is none.
float nearestHint(const DepthImage& hint, int u, int v, int scale, int radius) {
    const int x0 = std::max(0, u * scale - radius),
              x1 = std::min(hint.width(), (u + 1) * scale + radius);
    const int y0 = std::max(0, v * scale - radius),
              y1 = std::min(hint.height(), (v + 1) * scale + radius);
    float d = std::numeric_limits<float>::infinity();
    for (int y = y0; y < y1; ++y) {
        for (int x = x0; x < x1; ++x) {
            const float h = hint(x, y);
            if (h > 0.0f) d = std::min(d, h);
        }
    }
    return d;
}

/// Where a march ended: a front-face hit, nothing before t_end, or a hinted start that is not in
/// observed free space.
enum class March { kHit, kMiss, kBadStart };

/// The ray of pixel (u, v) in the volume frame, o + t r with unit z in the camera frame: the
/// parameter t is the camera z-depth.
struct Ray {
    int u = 0, v = 0;
    Eigen::Vector3f r;
    float inv_len = 0.0f;   ///< 1 / |r|
    float voxel_dt = 0.0f;  ///< a voxel in units of t
    float t_end = 0.0f;     ///< the march stops here
};

/// Marches rays from the camera centre o through a volume (§2.4) and writes their hits into a
/// RaycastResult; const, so the rows' threads share one.
class RayMarcher {
  public:
    RayMarcher(const TsdfVolume& volume, const RaycastConfig& config, const Eigen::Vector3f& o,
               RaycastResult* out)
        : volume_(volume),
          config_(config),
          o_(o),
          out_(out),
          vs_(volume.voxelSize()),
          bs_(volume.blockSize()),
          mu_(volume.config().truncation_m),
          cell_normal_(config.normals == RaycastNormals::kCell) {}

    float voxelSize() const { return vs_; }
    float truncation() const { return mu_; }
    const RaycastConfig& config() const { return config_; }

    /// Marches `ray` from t to its end; a hinted start must lie in observed free space (F > 0).
    March march(const Ray& ray, float t, bool hinted, BlockCache* cache) const {
        const Eigen::Vector3f& r = ray.r;
        float t_prev = 0.0f, f_prev = 0.0f;
        bool prev_valid = false;
        bool aimed = false;  // this sample is where the last one predicted the surface
        while (t < ray.t_end) {
            const Eigen::Vector3f p = o_ + t * r;
            float f = 0.0f;
            Eigen::Vector3f grad = Eigen::Vector3f::Zero();
            const bool secant = config_.secant_hits && aimed && prev_valid;
            const Sample s = volume_.sample(p, config_.min_weight, cache, &f,
                                            secant && cell_normal_ ? &grad : nullptr);
            aimed = false;
            const bool allocated = s != Sample::kUnallocated;
            const bool observed = s == Sample::kObserved;
            if (hinted) {
                if (!observed || !(f > 0.0f)) return March::kBadStart;
                hinted = false;
            }
            if (!allocated) {
                // Unallocated: jump to where the ray leaves this block.
                t = std::max(blockExit(o_, r, p, bs_) + 1e-3f * ray.voxel_dt,
                             t + 1e-3f * ray.voxel_dt);
                prev_valid = false;
                continue;
            }
            if (!observed) {
                // Unobserved voxels (behind surfaces or never in view): an observed band is at
                // least 2 mu thick along the viewing rays that made it, so mu / 2 steps cannot
                // jump over one.
                t += std::max(ray.voxel_dt, 0.5f * mu_ * ray.inv_len);
                prev_valid = false;
                continue;
            }
            if (secant && f < f_prev && std::abs(f) * mu_ < 0.5f * vs_) {
                // The sample aimed at the surface landed within half a voxel of it: the secant
                // through it and the last one is the crossing (exact where the field is linear
                // along the ray, as on planes).
                record(ray, t - f * (t - t_prev) / (f - f_prev), grad, cache);
                return March::kHit;
            }
            if (prev_valid && f_prev > 0.0f && f < 0.0f) {
                refineCrossing(ray, t_prev, f_prev, t, f, cache);
                return March::kHit;
            }
            t_prev = t;
            f_prev = f;
            prev_valid = true;
            // Near a surface in front (F mu, the projective distance of the fused views, within
            // two voxels) aim half a voxel past the crossing it predicts: the next sample then
            // mostly brackets it. Elsewhere the conservative step.
            const float predicted = f * mu_;
            if (f > 0.0f && predicted < 2.0f * vs_) {
                // With secant hits aim at the crossing itself (at least a tenth of a voxel on,
                // so that the march always advances).
                t += config_.secant_hits ? std::max(predicted, 0.1f * ray.voxel_dt)
                                         : predicted + 0.5f * ray.voxel_dt;
                aimed = true;
            } else {
                t +=
                    std::max(ray.voxel_dt, config_.step_fraction * mu_ * std::abs(f) * ray.inv_len);
            }
        }
        return March::kMiss;
    }

  private:
    /// A + to - crossing between samples (ta, fa) and (tb, fb): linear interpolation, then one
    /// secant refinement; records the hit.
    void refineCrossing(const Ray& ray, float ta, float fa, float tb, float fb,
                        BlockCache* cache) const {
        float ts = ta + (tb - ta) * fa / (fa - fb);
        float fs = 0.0f;
        Eigen::Vector3f grad = Eigen::Vector3f::Zero();
        const Sample refined = volume_.sample(o_ + ts * ray.r, config_.min_weight, cache, &fs,
                                              cell_normal_ ? &grad : nullptr);
        if (cell_normal_ && refined != Sample::kObserved) return;
        if (refined == Sample::kObserved && fs != 0.0f) {
            if (fs > 0.0f) {
                ta = ts;
                fa = fs;
            } else {
                tb = ts;
                fb = fs;
            }
            ts = ta + (tb - ta) * fa / (fa - fb);
        }
        record(ray, ts, grad, cache);
    }

    /// Records a hit at ray parameter ts; `grad` is the cell gradient near it (kCell).
    void record(const Ray& ray, float ts, const Eigen::Vector3f& grad, BlockCache* cache) const {
        const Eigen::Vector3f hit = o_ + ts * ray.r;
        Eigen::Vector3f g = grad;
        if (config_.normals == RaycastNormals::kNeighbours) {
            out_->points_V(ray.u, ray.v) = hit;  // normal from the neighbours, afterwards
            out_->depth(ray.u, ray.v) = ts;
        } else if ((cell_normal_ || volume_.gradient(hit, config_.min_weight, cache, &g)) &&
                   g.squaredNorm() > 0.0f) {
            out_->points_V(ray.u, ray.v) = hit;
            out_->normals_V(ray.u, ray.v) = g.normalized();
            out_->depth(ray.u, ray.v) = ts;
        }
    }

    const TsdfVolume& volume_;
    const RaycastConfig& config_;
    const Eigen::Vector3f o_;
    RaycastResult* out_;
    const float vs_, bs_, mu_;
    const bool cell_normal_;
};

/// Marches `ray` from the depth this camera saw where the model was last fused (`hint`, `scale`
/// times finer than the camera): its zero crossing lies near it, and the space in front was just
/// carved free (z units, as the projective SDF; the nearest valid depth of the s x s hint pixels
/// under a coarser ray). True when the ray is done: marched from a hinted start, or not to be cast
/// at all; false when it must march in full from t_begin.
bool marchFromHint(const RayMarcher& marcher, const Ray& ray, float t_begin, const DepthImage& hint,
                   int scale, BlockCache* cache) {
    const RaycastConfig& config = marcher.config();
    const float vs = marcher.voxelSize(), mu = marcher.truncation();
    float d = nearestHint(hint, ray.u, ray.v, scale, 0);
    if (config.skip_hints_beyond_end && std::isfinite(d) && d > ray.t_end) return true;
    if (std::isfinite(d)) {
        // March from close in front of it: mostly the crossing is one or two samples away.
        // Where the model surface lies nearer than that (noise in the hint) that start is not
        // free space, so march from one truncation and one voxel in front, and if that is not
        // free space either, the whole ray.
        const float t_near = d - config.hint_near_voxels * vs;
        if (config.hint_near_voxels > 0.0f && t_near > t_begin && t_near < ray.t_end &&
            marcher.march(ray, t_near, /*hinted=*/true, cache) != March::kBadStart) {
            return true;
        }
    } else if (config.hint_hole_radius_px >= 0) {
        // A hole in the hint: the nearest depth around it (a depth edge, a dropout) starts the
        // march; where the hinted frame saw nothing at all around the ray, neither will the
        // frame being tracked, and the ray is not cast.
        d = nearestHint(hint, ray.u, ray.v, scale, config.hint_hole_radius_px);
        if (!std::isfinite(d)) return true;
    }
    const float t_hint = d - (mu + vs);
    return std::isfinite(t_hint) && t_hint > t_begin && t_hint < ray.t_end &&
           marcher.march(ray, t_hint, /*hinted=*/true, cache) != March::kBadStart;
}

}  // namespace

RaycastResult raycast(const TsdfVolume& volume, const PinholeCamera& camera,
                      const Eigen::Isometry3d& T_V_C, const RaycastConfig& config,
                      const DepthImage* start_hint) {
    RaycastResult out;
    out.points_V = PointImage(camera.width, camera.height, invalidPoint());
    out.normals_V = PointImage(camera.width, camera.height, invalidPoint());
    out.depth = DepthImage(camera.width, camera.height, 0.0f);
    const Eigen::Matrix3f R = T_V_C.linear().cast<float>();
    const Eigen::Vector3f o = T_V_C.translation().cast<float>();
    const float vs = volume.voxelSize();
    const RangeImage ranges = blockRanges(volume, camera, T_V_C, config);
    // The hint may be finer than the camera by an integer factor (a raycast at a coarser
    // pyramid level): ray (u, v) reads hint pixel (s u, s v).
    int hint_scale = 0;
    if (start_hint != nullptr && !start_hint->empty()) {
        hint_scale = start_hint->width() / camera.width;
        PLUMB_CHECK(hint_scale >= 1 && start_hint->width() == hint_scale * camera.width &&
                    start_hint->height() == hint_scale * camera.height)
            << "raycast start hint is " << start_hint->width() << "x" << start_hint->height()
            << ", not a multiple of the camera's " << camera.width << "x" << camera.height;
    }

    const RayMarcher marcher(volume, config, o, &out);
    parallelFor(config.num_threads, camera.height, [&](int v) {
        BlockCache cache(volume);  // neighbouring rays mostly read the same blocks
        for (int u = 0; u < camera.width; ++u) {
            // Ray with unit z in the camera frame: the parameter t is the camera z-depth.
            Ray ray;
            ray.u = u;
            ray.v = v;
            ray.r = R * camera.ray(u, v).cast<float>();
            ray.inv_len = 1.0f / ray.r.norm();
            ray.voxel_dt = vs * ray.inv_len;
            float z_lo = 0.0f, z_hi = 0.0f;
            if (!ranges.bounds(u, v, &z_lo, &z_hi)) continue;  // no block along this ray
            const float t_begin = std::max(config.min_depth_m, z_lo - ray.voxel_dt);
            ray.t_end = std::min(config.max_depth_m, z_hi + ray.voxel_dt);
            if (hint_scale > 0 &&
                marchFromHint(marcher, ray, t_begin, *start_hint, hint_scale, &cache)) {
                continue;
            }
            marcher.march(ray, t_begin, /*hinted=*/false, &cache);
        }
    });
    if (config.normals == RaycastNormals::kNeighbours) normalsFromNeighbours(o, config, &out);
    if (config.normals == RaycastNormals::kCell) smoothCellNormals(config, &out);
    return out;
}

}  // namespace plumb::tsdf
