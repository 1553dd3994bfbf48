// SPDX-License-Identifier: Apache-2.0
#pragma once

// Exact ray casting of a Scene (reference §1.2-1.3). A camera ray through pixel (u, v) has the
// unnormalised direction d_C = ((u - cx)/fx, (v - cy)/fy, 1), so the hit parameter t along
// d_W = R_W_C d_C equals the z-depth of the hit in the camera frame.

#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/image/image.hpp"
#include "drivers/sim/scene.hpp"

namespace plumb::sim {

struct RayHit {
    double t = 0.0;                                      ///< ray parameter; 0 = no hit
    Eigen::Vector3d normal_W = Eigen::Vector3d::Zero();  ///< unit surface normal facing the ray
    int label = kNoPrimitive;                            ///< primitive label (scene.hpp)
};

/// Precomputed primitives for fast ray tests. Immutable after construction; thread-safe.
class RayCaster {
  public:
    explicit RayCaster(const Scene& scene);

    /// First surface hit by o + t d with t > 0. The origin must be inside the room; rays that
    /// leave the room through an opening (or hit nothing) return label kNoPrimitive, t = 0.
    RayHit cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const;

    const Scene& scene() const { return scene_; }

  private:
    struct Wall {
        Eigen::Vector2d a, e;    // start vertex and edge vector
        Eigen::Vector2d normal;  // unit, into the room
        double length;
        std::vector<Opening> openings;
    };
    struct BoxData {
        Eigen::Vector3d center;
        Eigen::Vector3d half;
        double c, s;  // cos, sin of yaw
    };
    Scene scene_;
    std::vector<Wall> walls_;
    std::vector<BoxData> boxes_;
};

/// One rendered view.
struct RenderedView {
    DepthImage depth;       ///< clean z-depth, metres, 0 where nothing is hit
    Image<float> cos_view;  ///< |cos| of the angle between surface normal and viewing ray, 0 = none
    Image<int16_t> label;   ///< primitive label per pixel (kNoPrimitive where nothing is hit)
    GrayImage gray;         ///< Lambertian shading with a light at the camera (albedo * cos)
};

/// Renders views of one scene through one camera. Thread-safe; render() uses TBB over rows and
/// gives the same result for any thread count.
class Renderer {
  public:
    Renderer(const Scene& scene, const PinholeCamera& camera);

    /// Renders the view from camera pose T_W_C (camera -> world) into `view` (resized as needed).
    void render(const Eigen::Isometry3d& T_W_C, RenderedView* view) const;

    const PinholeCamera& camera() const { return camera_; }
    const RayCaster& caster() const { return caster_; }

  private:
    RayCaster caster_;
    PinholeCamera camera_;
    std::vector<Eigen::Vector3d> rays_C_;  // per-pixel direction, z = 1
    std::vector<double> inv_norm_;         // 1 / |d_C| per pixel
};

}  // namespace plumb::sim
