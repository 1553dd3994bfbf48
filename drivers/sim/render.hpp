// SPDX-License-Identifier: Apache-2.0
#pragma once

// Exact ray casting of a Scene (reference §1.2-1.3). A camera ray through pixel (u, v) has the
// unnormalised direction d_C = ((u - cx)/fx, (v - cy)/fy, 1), so the hit parameter t along
// d_W = R_W_C d_C equals the z-depth of the hit in the camera frame.

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/image/image.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/texture.hpp"

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

    /// The ray-independent terms of every primitive test for rays from one origin o. cast()
    /// computes them per primitive and ray; a renderer computes them once per frame and passes
    /// them to the cast() overload below, which does the same arithmetic (bit-identical hits).
    struct OriginTerms {
        Eigen::Vector3d o = Eigen::Vector3d::Zero();
        std::vector<Eigen::Vector2d> wall_ao;  ///< per wall: a - o_xy
        std::vector<double> wall_num;          ///< per wall: (a - o_xy) x e (t's numerator)
        std::vector<Eigen::Vector3d> box_ol;   ///< per box: the origin in the box frame
        std::vector<Eigen::Vector2d> cyl_q;    ///< per cylinder: o_xy - axis
        std::vector<double> cyl_c;             ///< per cylinder: |q|^2 - r^2
    };
    OriginTerms originTerms(const Eigen::Vector3d& o) const;

    /// Primitives a bundle of rays may hit, as ascending indices into the scene's walls, boxes
    /// and cylinders (floor and ceiling are always tested). Non-owning.
    struct Candidates {
        const int* walls = nullptr;
        size_t num_walls = 0;
        const int* boxes = nullptr;
        size_t num_boxes = 0;
        const int* cylinders = nullptr;
        size_t num_cylinders = 0;
    };

    /// cast(terms.o, d) testing only `candidates`: the same hit as cast() whenever every
    /// primitive the ray hits is a candidate (e.g. a screen-space cull that keeps every primitive
    /// whose projection covers the ray's pixel).
    RayHit cast(const OriginTerms& terms, const Eigen::Vector3d& d,
                const Candidates& candidates) const;

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
    struct Nearest;  // the nearest surface found so far along one ray (render.cpp)

    // The per-primitive tests of both cast() overloads: each updates `n` when the ray o + t d
    // hits the primitive nearer than n->best. Ray-independent terms come in as arguments.
    void castFloorCeiling(const Eigen::Vector3d& o, const Eigen::Vector3d& d, Nearest* n) const;
    void castWall(size_t k, const Eigen::Vector2d& ao, double num, const Eigen::Vector3d& o,
                  const Eigen::Vector3d& d, Nearest* n) const;
    void castBox(size_t i, const Eigen::Vector3d& ol, const Eigen::Vector3d& d, Nearest* n) const;
    void castCylinder(size_t i, const Eigen::Vector2d& q, double c, const Eigen::Vector3d& o,
                      const Eigen::Vector3d& d, Nearest* n) const;
    static RayHit finish(const Nearest& n);

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
    /// Clean colour (no exposure change, no noise), registered to `depth`: per channel
    /// round(255 * rho * (ambient + (1 - ambient) * cos)) with rho the surface's textured RGB
    /// reflectance (SurfaceTextures), black where nothing is hit. Empty when the renderer was
    /// built without colour.
    ColourImage colour;
};

/// Options of a Renderer.
struct RenderConfig {
    /// Render RenderedView::colour (textures and shading); false leaves it empty.
    bool colour = true;
    /// Colour shading: fraction of the light that is ambient (the rest comes from a point light
    /// at the camera, Lambertian), in [0, 1].
    float ambient = 0.1F;
};

/// Renders views of one scene through one camera. Thread-safe; render() uses TBB over tiles and
/// gives the same result for any thread count.
class Renderer {
  public:
    Renderer(const Scene& scene, const PinholeCamera& camera, const RenderConfig& config = {});

    /// Renders the view from camera pose T_W_C (camera -> world) into `view` (resized as needed;
    /// buffers of the right size are reused, so rendering into the same view allocates nothing).
    void render(const Eigen::Isometry3d& T_W_C, RenderedView* view) const;

    const PinholeCamera& camera() const { return camera_; }
    const RayCaster& caster() const { return caster_; }
    const SurfaceTextures& textures() const { return textures_; }
    const RenderConfig& config() const { return config_; }

  private:
    // Inclusive pixel rectangle; empty when u0 > u1 or v0 > v1.
    struct PixelRect {
        int u0, v0, u1, v1;
    };
    // Corners of a convex hull of one primitive in W (walls use 4 of the 8).
    struct Hull {
        std::array<Eigen::Vector3d, 8> corners_W;
        int num_corners;
    };
    PixelRect projectedRect(const Hull& hull, const Eigen::Isometry3d& T_C_W, double dist_m) const;
    // What the colour pass needs of one pixel's ray hit (t = 0 where nothing is hit).
    struct TileHit {
        double t;
        Eigen::Vector3d p_W;  // the hit point
        Eigen::Vector3d normal_W;
    };
    // Ray casts the tile's pixels into depth, cos_view, label and gray, and records each pixel's
    // hit in `hits` (row-major over the tile) when it is not null.
    void renderTile(const Eigen::Matrix3d& R_W_C, const RayCaster::OriginTerms& terms,
                    const RayCaster::Candidates& candidates, const PixelRect& tile,
                    RenderedView* view, TileHit* hits) const;
    // The colour of the tile's pixels from their hits and the labels and cosines renderTile wrote.
    void shadeTile(const PixelRect& tile, const TileHit* hits, RenderedView* view) const;

    RayCaster caster_;
    SurfaceTextures textures_;
    RenderConfig config_;
    PinholeCamera camera_;
    std::vector<Eigen::Vector3d> rays_C_;  // per-pixel direction, z = 1
    std::vector<double> inv_norm_;         // 1 / |d_C| per pixel
    double max_ray_norm_ = 1.0;            // max |d_C| over the pixels
    std::vector<Hull> wall_hulls_, box_hulls_, cylinder_hulls_;
};

}  // namespace plumb::sim
