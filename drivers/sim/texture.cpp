// SPDX-License-Identifier: Apache-2.0
#include "drivers/sim/texture.hpp"

#include <algorithm>
#include <cmath>

#include "drivers/sim/noise.hpp"

namespace plumb::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Salts that keep the texture's random streams apart from each other.
constexpr uint64_t kNoiseTableSalt = 0x7e57a11ce0ULL;
constexpr uint64_t kOctaveSalt = 0x0c7a7e5ULL;
constexpr uint64_t kPictureSalt = 0x91c70e7eULL;
constexpr uint64_t kPlankSalt = 0x91a4cULL;
constexpr uint64_t kTileSalt = 0x7113ULL;

// Wall plaster: 4 octaves from 24 cm down to 3 cm.
constexpr double kPlasterCellM = 0.24;
constexpr float kPlasterAmplitude = 0.22F;
constexpr float kPlasterPersistence = 0.85F;
// Ceiling: faint, 2 octaves from 40 cm.
constexpr double kCeilingCellM = 0.40;
constexpr float kCeilingAmplitude = 0.05F;
// Floor planks and tiles.
constexpr double kPlankWidthM = 0.14;
constexpr double kPlankLengthM = 1.2;
constexpr double kPlankGapM = 0.005;
constexpr double kTileM = 0.40;
constexpr double kGroutM = 0.008;
// Furniture patterns.
constexpr double kFurnitureNoiseCellM = 0.12;
constexpr double kStripePeriodM = 0.10;
constexpr double kCheckerCellM = 0.08;
// Picture placement: clearance to the wall ends, between pictures and to openings, metres.
constexpr double kPictureEndClearanceM = 0.2;
constexpr double kPictureGapM = 0.15;
constexpr int kPlacementAttempts = 40;
// Lattice rotation of the noise octaves: 0.5, 1.7, 2.9 and 4.1 rad.
constexpr double kOctaveCos[4] = {0.8775825618903728, -0.1288444942955251, -0.9709581651495905,
                                  -0.5748239465332692};
constexpr double kOctaveSin[4] = {0.479425538604203, 0.9916648104524686, 0.2392493292139824,
                                  -0.8182771110644103};

// A uniform number in [0, 1) from a hash of (seed, a, b, c).
double uniform01(uint64_t seed, uint64_t a, uint64_t b, uint64_t c) {
    const uint64_t h = mixSeed(mixSeed(mixSeed(mixSeed(seed) ^ a) ^ b) ^ c);
    return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

// Integer lattice hash of a cell (i, j) to [0, 1).
double cellHash01(uint64_t salt, int64_t i, int64_t j) {
    const uint64_t h = mixSeed(salt ^ mixSeed(static_cast<uint64_t>(i) * 0x9E3779B97F4A7C15ULL ^
                                              static_cast<uint64_t>(j)));
    return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

float smoothStep(float edge0, float edge1, float x) {
    const float t = std::clamp((x - edge0) / (edge1 - edge0), 0.0F, 1.0F);
    return t * t * (3.0F - 2.0F * t);
}

// Mean over [x - w/2, x + w/2] of the periodic indicator 1[frac(x / period) < duty]: a box-
// filtered pulse train (stripes, gaps, grout), exact for any footprint w >= 0.
double filteredPulse(double x, double period, double duty, double w) {
    const double on = duty * period;
    if (w < 1e-7) return x - period * std::floor(x / period) < on ? 1.0 : 0.0;
    // Integral of the indicator from 0 to x.
    auto integral = [&](double t) {
        const double n = std::floor(t / period);
        return n * on + std::min(t - n * period, on);
    };
    return (integral(x + 0.5 * w) - integral(x - 0.5 * w)) / w;
}

// Fraction of [x - w/2, x + w/2] inside [lo, hi] (a box-filtered edge pair).
double filteredInterval(double x, double lo, double hi, double w) {
    if (w < 1e-7) return x >= lo && x <= hi ? 1.0 : 0.0;
    const double overlap = std::min(hi, x + 0.5 * w) - std::max(lo, x - 0.5 * w);
    return std::clamp(overlap / w, 0.0, 1.0);
}

// Box-filtered checkerboard of squares `cell` in [0, 1]: the XOR of two pulse trains is bilinear
// in them, so filtering each axis gives the exactly filtered checker.
double filteredChecker(double u, double v, double cell, double w) {
    const double a = filteredPulse(u, 2.0 * cell, 0.5, w);
    const double b = filteredPulse(v, 2.0 * cell, 0.5, w);
    return a + b - 2.0 * a * b;
}

Colour lerp(const Colour& a, const Colour& b, float t) { return a + t * (b - a); }

Colour clampColour(const Colour& c) { return c.cwiseMax(0.0F).cwiseMin(1.0F); }

// Colour with every channel drawn from [lo, hi).
Colour randomColour(uint64_t seed, uint64_t a, uint64_t b, double lo, double hi) {
    Colour c;
    for (int ch = 0; ch < 3; ++ch) {
        c[ch] = static_cast<float>(lo + (hi - lo) * uniform01(seed, a, b, 100 + ch));
    }
    return c;
}

// Pictures on one wall: `count` attempts at non-overlapping framed rectangles that keep clear of
// the wall ends, the openings and each other; a wall with no room for one gets fewer.
std::vector<Picture> placePictures(const Scene& scene, int wall, double length_m, uint64_t seed) {
    std::vector<Picture> out;
    const double height = scene.height_m;
    for (int p = 0; p < scene.pictures_per_wall; ++p) {
        for (int attempt = 0; attempt < kPlacementAttempts; ++attempt) {
            auto u = [&](int field) {
                return uniform01(seed ^ kPictureSalt, static_cast<uint64_t>(wall),
                                 static_cast<uint64_t>(p * kPlacementAttempts + attempt),
                                 static_cast<uint64_t>(field));
            };
            Picture pic;
            const double w = 0.4 + 0.6 * u(0);
            const double h = 0.3 + 0.5 * u(1);
            const double free_length = length_m - 2.0 * kPictureEndClearanceM - w;
            const double z_lo = 0.6, z_hi = height - 0.25;  // frame bottom and top limits
            if (free_length <= 0.0 || z_hi - z_lo < h) continue;
            pic.s_min_m = kPictureEndClearanceM + free_length * u(2);
            pic.s_max_m = pic.s_min_m + w;
            const double z_centre = std::clamp(1.1 + 0.7 * u(3), z_lo + 0.5 * h,
                                               std::max(z_lo + 0.5 * h, z_hi - 0.5 * h));
            pic.z_min_m = z_centre - 0.5 * h;
            pic.z_max_m = z_centre + 0.5 * h;
            bool clear = true;
            for (const Picture& q : out) {
                clear &= pic.s_max_m + kPictureGapM < q.s_min_m ||
                         q.s_max_m + kPictureGapM < pic.s_min_m ||
                         pic.z_max_m + kPictureGapM < q.z_min_m ||
                         q.z_max_m + kPictureGapM < pic.z_min_m;
            }
            for (const Opening& o : scene.openings) {
                if (o.wall != wall) continue;
                clear &= pic.s_max_m + 0.05 < o.offset_m ||
                         o.offset_m + o.width_m + 0.05 < pic.s_min_m ||
                         pic.z_max_m + 0.05 < o.z_min_m || o.z_max_m + 0.05 < pic.z_min_m;
            }
            if (!clear) continue;
            const int kind = std::min(2, static_cast<int>(3.0 * u(4)));
            pic.kind = static_cast<Picture::Kind>(kind);
            switch (pic.kind) {
                case Picture::Kind::kChecker:
                    pic.scale_m = 0.04 + 0.04 * u(5);
                    break;
                case Picture::Kind::kStripes:
                    pic.scale_m = 0.05 + 0.07 * u(5);
                    break;
                case Picture::Kind::kBlobs:
                    pic.scale_m = 0.06 + 0.06 * u(5);
                    break;
            }
            pic.angle_rad = kPi * u(6);
            pic.frame_m = 0.02 + 0.03 * u(7);
            const uint64_t pic_id = static_cast<uint64_t>(wall * 64 + p);
            pic.light = randomColour(seed ^ kPictureSalt, pic_id, 1, 0.55, 0.95);
            pic.dark = randomColour(seed ^ kPictureSalt, pic_id, 2, 0.03, 0.25);
            pic.frame = randomColour(seed ^ kPictureSalt, pic_id, 3, 0.05, 0.35);
            out.push_back(pic);
            break;
        }
    }
    return out;
}

}  // namespace

SurfaceTextures::SurfaceTextures(const Scene& scene)
    : mode_(scene.texture),
      num_walls_(scene.numWalls()),
      seed_(scene.texture_seed),
      wall_colour_(scene.wall_colour),
      floor_colour_(scene.floor_colour),
      ceiling_colour_(scene.ceiling_colour),
      floor_pattern_(scene.floor_pattern) {
    noise_.resize(static_cast<size_t>(kNoiseSize) * kNoiseSize);
    for (size_t i = 0; i < noise_.size(); ++i) {
        noise_[i] = static_cast<float>(2.0 * uniform01(seed_ ^ kNoiseTableSalt, i, 0, 0) - 1.0);
    }
    floor_octaves_ = makeOctaves(floorLabel());
    ceiling_octaves_ = makeOctaves(ceilingLabel());
    for (int k = 0; k < num_walls_; ++k) {
        WallTexture w;
        w.a = scene.polygon[k];
        const Eigen::Vector2d e = scene.polygon[(k + 1) % num_walls_] - w.a;
        w.dir = e.normalized();
        w.octaves = makeOctaves(wallLabel(k));
        if (mode_ == TextureMode::kTextured) w.pictures = placePictures(scene, k, e.norm(), seed_);
        walls_.push_back(std::move(w));
    }
    for (size_t i = 0; i < scene.boxes.size(); ++i) {
        const Box& b = scene.boxes[i];
        boxes_.push_back({b.center_W, std::cos(b.yaw_rad), std::sin(b.yaw_rad), b.colour, b.pattern,
                          makeOctaves(boxLabel(scene, static_cast<int>(i)))});
    }
    for (size_t i = 0; i < scene.cylinders.size(); ++i) {
        const Cylinder& c = scene.cylinders[i];
        // An even number of checker squares around the circumference keeps the seam invisible.
        const double circumference = 2.0 * kPi * c.radius_m;
        const double squares =
            std::max(2.0, 2.0 * std::round(circumference / (2.0 * kCheckerCellM)));
        cylinders_.push_back({c.center_xy, c.radius_m, circumference / squares, c.colour, c.pattern,
                              makeOctaves(cylinderLabel(scene, static_cast<int>(i)))});
    }
}

SurfaceTextures::Octaves SurfaceTextures::makeOctaves(uint64_t salt) const {
    Octaves o{};
    for (int i = 0; i < 2 * kMaxOctaves; ++i) {
        o.offset[i] = static_cast<float>(kNoiseSize * uniform01(seed_ ^ kOctaveSalt, salt, i, 0));
    }
    return o;
}

// Bilinear value noise with smoothstep weights on the periodic lattice table, in [-1, 1].
inline float SurfaceTextures::valueNoise(float x, float y) const {
    const float fx = std::floor(x), fy = std::floor(y);
    const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
    float tx = x - fx, ty = y - fy;
    tx = tx * tx * (3.0F - 2.0F * tx);
    ty = ty * ty * (3.0F - 2.0F * ty);
    constexpr int kMask = kNoiseSize - 1;
    const int x0 = ix & kMask, x1 = (ix + 1) & kMask;
    const int y0 = (iy & kMask) * kNoiseSize, y1 = ((iy + 1) & kMask) * kNoiseSize;
    const float a = noise_[y0 + x0], b = noise_[y0 + x1];
    const float c = noise_[y1 + x0], d = noise_[y1 + x1];
    const float top = a + tx * (b - a), bottom = c + tx * (d - c);
    return top + ty * (bottom - top);
}

float SurfaceTextures::fractalNoise(double x, double y, const Octaves& oct, double cell_m,
                                    int octaves, float amplitude, float persistence,
                                    double footprint_m) const {
    float sum = 0.0F;
    double cell = cell_m;
    for (int o = 0; o < octaves; ++o) {
        // Fade: full weight while the cell spans >= 4 footprints, none below 2.
        const float weight =
            std::clamp(static_cast<float>(2.0 - 4.0 * footprint_m / cell), 0.0F, 1.0F);
        if (weight <= 0.0F) break;
        // Each octave's lattice is turned by its own angle, which hides the lattice axes.
        const double inv = 1.0 / cell;
        const double xr = kOctaveCos[o] * x - kOctaveSin[o] * y;
        const double yr = kOctaveSin[o] * x + kOctaveCos[o] * y;
        sum += weight * amplitude *
               valueNoise(static_cast<float>(xr * inv) + oct.offset[2 * o],
                          static_cast<float>(yr * inv) + oct.offset[2 * o + 1]);
        cell *= 0.5;
        amplitude *= persistence;
    }
    return sum;
}

Colour SurfaceTextures::pictureAlbedo(const Picture& pic, const Octaves& oct, double s, double z,
                                      double fp, const Colour& wall) const {
    // Box-filtered coverage of the outer (frame) and inner (pattern) rectangles.
    const double outer = filteredInterval(s, pic.s_min_m, pic.s_max_m, fp) *
                         filteredInterval(z, pic.z_min_m, pic.z_max_m, fp);
    if (outer <= 0.0) return wall;
    const double in_s0 = pic.s_min_m + pic.frame_m, in_s1 = pic.s_max_m - pic.frame_m;
    const double in_z0 = pic.z_min_m + pic.frame_m, in_z1 = pic.z_max_m - pic.frame_m;
    const double inner =
        filteredInterval(s, in_s0, in_s1, fp) * filteredInterval(z, in_z0, in_z1, fp);
    Colour pattern = pic.frame;
    if (inner > 0.0) {
        const double u = s - in_s0, v = z - in_z0;
        double t = 0.0;  // 0 = dark, 1 = light
        switch (pic.kind) {
            case Picture::Kind::kChecker:
                t = filteredChecker(u, v, pic.scale_m, fp);
                break;
            case Picture::Kind::kStripes:
                t = filteredPulse(u * std::cos(pic.angle_rad) + v * std::sin(pic.angle_rad),
                                  pic.scale_m, 0.5, fp);
                break;
            case Picture::Kind::kBlobs: {
                // Thresholded noise in wall coordinates (so no two pictures look alike); the
                // threshold's ramp widens with the footprint.
                const float n = fractalNoise(s, z, oct, pic.scale_m, 2, 1.0F, 0.5F, fp);
                const float k = 0.12F + static_cast<float>(fp / pic.scale_m);
                t = smoothStep(-k, k, n);
                break;
            }
        }
        pattern = lerp(pic.dark, pic.light, static_cast<float>(t));
    }
    // Wall outside, frame in the ring, pattern inside: weights 1 - outer, outer - inner, inner.
    return static_cast<float>(1.0 - outer) * wall + static_cast<float>(outer - inner) * pic.frame +
           static_cast<float>(inner) * pattern;
}

Colour SurfaceTextures::wallAlbedo(const WallTexture& w, const Eigen::Vector3d& p_W,
                                   double fp) const {
    const double s = (p_W.head<2>() - w.a).dot(w.dir);
    const double z = p_W.z();
    const float m = fractalNoise(s, z, w.octaves, kPlasterCellM, kMaxOctaves, kPlasterAmplitude,
                                 kPlasterPersistence, fp);
    Colour out = clampColour(wall_colour_ * std::clamp(1.0F + m, 0.3F, 1.5F));
    for (const Picture& pic : w.pictures) {
        if (s < pic.s_min_m - fp || s > pic.s_max_m + fp || z < pic.z_min_m - fp ||
            z > pic.z_max_m + fp) {
            continue;
        }
        out = pictureAlbedo(pic, w.octaves, s, z, fp, out);
    }
    return out;
}

Colour SurfaceTextures::floorAlbedo(const Eigen::Vector3d& p_W, double fp) const {
    const double x = p_W.x(), y = p_W.y();
    if (floor_pattern_ == FloorPattern::kWood) {
        // Rows of planks along x, each row shifted by a random fraction of a plank length.
        const int64_t row = static_cast<int64_t>(std::floor(y / kPlankWidthM));
        const double xs = x + kPlankLengthM * cellHash01(seed_ ^ kPlankSalt, row, -1);
        const int64_t col = static_cast<int64_t>(std::floor(xs / kPlankLengthM));
        const float tint =
            0.8F + 0.35F * static_cast<float>(cellHash01(seed_ ^ kPlankSalt, row, col));
        const float hue =
            0.08F * static_cast<float>(cellHash01(seed_ ^ kPlankSalt, col, row) - 0.5);
        // Grain: noise stretched along the plank (30 cm x 2 cm cells).
        const float grain =
            fractalNoise(xs * (0.02 / 0.30), y, floor_octaves_, 0.02, 2, 0.12F, 0.5F, fp);
        const double gap_y = filteredPulse(y, kPlankWidthM, kPlankGapM / kPlankWidthM, fp);
        const double gap_x = filteredPulse(xs, kPlankLengthM, kPlankGapM / kPlankLengthM, fp);
        const float gap = static_cast<float>(gap_x + gap_y - gap_x * gap_y);
        Colour c = floor_colour_ * (tint * (1.0F + grain));
        c.x() += hue;
        return clampColour(c * (1.0F - 0.65F * gap));
    }
    const int64_t ix = static_cast<int64_t>(std::floor(x / kTileM));
    const int64_t iy = static_cast<int64_t>(std::floor(y / kTileM));
    const float tint = 0.88F + 0.24F * static_cast<float>(cellHash01(seed_ ^ kTileSalt, ix, iy));
    const float m = fractalNoise(x, y, floor_octaves_, 0.2, 2, 0.06F, 0.7F, fp);
    const double gx = filteredPulse(x, kTileM, kGroutM / kTileM, fp);
    const double gy = filteredPulse(y, kTileM, kGroutM / kTileM, fp);
    const float grout = static_cast<float>(gx + gy - gx * gy);
    return clampColour(lerp(floor_colour_ * (tint * (1.0F + m)), 0.45F * floor_colour_, grout));
}

Colour SurfaceTextures::ceilingAlbedo(const Eigen::Vector3d& p_W, double fp) const {
    const float m = fractalNoise(p_W.x(), p_W.y(), ceiling_octaves_, kCeilingCellM, 2,
                                 kCeilingAmplitude, 0.6F, fp);
    return clampColour(ceiling_colour_ * (1.0F + m));
}

Colour SurfaceTextures::furnitureAlbedo(const Colour& colour, FurniturePattern pattern,
                                        const Octaves& oct, double u, double v,
                                        double checker_u_cell, double fp) const {
    switch (pattern) {
        case FurniturePattern::kSolid:
            return colour;
        case FurniturePattern::kNoise: {
            const float m = fractalNoise(u, v, oct, kFurnitureNoiseCellM, 3, 0.25F, 0.7F, fp);
            return clampColour(colour * (1.0F + m));
        }
        case FurniturePattern::kStripes: {
            const double t = filteredPulse(v, kStripePeriodM, 0.5, fp);
            return colour * (1.0F - 0.5F * static_cast<float>(t));
        }
        case FurniturePattern::kChecker: {
            // Scale u so that its squares measure checker_u_cell (cylinders) but pass through
            // the same filtered checker of kCheckerCellM squares.
            const double su = kCheckerCellM / checker_u_cell;
            const double t = filteredChecker(u * su, v, kCheckerCellM, fp * std::max(su, 1.0));
            return colour * (1.0F - 0.55F * static_cast<float>(t));
        }
    }
    return colour;
}

Colour SurfaceTextures::boxAlbedo(const BoxTexture& b, const Eigen::Vector3d& p_W,
                                  const Eigen::Vector3d& normal_W, double fp) const {
    const Eigen::Vector3d q = p_W - b.center;
    const Eigen::Vector3d local(b.c * q.x() + b.s * q.y(), -b.s * q.x() + b.c * q.y(), q.z());
    const double nx = std::abs(b.c * normal_W.x() + b.s * normal_W.y());
    const double ny = std::abs(-b.s * normal_W.x() + b.c * normal_W.y());
    const double nz = std::abs(normal_W.z());
    // Face coordinates: sides (horizontal, z), top and bottom (x, y).
    double u = local.x(), v = local.y();
    if (nx >= ny && nx >= nz) {
        u = local.y();
        v = local.z();
    } else if (ny >= nz) {
        v = local.z();
    }
    return furnitureAlbedo(b.colour, b.pattern, b.octaves, u, v, kCheckerCellM, fp);
}

Colour SurfaceTextures::cylinderAlbedo(const CylinderTexture& c, const Eigen::Vector3d& p_W,
                                       const Eigen::Vector3d& normal_W, double fp) const {
    const Eigen::Vector2d q = p_W.head<2>() - c.center;
    if (std::abs(normal_W.z()) > 0.5) {  // a cap
        return furnitureAlbedo(c.colour, c.pattern, c.octaves, q.x(), q.y(), kCheckerCellM, fp);
    }
    const double arc = c.radius * (std::atan2(q.y(), q.x()) + kPi);
    return furnitureAlbedo(c.colour, c.pattern, c.octaves, arc, p_W.z(), c.checker_cell, fp);
}

Colour SurfaceTextures::albedo(int label, const Eigen::Vector3d& p_W,
                               const Eigen::Vector3d& normal_W, double footprint_m) const {
    const int num_boxes = static_cast<int>(boxes_.size());
    const bool plain = mode_ == TextureMode::kPlain;
    if (label == floorLabel()) return plain ? floor_colour_ : floorAlbedo(p_W, footprint_m);
    if (label == ceilingLabel()) return plain ? ceiling_colour_ : ceilingAlbedo(p_W, footprint_m);
    if (label < 2 + num_walls_) {
        return plain ? wall_colour_ : wallAlbedo(walls_[label - 2], p_W, footprint_m);
    }
    if (label < 2 + num_walls_ + num_boxes) {
        const BoxTexture& b = boxes_[label - 2 - num_walls_];
        return plain ? b.colour : boxAlbedo(b, p_W, normal_W, footprint_m);
    }
    const CylinderTexture& c = cylinders_[label - 2 - num_walls_ - num_boxes];
    return plain ? c.colour : cylinderAlbedo(c, p_W, normal_W, footprint_m);
}

}  // namespace plumb::sim
