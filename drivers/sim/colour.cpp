// SPDX-License-Identifier: Apache-2.0
#include "drivers/sim/colour.hpp"

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "drivers/sim/noise.hpp"

namespace plumb::sim {
namespace {

// Salts of the colour streams (the depth noise seeds its rows from mixSeed(seed) directly).
constexpr uint64_t kPixelNoiseSalt = 0xc0105e7a9e5ULL;
constexpr uint64_t kExposureSalt = 0xe7905e9a17ULL;
constexpr uint64_t kGolden = 0x9E3779B97F4A7C15ULL;
constexpr int kRowsPerTask = 16;

// mixSeed (splitmix64's finaliser), inline for the per-pixel loop.
inline uint64_t mix64(uint64_t x) {
    x += kGolden;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}

// Standard normal of drift lattice frame j.
double latticeNormal(uint64_t seed, int64_t j) {
    const uint64_t h = mixSeed(mixSeed(seed ^ kExposureSalt) ^ static_cast<uint64_t>(j));
    return standardNormalFromBits(static_cast<uint32_t>(h >> 32));
}

}  // namespace

Status validateColourConfig(const ColourConfig& c) {
    if (!(c.noise_std_levels >= 0.0 && c.noise_std_levels <= 255.0)) {
        return invalidArgument(
            fmt::format("colour noise_std_levels must be in [0, 255], got {}", c.noise_std_levels));
    }
    if (!(c.exposure_log_std >= 0.0) || !std::isfinite(c.exposure_log_std)) {
        return invalidArgument(fmt::format(
            "colour exposure_log_std must be finite and >= 0, got {}", c.exposure_log_std));
    }
    if (!(c.exposure_period_frames > 0.0) || !std::isfinite(c.exposure_period_frames)) {
        return invalidArgument(fmt::format("colour exposure_period_frames must be > 0, got {}",
                                           c.exposure_period_frames));
    }
    for (const ExposureJump& j : c.exposure_jumps) {
        if (!(j.factor > 0.0) || !std::isfinite(j.factor)) {
            return invalidArgument(fmt::format(
                "colour exposure jump at frame {}: factor must be finite and > 0, got {}", j.frame,
                j.factor));
        }
    }
    return Status::ok();
}

double exposureGain(const ColourConfig& config, uint64_t seed, uint64_t frame_index) {
    double gain = 1.0;
    if (config.exposure_log_std > 0.0) {
        // Smoothstep blend of the two neighbouring lattice normals, renormalised to unit variance:
        // Var((1 - s) z0 + s z1) = (1 - s)^2 + s^2 for independent z0, z1.
        const double x = static_cast<double>(frame_index) / config.exposure_period_frames;
        const double j = std::floor(x);
        const double t = x - j;
        const double s = t * t * (3.0 - 2.0 * t);
        const int64_t j0 = static_cast<int64_t>(j);
        const double z = ((1.0 - s) * latticeNormal(seed, j0) + s * latticeNormal(seed, j0 + 1)) /
                         std::sqrt((1.0 - s) * (1.0 - s) + s * s);
        gain = std::exp(config.exposure_log_std * z);
    }
    for (const ExposureJump& jump : config.exposure_jumps) {
        if (frame_index >= jump.frame) gain *= jump.factor;
    }
    return gain;
}

ColourNoiseModel::ColourNoiseModel(const ColourConfig& config) : config_(config) {
    const Status valid = validateColourConfig(config);
    PLUMB_CHECK(valid.isOk()) << valid.message();
    // Quantile j of N(0, 1) at probability (j + 1/2) / kQuantiles, from the shared table.
    noise_levels_.resize(kQuantiles);
    for (int j = 0; j < kQuantiles; ++j) {
        const uint32_t bits = (static_cast<uint32_t>(j) << 20) | 0x80000U;
        noise_levels_[j] = static_cast<int16_t>(
            std::lround(config.noise_std_levels * standardNormalFromBits(bits)));
    }
}

void ColourNoiseModel::apply(const ColourImage& clean, uint64_t seed, uint64_t frame_index,
                             ColourImage* out) const {
    PLUMB_CHECK(out != &clean) << "ColourNoiseModel::apply: out aliases the clean image";
    const int w = clean.width();
    const int h = clean.height();
    if (out->width() != w || out->height() != h || out->size() != clean.size()) {
        *out = ColourImage(w, h);
    }
    const double exposure = gain(seed, frame_index);
    if (config_.noise_std_levels == 0.0 && exposure == 1.0) {
        std::copy(clean.pixels().begin(), clean.pixels().end(), out->pixels().begin());
        return;
    }
    // round(gain * c) for every 8-bit level c (clamped later, with the noise added).
    std::array<int16_t, 256> exposed;
    for (int c = 0; c < 256; ++c) {
        exposed[c] = static_cast<int16_t>(std::min(4096L, std::lround(exposure * c)));
    }
    const uint64_t frame_key = mixSeed(mixSeed(seed ^ kPixelNoiseSalt) ^ frame_index);
    const int16_t* noise = noise_levels_.data();
    auto level = [](int x) { return static_cast<uint8_t>(std::clamp(x, 0, 255)); };
    tbb::parallel_for(tbb::blocked_range<int>(0, h, kRowsPerTask),
                      [&](const tbb::blocked_range<int>& rows) {
                          for (int v = rows.begin(); v < rows.end(); ++v) {
                              const Rgb8* in = &clean(0, v);
                              Rgb8* o = &(*out)(0, v);
                              uint64_t i = static_cast<uint64_t>(v) * w;
                              for (int u = 0; u < w; ++u, ++i) {
                                  // 12 bits of pixel i's hash per channel.
                                  const uint64_t bits = mix64(frame_key + i * kGolden);
                                  o[u].r = level(exposed[in[u].r] + noise[bits & 0xFFFU]);
                                  o[u].g = level(exposed[in[u].g] + noise[(bits >> 12) & 0xFFFU]);
                                  o[u].b = level(exposed[in[u].b] + noise[(bits >> 24) & 0xFFFU]);
                              }
                          }
                      });
}

}  // namespace plumb::sim
