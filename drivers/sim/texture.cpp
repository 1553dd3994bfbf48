// SPDX-License-Identifier: Apache-2.0
#include "drivers/sim/texture.hpp"

#include <algorithm>
#include <cmath>

namespace plumb::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Salts that keep the texture's random streams apart from each other.
constexpr uint64_t kNoiseTableSalt = 0x7e57a11ce0ULL;
constexpr uint64_t kOctaveSalt = 0x0c7a7e5ULL;
constexpr uint64_t kPictureSalt = 0x91c70e7eULL;
constexpr uint64_t kPlankSalt = 0x91a4cULL;
constexpr uint64_t kTileSalt = 0x7113ULL;
// Noise of the floor (grain or mottling), ceiling and pictures: salts beyond every label.
constexpr uint64_t kCeilingNoiseSalt = 1ULL << 40;
constexpr uint64_t kFloorNoiseSalt = 2ULL << 40;
constexpr uint64_t kBlobSalt = 3ULL << 40;

// Wall plaster: 4 octaves from 24 cm down to 3 cm, amplitudes 0.22 * 0.85^o.
constexpr double kPlasterCellM = 0.24;
constexpr float kPlasterAmplitude = 0.22F;
constexpr float kPlasterPersistence = 0.85F;
// The plaster is precomputed on a grid of 1 cm (a third of its finest cell) and mip-mapped.
constexpr double kPlasterTexelM = 0.01;
// Ceiling: faint, 2 octaves from 40 cm.
constexpr double kCeilingCellM = 0.40;
constexpr float kCeilingAmplitude = 0.05F;
// Floor planks (grain: cells 30 cm along the plank, 2 cm across) and tiles.
constexpr double kPlankWidthM = 0.14;
constexpr double kPlankLengthM = 1.2;
constexpr double kPlankGapM = 0.005;
constexpr double kGrainCellM = 0.02;
constexpr double kGrainStretch = 15.0;
constexpr double kTileM = 0.40;
constexpr double kGroutM = 0.008;
// Furniture patterns.
constexpr double kFurnitureNoiseCellM = 0.12;
constexpr double kStripePeriodM = 0.10;
constexpr double kCheckerCellM = 0.08;
// Picture placement: clearance to the wall ends, between pictures and to openings, metres.
constexpr double kPictureEndClearanceM = 0.2;
constexpr double kPictureGapM = 0.15;
constexpr double kOpeningClearanceM = 0.05;
constexpr int kPlacementAttempts = 40;

// splitmix64's finaliser (drivers/sim/noise.hpp mixSeed), inline for per-pixel hashes.
inline uint64_t hash64(uint64_t x) {
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}

inline double toUnit(uint64_t h) {
    return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

// A uniform number in [0, 1) from a hash of (seed, a, b, c).
double uniform01(uint64_t seed, uint64_t a, uint64_t b, uint64_t c) {
    return toUnit(hash64(hash64(hash64(hash64(seed) ^ a) ^ b) ^ c));
}

// Integer lattice hash of a cell (i, j) to [0, 1).
inline double cellHash01(uint64_t salt, int64_t i, int64_t j) {
    return toUnit(hash64(salt ^ hash64(static_cast<uint64_t>(i) * 0x9E3779B97F4A7C15ULL ^
                                       static_cast<uint64_t>(j))));
}

float smoothStep(float edge0, float edge1, float x) {
    const float t = std::clamp((x - edge0) / (edge1 - edge0), 0.0F, 1.0F);
    return t * t * (3.0F - 2.0F * t);
}

Colour lerp(const Colour& a, const Colour& b, float t) { return a + t * (b - a); }

float clamp01(float x) { return std::min(std::max(x, 0.0F), 1.0F); }

Colour clampColour(const Colour& c) { return {clamp01(c.x()), clamp01(c.y()), clamp01(c.z())}; }

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
            const double w = 0.4 + 0.6 * u(0);
            const double h = 0.3 + 0.5 * u(1);
            const double free_length = length_m - 2.0 * kPictureEndClearanceM - w;
            const double z_lo = 0.6, z_hi = height - 0.25;  // frame bottom and top limits
            if (free_length <= 0.0 || z_hi - z_lo < h) continue;
            Picture pic;
            pic.s_min_m = kPictureEndClearanceM + free_length * u(2);
            pic.s_max_m = pic.s_min_m + w;
            const double z_centre = std::clamp(1.1 + 0.7 * u(3), z_lo + 0.5 * h, z_hi - 0.5 * h);
            pic.z_min_m = z_centre - 0.5 * h;
            pic.z_max_m = z_centre + 0.5 * h;
            auto apart = [](double lo0, double hi0, double lo1, double hi1, double gap) {
                return hi0 + gap < lo1 || hi1 + gap < lo0;
            };
            bool clear = true;
            for (const Picture& q : out) {
                clear &= apart(pic.s_min_m, pic.s_max_m, q.s_min_m, q.s_max_m, kPictureGapM) ||
                         apart(pic.z_min_m, pic.z_max_m, q.z_min_m, q.z_max_m, kPictureGapM);
            }
            for (const Opening& o : scene.openings) {
                if (o.wall != wall) continue;
                clear &= apart(pic.s_min_m, pic.s_max_m, o.offset_m, o.offset_m + o.width_m,
                               kOpeningClearanceM) ||
                         apart(pic.z_min_m, pic.z_max_m, o.z_min_m, o.z_max_m, kOpeningClearanceM);
            }
            if (!clear) continue;
            pic.kind = static_cast<Picture::Kind>(std::min(2, static_cast<int>(3.0 * u(4))));
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
            const double angle = kPi * u(6);
            pic.stripe_normal = {std::cos(angle), std::sin(angle)};
            pic.frame_m = 0.02 + 0.03 * u(7);
            const uint64_t pic_id = static_cast<uint64_t>(wall) * 64 + static_cast<uint64_t>(p);
            pic.light = randomColour(seed ^ kPictureSalt, pic_id, 1, 0.55, 0.95);
            pic.dark = randomColour(seed ^ kPictureSalt, pic_id, 2, 0.03, 0.25);
            pic.frame = randomColour(seed ^ kPictureSalt, pic_id, 3, 0.05, 0.35);
            out.push_back(pic);
            break;
        }
    }
    return out;
}

// ---- filters -----------------------------------------------------------------------------------
// Each returns the mean of a pattern over a window of the footprint's width w centred on x (a box
// filter), exactly: stripes and edges narrower than a pixel turn to their average instead of
// aliasing.

// Integral of the pulse indicator from 0 to t.
inline double pulseIntegral(double t, double period, double inv_period, double on) {
    const double n = std::floor(t * inv_period);
    return n * on + std::min(t - n * period, on);
}

// Fraction of [x - w/2, x + w/2] inside [lo, hi].
inline double filteredInterval(double x, double lo, double hi, double w, double inv_w) {
    const double overlap = std::min(hi, x + 0.5 * w) - std::max(lo, x - 0.5 * w);
    return std::clamp(overlap * inv_w, 0.0, 1.0);
}

// Box-filtered 1[frac(x / period) < on / period]; inv_* are the reciprocals (no division here).
inline double filteredPulse(double x, double period, double inv_period, double on, double w,
                            double inv_w) {
    return (pulseIntegral(x + 0.5 * w, period, inv_period, on) -
            pulseIntegral(x - 0.5 * w, period, inv_period, on)) *
           inv_w;
}

// Box-filtered checkerboard of squares `cell` in [0, 1]: the XOR of two pulse trains is bilinear
// in them, so filtering each axis gives the exactly filtered checker.
inline double filteredChecker(double u, double v, double cell, double inv_cell, double w,
                              double inv_w) {
    const double a = filteredPulse(u, 2.0 * cell, 0.5 * inv_cell, cell, w, inv_w);
    const double b = filteredPulse(v, 2.0 * cell, 0.5 * inv_cell, cell, w, inv_w);
    return a + b - 2.0 * a * b;
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
    plank_grain_ = makeNoise(kFloorNoiseSalt, kGrainCellM, 2, 0.12F, 0.5F, false, kGrainStretch);
    tile_mottle_ = makeNoise(kFloorNoiseSalt, 0.2, 2, 0.06F, 0.7F);
    ceiling_noise_ = makeNoise(kCeilingNoiseSalt, kCeilingCellM, 2, kCeilingAmplitude, 0.6F);
    for (int k = 0; k < num_walls_; ++k) {
        WallTexture w;
        w.a = scene.polygon[k];
        const Eigen::Vector2d e = scene.polygon[(k + 1) % num_walls_] - w.a;
        w.dir = e.normalized();
        w.plaster = makeMipMap(
            makeNoise(wallLabel(k), kPlasterCellM, 4, kPlasterAmplitude, kPlasterPersistence),
            e.norm(), scene.height_m, kPlasterTexelM);
        if (mode_ == TextureMode::kTextured) w.pictures = placePictures(scene, k, e.norm(), seed_);
        std::sort(w.pictures.begin(), w.pictures.end(),
                  [](const Picture& a, const Picture& b) { return a.s_min_m < b.s_min_m; });
        for (size_t p = 0; p < w.pictures.size(); ++p) {
            w.blobs.push_back(makeNoise(kBlobSalt + static_cast<uint64_t>(k) * 64 + p,
                                        w.pictures[p].scale_m, 2, 1.0F, 0.5F));
        }
        walls_.push_back(std::move(w));
    }
    for (size_t i = 0; i < scene.boxes.size(); ++i) {
        const Box& b = scene.boxes[i];
        boxes_.push_back({b.center_W, std::cos(b.yaw_rad), std::sin(b.yaw_rad), b.colour, b.pattern,
                          makeNoise(boxLabel(scene, static_cast<int>(i)), kFurnitureNoiseCellM, 3,
                                    0.25F, 0.7F)});
    }
    for (size_t i = 0; i < scene.cylinders.size(); ++i) {
        const Cylinder& c = scene.cylinders[i];
        // An even number of checker squares around the circumference keeps the seam invisible.
        const double circumference = 2.0 * kPi * c.radius_m;
        const double squares =
            std::max(2.0, 2.0 * std::round(circumference / (2.0 * kCheckerCellM)));
        cylinders_.push_back({c.center_xy, c.radius_m, circumference / squares, c.colour, c.pattern,
                              makeNoise(cylinderLabel(scene, static_cast<int>(i)),
                                        kFurnitureNoiseCellM, 3, 0.25F, 0.7F)});
    }
}

SurfaceTextures::FractalNoise SurfaceTextures::makeNoise(uint64_t salt, double cell_m, int octaves,
                                                         float amplitude, float persistence,
                                                         bool rotate, double stretch_x) const {
    FractalNoise n;
    n.octaves = std::clamp(octaves, 0, 4);
    n.amplitude.setZero();
    n.inv_cell.setZero();
    n.m00.setZero();
    n.m01.setZero();
    n.m10.setZero();
    n.m11.setZero();
    double cell = cell_m;
    float amp = amplitude;
    for (int o = 0; o < 4; ++o) {
        // Lattice angle of octave o: 0.5 + 1.2 o rad (none for stretched, oriented noise).
        const double angle = rotate ? 0.5 + 1.2 * o : 0.0;
        const double c = std::cos(angle) / cell, s = std::sin(angle) / cell;
        const double sx = 1.0 / stretch_x;
        n.m00[o] = static_cast<float>(c * sx);
        n.m01[o] = static_cast<float>(-s);
        n.m10[o] = static_cast<float>(s * sx);
        n.m11[o] = static_cast<float>(c);
        n.ox[o] = static_cast<float>(kNoiseSize * uniform01(seed_ ^ kOctaveSalt, salt, 2 * o, 0));
        n.oy[o] =
            static_cast<float>(kNoiseSize * uniform01(seed_ ^ kOctaveSalt, salt, 2 * o + 1, 0));
        if (o < octaves) {
            n.inv_cell[o] = static_cast<float>(1.0 / cell);
            n.amplitude[o] = amp;
        }
        cell *= 0.5;
        amp *= persistence;
    }
    return n;
}

// Bilinear value noise with smoothstep weights on the periodic lattice table, one octave per
// lane, faded by the footprint and summed.
inline float SurfaceTextures::noise(const FractalNoise& n, double x, double y, double fp) const {
    const float xf = static_cast<float>(x), yf = static_cast<float>(y);
    const Eigen::Array4f gx = n.m00 * xf + n.m01 * yf + n.ox;
    const Eigen::Array4f gy = n.m10 * xf + n.m11 * yf + n.oy;
    const Eigen::Array4f fx = gx.floor(), fy = gy.floor();
    Eigen::Array4f tx = gx - fx, ty = gy - fy;
    tx = tx * tx * (3.0F - 2.0F * tx);
    ty = ty * ty * (3.0F - 2.0F * ty);
    const Eigen::Array4i ix = fx.cast<int>(), iy = fy.cast<int>();
    constexpr int kMask = kNoiseSize - 1;
    Eigen::Array4f a = Eigen::Array4f::Zero(), b = a, c = a, d = a;
    for (int o = 0; o < n.octaves; ++o) {
        const int x0 = ix[o] & kMask, x1 = (ix[o] + 1) & kMask;
        const int y0 = (iy[o] & kMask) * kNoiseSize, y1 = ((iy[o] + 1) & kMask) * kNoiseSize;
        a[o] = noise_[y0 + x0];
        b[o] = noise_[y0 + x1];
        c[o] = noise_[y1 + x0];
        d[o] = noise_[y1 + x1];
    }
    const Eigen::Array4f top = a + tx * (b - a), bottom = c + tx * (d - c);
    const Eigen::Array4f value = top + ty * (bottom - top);
    // Fade: full weight while the cell spans >= 4 footprints, none below 2.
    const Eigen::Array4f weight =
        (2.0F - (4.0F * static_cast<float>(fp)) * n.inv_cell).max(0.0F).min(1.0F);
    return (weight * n.amplitude * value).sum();
}

SurfaceTextures::MipMap SurfaceTextures::makeMipMap(const FractalNoise& n, double width_m,
                                                    double height_m, double texel_m) const {
    MipMap map;
    map.inv_texel_m = 1.0 / texel_m;
    auto add_level = [&map](std::vector<float> texels, int w, int h, double texel) {
        const float w_max = static_cast<float>(w) - 1.0001F,
                    h_max = static_cast<float>(h) - 1.0001F;
        map.levels.push_back(
            {std::move(texels), w, h, static_cast<float>(1.0 / texel), w_max, h_max});
    };
    int w = std::max(2, static_cast<int>(std::ceil(width_m / texel_m)));
    int h = std::max(2, static_cast<int>(std::ceil(height_m / texel_m)));
    std::vector<float> base(static_cast<size_t>(w) * h);
    for (int j = 0; j < h; ++j) {
        for (int i = 0; i < w; ++i) {
            base[static_cast<size_t>(j) * w + i] =
                noise(n, (i + 0.5) * texel_m, (j + 0.5) * texel_m, 0.0);
        }
    }
    add_level(std::move(base), w, h, texel_m);
    // Each level averages 2x2 texels of the one below (a lone last row or column averages less);
    // every level keeps at least 2x2 texels (the bilinear read needs a neighbour).
    while (w >= 4 && h >= 4) {
        const std::vector<float>& fine = map.levels.back().texels;
        const int fw = w, fh = h;
        w = (w + 1) / 2;
        h = (h + 1) / 2;
        std::vector<float> coarse(static_cast<size_t>(w) * h);
        for (int j = 0; j < h; ++j) {
            for (int i = 0; i < w; ++i) {
                float sum = 0.0F;
                int count = 0;
                for (int dj = 0; dj < 2; ++dj) {
                    for (int di = 0; di < 2; ++di) {
                        const int fi = 2 * i + di, fj = 2 * j + dj;
                        if (fi >= fw || fj >= fh) continue;
                        sum += fine[static_cast<size_t>(fj) * fw + fi];
                        ++count;
                    }
                }
                coarse[static_cast<size_t>(j) * w + i] = sum / static_cast<float>(count);
            }
        }
        texel_m *= 2.0;
        add_level(std::move(coarse), w, h, texel_m);
    }
    return map;
}

inline float SurfaceTextures::sampleLevel(const MipLevel& l, double x, double y) {
    // Texel centres at (i + 1/2) texels; outside the centres the edge texels extend (clamped
    // just below the last centre so that texel i0 + 1 exists).
    const float tx =
        std::min(std::max(static_cast<float>(x) * l.texels_per_m - 0.5F, 0.0F), l.max_x);
    const float ty =
        std::min(std::max(static_cast<float>(y) * l.texels_per_m - 0.5F, 0.0F), l.max_y);
    const int i0 = static_cast<int>(tx), j0 = static_cast<int>(ty);
    const float ax = tx - static_cast<float>(i0), ay = ty - static_cast<float>(j0);
    const float* row0 = l.texels.data() + static_cast<size_t>(j0) * l.width + i0;
    const float* row1 = row0 + l.width;
    const float top = row0[0] + ax * (row0[1] - row0[0]);
    const float bottom = row1[0] + ax * (row1[1] - row1[0]);
    return top + ay * (bottom - top);
}

float SurfaceTextures::sampleMipMap(const MipMap& map, double x, double y, double fp) {
    // Level l serves footprints of 2^l to 2^(l+1) texels, blended linearly towards level l + 1.
    double ratio = fp * map.inv_texel_m;
    if (ratio <= 1.0) return sampleLevel(map.levels[0], x, y);
    const size_t last = map.levels.size() - 1;
    size_t level = 0;
    while (ratio >= 2.0 && level < last) {
        ratio *= 0.5;
        ++level;
    }
    if (level == last) return sampleLevel(map.levels[last], x, y);
    const float blend = static_cast<float>(std::min(ratio - 1.0, 1.0));
    const float a = sampleLevel(map.levels[level], x, y);
    return a + blend * (sampleLevel(map.levels[level + 1], x, y) - a);
}

Colour SurfaceTextures::pictureAlbedo(const Picture& pic, const FractalNoise& blobs, double s,
                                      double z, double fp, const Colour& wall) const {
    // Box-filtered coverage of the outer (frame) and inner (pattern) rectangles.
    const double inv_fp = 1.0 / fp;
    const double outer = filteredInterval(s, pic.s_min_m, pic.s_max_m, fp, inv_fp) *
                         filteredInterval(z, pic.z_min_m, pic.z_max_m, fp, inv_fp);
    if (outer <= 0.0) return wall;
    const double in_s0 = pic.s_min_m + pic.frame_m, in_s1 = pic.s_max_m - pic.frame_m;
    const double in_z0 = pic.z_min_m + pic.frame_m, in_z1 = pic.z_max_m - pic.frame_m;
    const double inner = filteredInterval(s, in_s0, in_s1, fp, inv_fp) *
                         filteredInterval(z, in_z0, in_z1, fp, inv_fp);
    Colour pattern = pic.frame;
    if (inner > 0.0) {
        const double u = s - in_s0, v = z - in_z0;
        double t = 0.0;  // 0 = dark, 1 = light
        switch (pic.kind) {
            case Picture::Kind::kChecker:
                t = filteredChecker(u, v, pic.scale_m, 1.0 / pic.scale_m, fp, inv_fp);
                break;
            case Picture::Kind::kStripes:
                t = filteredPulse(u * pic.stripe_normal.x() + v * pic.stripe_normal.y(),
                                  pic.scale_m, 1.0 / pic.scale_m, 0.5 * pic.scale_m, fp, inv_fp);
                break;
            case Picture::Kind::kBlobs: {
                // Thresholded noise; the threshold's ramp widens with the footprint.
                const float n = noise(blobs, u, v, fp);
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
    const float m = sampleMipMap(w.plaster, s, z, fp);
    Colour out = clampColour(wall_colour_ * std::min(std::max(1.0F + m, 0.3F), 1.5F));
    for (size_t i = 0; i < w.pictures.size(); ++i) {
        const Picture& pic = w.pictures[i];
        if (s < pic.s_min_m - fp) break;  // sorted by s_min_m
        if (s > pic.s_max_m + fp || z < pic.z_min_m - fp || z > pic.z_max_m + fp) continue;
        out = pictureAlbedo(pic, w.blobs[i], s, z, fp, out);
    }
    return out;
}

Colour SurfaceTextures::floorAlbedo(const Eigen::Vector3d& p_W, double fp) const {
    const double x = p_W.x(), y = p_W.y();
    if (floor_pattern_ == FloorPattern::kWood) {
        // Rows of planks along x, each row shifted by a random fraction of a plank length.
        const double row_f = std::floor(y * (1.0 / kPlankWidthM));
        const int64_t row = static_cast<int64_t>(row_f);
        const double xs = x + kPlankLengthM * cellHash01(seed_ ^ kPlankSalt, row, -1);
        const int64_t col = static_cast<int64_t>(std::floor(xs * (1.0 / kPlankLengthM)));
        // One hash per plank: its tint from the high bits, a shift towards red from the low.
        const uint64_t h = hash64(seed_ ^ kPlankSalt ^
                                  hash64(static_cast<uint64_t>(row) * 0x9E3779B97F4A7C15ULL ^
                                         static_cast<uint64_t>(col)));
        const float tint = 0.8F + 0.35F * static_cast<float>(toUnit(h));
        const float red_shift = 0.08F * (static_cast<float>(h & 0xFFFFU) / 65536.0F - 0.5F);
        const float grain = noise(plank_grain_, xs, y, fp);
        const double inv_fp = 1.0 / fp;
        const double gap_y =
            filteredPulse(y, kPlankWidthM, 1.0 / kPlankWidthM, kPlankGapM, fp, inv_fp);
        const double gap_x =
            filteredPulse(xs, kPlankLengthM, 1.0 / kPlankLengthM, kPlankGapM, fp, inv_fp);
        const float gap = static_cast<float>(gap_x + gap_y - gap_x * gap_y);
        Colour c = floor_colour_ * (tint * (1.0F + grain));
        c.x() += red_shift;
        return clampColour(c * (1.0F - 0.65F * gap));
    }
    const int64_t ix = static_cast<int64_t>(std::floor(x * (1.0 / kTileM)));
    const int64_t iy = static_cast<int64_t>(std::floor(y * (1.0 / kTileM)));
    const float tint = 0.88F + 0.24F * static_cast<float>(cellHash01(seed_ ^ kTileSalt, ix, iy));
    const float m = noise(tile_mottle_, x, y, fp);
    const double inv_fp = 1.0 / fp;
    const double gx = filteredPulse(x, kTileM, 1.0 / kTileM, kGroutM, fp, inv_fp);
    const double gy = filteredPulse(y, kTileM, 1.0 / kTileM, kGroutM, fp, inv_fp);
    const float grout = static_cast<float>(gx + gy - gx * gy);
    return clampColour(lerp(floor_colour_ * (tint * (1.0F + m)), 0.45F * floor_colour_, grout));
}

Colour SurfaceTextures::ceilingAlbedo(const Eigen::Vector3d& p_W, double fp) const {
    return clampColour(ceiling_colour_ * (1.0F + noise(ceiling_noise_, p_W.x(), p_W.y(), fp)));
}

Colour SurfaceTextures::furnitureAlbedo(const Colour& colour, FurniturePattern pattern,
                                        const FractalNoise& n, double u, double v,
                                        double checker_u_cell, double fp) const {
    switch (pattern) {
        case FurniturePattern::kSolid:
            return colour;
        case FurniturePattern::kNoise:
            return clampColour(colour * (1.0F + noise(n, u, v, fp)));
        case FurniturePattern::kStripes: {
            const double t = filteredPulse(v, kStripePeriodM, 1.0 / kStripePeriodM,
                                           0.5 * kStripePeriodM, fp, 1.0 / fp);
            return colour * (1.0F - 0.5F * static_cast<float>(t));
        }
        case FurniturePattern::kChecker: {
            // u scaled so that its squares measure checker_u_cell (cylinders) in the filtered
            // checker of kCheckerCellM squares; the footprint grows by the same factor.
            const double su = kCheckerCellM / checker_u_cell;
            const double w = fp * std::max(su, 1.0);
            const double t =
                filteredChecker(u * su, v, kCheckerCellM, 1.0 / kCheckerCellM, w, 1.0 / w);
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
    return furnitureAlbedo(b.colour, b.pattern, b.noise, u, v, kCheckerCellM, fp);
}

Colour SurfaceTextures::cylinderAlbedo(const CylinderTexture& c, const Eigen::Vector3d& p_W,
                                       const Eigen::Vector3d& normal_W, double fp) const {
    const Eigen::Vector2d q = p_W.head<2>() - c.center;
    if (std::abs(normal_W.z()) > 0.5) {  // a cap
        return furnitureAlbedo(c.colour, c.pattern, c.noise, q.x(), q.y(), kCheckerCellM, fp);
    }
    const double arc = c.radius * (std::atan2(q.y(), q.x()) + kPi);
    return furnitureAlbedo(c.colour, c.pattern, c.noise, arc, p_W.z(), c.checker_cell, fp);
}

}  // namespace plumb::sim
