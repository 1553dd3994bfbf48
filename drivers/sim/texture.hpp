// SPDX-License-Identifier: Apache-2.0
#pragma once

// Procedural albedo of the simulated room: what the colour camera sees before shading (reference
// §7b: photometric tracking needs textured walls). Every pattern lives in the surface's own
// metric coordinates, so it is glued to the geometry and the colour image stays registered to
// the depth image:
//   walls     (s, z): s metres along the wall from its start vertex, z above the floor;
//   floor, ceiling, cylinder caps (x, y) in W; cylinder sides (arc length, z);
//   box faces: the two box-frame coordinates spanning the face (sides: horizontal, z).
//
// Patterns (TextureMode::kTextured; kPlain gives every surface its base colour):
//   walls    "plaster": value noise in 4 octaves, cells 24, 12, 6, 3 cm, brightness std ~14 %
//            (precomputed per wall on a 1 cm grid with box-filtered mip levels), plus
//            `Scene::pictures_per_wall` framed pictures (checker, stripes or blobs in two
//            contrasting colours, features 4-12 cm) placed by `Scene::texture_seed`;
//   floor    wood: planks 14 cm x 1.2 m along x with 5 mm gaps, per-plank tint, grain;
//            tiles: 40 cm squares, 8 mm grout lines, per-tile tint, faint mottling;
//   ceiling  faint value noise (cells 40, 20 cm, brightness std ~2 %);
//   furniture (FurniturePattern) solid, noise, stripes or checker.
// Features are 3 cm or larger (>= 4 px at 4 m with fx = 525). Detail finer than a pixel's
// footprint on the surface is averaged out analytically (box-filtered edges and stripes, noise
// octaves faded), so distant and grazing views neither alias nor speckle.

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <vector>

#include "drivers/sim/scene.hpp"

namespace plumb::sim {

/// A framed picture on a wall, in the wall's coordinates (see above), metres.
struct Picture {
    enum class Kind { kChecker, kStripes, kBlobs };
    double s_min_m = 0.0;  ///< outer edge of the frame along the wall
    double s_max_m = 0.0;
    double z_min_m = 0.0;  ///< outer edge of the frame in height
    double z_max_m = 0.0;
    double frame_m = 0.03;  ///< width of the frame around the pattern
    Kind kind = Kind::kChecker;
    double scale_m = 0.06;  ///< checker square, stripe period or blob cell
    /// Stripes: unit normal of the stripes in (s, z).
    Eigen::Vector2d stripe_normal = Eigen::Vector2d::UnitX();
    Colour light = Colour::Ones();
    Colour dark = Colour::Zero();
    Colour frame = Colour::Zero();
};

/// The textures of one scene. Immutable after construction; albedo() is thread-safe.
class SurfaceTextures {
  public:
    explicit SurfaceTextures(const Scene& scene);

    /// RGB reflectance in [0, 1] of primitive `label` (scene.hpp) at the point p_W on its surface
    /// with unit normal `normal_W` (either side). `footprint_m` >= 0 is the width of a pixel's
    /// footprint on the surface, metres: detail finer than it is averaged out. A pure function of
    /// (scene, label, p_W, normal_W, footprint_m).
    Colour albedo(int label, const Eigen::Vector3d& p_W, const Eigen::Vector3d& normal_W,
                  double footprint_m) const {
        // Inline: the dispatch runs once per pixel of every colour frame.
        const double fp = std::max(footprint_m, kMinFootprintM);
        const bool plain = mode_ == TextureMode::kPlain;
        if (label == floorLabel()) return plain ? floor_colour_ : floorAlbedo(p_W, fp);
        if (label == ceilingLabel()) return plain ? ceiling_colour_ : ceilingAlbedo(p_W, fp);
        const int wall = label - 2;
        if (wall < num_walls_) return plain ? wall_colour_ : wallAlbedo(walls_[wall], p_W, fp);
        const size_t box = static_cast<size_t>(wall - num_walls_);
        if (box < boxes_.size()) {
            return plain ? boxes_[box].colour : boxAlbedo(boxes_[box], p_W, normal_W, fp);
        }
        const CylinderTexture& c = cylinders_[box - boxes_.size()];
        return plain ? c.colour : cylinderAlbedo(c, p_W, normal_W, fp);
    }

    /// The pictures on wall k (empty for a plain scene).
    const std::vector<Picture>& pictures(int wall) const { return walls_[wall].pictures; }

    /// Side of the value-noise lattice table; the noise repeats every kNoiseSize cells.
    static constexpr int kNoiseSize = 64;

  private:
    // Smallest footprint used by the filters (they divide by it), metres.
    static constexpr double kMinFootprintM = 1e-6;
    // Up to four value-noise octaves evaluated together, one SIMD lane each: lane o reads the
    // lattice at (m00 x + m01 y + ox, m10 x + m11 y + oy) for surface coordinates (x, y) in
    // metres, i.e. its own rotation, 1 / cell scaling and offset (which decorrelates surfaces).
    struct FractalNoise {
        Eigen::Array4f m00, m01, m10, m11, ox, oy;
        Eigen::Array4f inv_cell;   // 1 / cell (the smaller side), 1/m: the footprint fade
        Eigen::Array4f amplitude;  // 0 in unused lanes
        int octaves;               // lanes in use
    };
    // A scalar field sampled on a grid of texel_m over [0, width * texel_m] x [0, height *
    // texel_m] (texel centres at (i + 1/2) texel_m), with box-filtered mip levels (level l has
    // texels 2^l times as large), read bilinearly and between levels by the footprint.
    struct MipLevel {
        std::vector<float> texels;  // row-major, width x height (both >= 2)
        int width, height;
        float texels_per_m;  // 1 / texel size
        float max_x, max_y;  // largest texel coordinate whose right/lower neighbour exists
    };
    struct MipMap {
        double inv_texel_m = 100.0;  // of level 0
        std::vector<MipLevel> levels;
    };
    struct WallTexture {
        Eigen::Vector2d a, dir;  // start vertex and unit direction
        MipMap plaster;          // the plaster's noise over (s, z)
        std::vector<Picture> pictures;
        std::vector<FractalNoise> blobs;  // per picture (used by Kind::kBlobs)
    };
    struct BoxTexture {
        Eigen::Vector3d center;
        double c, s;  // cos, sin of yaw
        Colour colour;
        FurniturePattern pattern;
        FractalNoise noise;
    };
    struct CylinderTexture {
        Eigen::Vector2d center;
        double radius;
        double checker_cell;  // arc length of a checker square: a whole number fits around
        Colour colour;
        FurniturePattern pattern;
        FractalNoise noise;
    };

    // Octaves of cells cell_m, cell_m / 2, ... (at most 4) with amplitudes amplitude,
    // amplitude * persistence, ...; each lattice turned by its own angle when `rotate`, cells
    // stretched by `stretch_x` along x. Offsets drawn from (texture seed, salt).
    FractalNoise makeNoise(uint64_t salt, double cell_m, int octaves, float amplitude,
                           float persistence, bool rotate = true, double stretch_x = 1.0) const;
    // Zero-mean sum of the octaves at (x, y) metres; octaves whose cell is below 4 footprints
    // fade out (gone at 2).
    float noise(const FractalNoise& n, double x, double y, double fp) const;
    // The noise `n` (evaluated without fading) on a grid of `texel_m` over [0, width_m] x
    // [0, height_m], with its mip levels.
    MipMap makeMipMap(const FractalNoise& n, double width_m, double height_m, double texel_m) const;
    // Bilinear read of the level whose texels match footprint fp, blended with the next.
    static float sampleMipMap(const MipMap& map, double x, double y, double fp);
    static float sampleLevel(const MipLevel& level, double x, double y);

    Colour wallAlbedo(const WallTexture& w, const Eigen::Vector3d& p_W, double fp) const;
    // The wall colour `wall` at (s, z) with the picture over it (frame and pattern).
    Colour pictureAlbedo(const Picture& pic, const FractalNoise& blobs, double s, double z,
                         double fp, const Colour& wall) const;
    Colour floorAlbedo(const Eigen::Vector3d& p_W, double fp) const;
    Colour ceilingAlbedo(const Eigen::Vector3d& p_W, double fp) const;
    Colour furnitureAlbedo(const Colour& colour, FurniturePattern pattern,
                           const FractalNoise& noise, double u, double v, double checker_u_cell,
                           double fp) const;
    Colour boxAlbedo(const BoxTexture& b, const Eigen::Vector3d& p_W,
                     const Eigen::Vector3d& normal_W, double fp) const;
    Colour cylinderAlbedo(const CylinderTexture& c, const Eigen::Vector3d& p_W,
                          const Eigen::Vector3d& normal_W, double fp) const;

    TextureMode mode_;
    int num_walls_;
    uint64_t seed_;
    Colour wall_colour_, floor_colour_, ceiling_colour_;
    FloorPattern floor_pattern_;
    FractalNoise plank_grain_, tile_mottle_, ceiling_noise_;
    std::vector<WallTexture> walls_;
    std::vector<BoxTexture> boxes_;
    std::vector<CylinderTexture> cylinders_;
    std::vector<float> noise_;  // kNoiseSize^2 lattice values, uniform in [-1, 1]
};

}  // namespace plumb::sim
