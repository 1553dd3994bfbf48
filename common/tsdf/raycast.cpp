// SPDX-License-Identifier: Apache-2.0
#include "common/tsdf/raycast.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/tsdf/parallel.hpp"

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

}  // namespace

RaycastResult raycast(const TsdfVolume& volume, const PinholeCamera& camera,
                      const Eigen::Isometry3d& T_V_C, const RaycastConfig& config) {
    RaycastResult out;
    out.points_V = PointImage(camera.width, camera.height, invalidPoint());
    out.normals_V = PointImage(camera.width, camera.height, invalidPoint());
    out.depth = DepthImage(camera.width, camera.height, 0.0f);
    const Eigen::Matrix3f R = T_V_C.linear().cast<float>();
    const Eigen::Vector3f o = T_V_C.translation().cast<float>();
    const float vs = volume.voxelSize();
    const float bs = volume.blockSize();
    const float mu = volume.config().truncation_m;
    const float w_min = config.min_weight;

    parallelFor(config.num_threads, camera.height, [&](int v) {
        for (int u = 0; u < camera.width; ++u) {
            // Ray with unit z in the camera frame: the parameter t is the camera z-depth.
            const Eigen::Vector3f r = R * camera.ray(u, v).cast<float>();
            const float inv_len = 1.0f / r.norm();
            const float voxel_dt = vs * inv_len;
            float t = config.min_depth_m;
            float t_prev = 0.0f, f_prev = 0.0f;
            bool prev_valid = false;
            while (t < config.max_depth_m) {
                const Eigen::Vector3f p = o + t * r;
                float f = 0.0f;
                if (volume.findBlock(blockOf((p / vs).array().floor().cast<int>())) ==
                    BlockHashMap::kNotFound) {
                    // Unallocated: jump to where the ray leaves this block.
                    t = std::max(blockExit(o, r, p, bs) + 1e-3f * voxel_dt, t + 1e-3f * voxel_dt);
                    prev_valid = false;
                    continue;
                }
                if (!volume.interpolate(p, w_min, &f)) {
                    t += voxel_dt;
                    prev_valid = false;
                    continue;
                }
                if (prev_valid && f_prev > 0.0f && f < 0.0f) {
                    // + to - crossing: linear interpolation, then one secant refinement.
                    float ta = t_prev, fa = f_prev, tb = t, fb = f;
                    float ts = ta + (tb - ta) * fa / (fa - fb);
                    float fs = 0.0f;
                    if (volume.interpolate(o + ts * r, w_min, &fs) && fs != 0.0f) {
                        if (fs > 0.0f) {
                            ta = ts;
                            fa = fs;
                        } else {
                            tb = ts;
                            fb = fs;
                        }
                        ts = ta + (tb - ta) * fa / (fa - fb);
                    }
                    const Eigen::Vector3f hit = o + ts * r;
                    Eigen::Vector3f grad;
                    if (volume.gradient(hit, w_min, &grad) && grad.squaredNorm() > 0.0f) {
                        out.points_V(u, v) = hit;
                        out.normals_V(u, v) = grad.normalized();
                        out.depth(u, v) = ts;
                    }
                    break;
                }
                t_prev = t;
                f_prev = f;
                prev_valid = true;
                t += std::max(voxel_dt, config.step_fraction * mu * std::abs(f) * inv_len);
            }
        }
    });
    return out;
}

}  // namespace plumb::tsdf
