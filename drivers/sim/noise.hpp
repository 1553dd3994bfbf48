// SPDX-License-Identifier: Apache-2.0
#pragma once

// Depth-sensor noise (reference §1.4): the Redwood / augmented ICL-NUIM model of Choi, Zhou and
// Koltun (CVPR 2015) - pixel jitter, 2x2 sampling, low-frequency distortion (the measured table or
// a parametric substitute), 1/8-pixel disparity quantisation with disparity noise - plus missing
// data at grazing angles and depth edges, random dropout and the sensor's range limits.
//
// Randomness: every frame draws from MT19937-64 generators (Mt19937_64, the std::mt19937_64
// sequence) seeded per (seed, frame, row, pass), so a frame is a pure function of (clean depth,
// seed, frame index), whatever the thread count or the order in which frames are generated.

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "common/calibration/distortion_table.hpp"
#include "common/core/status.hpp"
#include "common/image/image.hpp"

namespace plumb::sim {

/// Low-frequency distortion applied in step A.3 (d <- d / f).
enum class DistortionKind {
    kNone,        ///< f = 1
    kTable,       ///< the measured 80x80x5 Redwood table (dist-model.txt)
    kParametric,  ///< f = 1 + k1 * clamp(z / 3, 0, 1.5) * rho(u, v) + k2 * (u - cx)/cx (§1.4.D)
};

struct NoiseConfig {
    /// false: the clean depth is returned (range limits still apply).
    bool enabled = true;
    /// Low-frequency distortion model.
    DistortionKind distortion = DistortionKind::kTable;
    /// Std of the per-axis Gaussian pixel jitter, pixels (A.1).
    double jitter_std_px = 0.25;
    /// Std of the additive disparity noise, in units of baseline_focal / z (A.4).
    double disparity_noise_std = 0.027778;
    /// Focal length times baseline, pixel*metres (A.4).
    double baseline_focal_px_m = 35.130;
    /// Disparity quantisation steps per pixel (8 = 1/8-pixel sub-pixel disparity) (A.4).
    double disparity_subpixel_steps = 8.0;
    /// Parametric distortion strength at the image corners at 3 m (D), dimensionless.
    double k1 = 0.02;
    /// Parametric distortion tilt term along x (D), dimensionless.
    double k2 = 0.0;
    /// Sensor range: depths below are dropped, metres.
    double min_depth_m = 0.4;
    /// Sensor range: depths above are dropped, metres (0 = no limit).
    double max_depth_m = 4.0;
    /// Missing data at grazing angles, depth edges and random dropout (E).
    bool missing_data = true;
    /// Grazing angle: pixels with cos(view angle) below this are always dropped.
    double grazing_cos_drop = 0.1;
    /// Grazing angle: drop probability ramps linearly from 1 at grazing_cos_drop to 0 here.
    double grazing_cos_keep = 0.3;
    /// Depth edges: drop pixels whose 3x3 depth range exceeds this fraction of their depth.
    double edge_relative_range = 0.1;
    /// Probability of dropping any valid pixel at random.
    double random_dropout = 0.005;
};

/// Finds the distortion table: `explicit_path` when non-empty, else $PLUMB_NOISE_MODEL, else the
/// compiled-in shared-data default. kNotFound explains how to point at the file.
Result<std::filesystem::path> findNoiseModelFile(const std::string& explicit_path);

/// The noise pipeline of one sensor. Immutable; apply() is thread-safe.
class DepthNoiseModel {
  public:
    /// `table` is required when config.distortion == kTable (PLUMB_CHECK).
    DepthNoiseModel(const NoiseConfig& config, std::optional<DistortionTable> table, double cx,
                    double cy);

    /// Noisy depth of frame `frame_index` from the clean depth and the per-pixel |cos| of the
    /// viewing angle (may be empty: no grazing-angle dropout). Steps (reference §1.4):
    /// E (edge, grazing, random dropout on the clean image), A.1 jitter, A.2 2x2 sampling,
    /// A.3 distortion, A.4 disparity quantisation + noise, E range gating.
    DepthImage apply(const DepthImage& clean, const Image<float>& cos_view, uint64_t seed,
                     uint64_t frame_index) const;
    /// The same into `out` (resized as needed; a buffer of the right size is reused, which avoids
    /// first-touching fresh pages every frame). `out` must not alias `clean` or `cos_view`.
    void apply(const DepthImage& clean, const Image<float>& cos_view, uint64_t seed,
               uint64_t frame_index, DepthImage* out) const;

    const NoiseConfig& config() const { return config_; }

  private:
    // Pass 1 (§1.4.E) for the even row v: the clean depth with missing data set to 0 at the even
    // columns u, stored at row[u / 2]. Draws the row's whole random stream.
    void maskRow(const DepthImage& clean, const Image<float>& cos_view, uint64_t seed,
                 uint64_t frame_index, int v, float* row) const;

    NoiseConfig config_;
    std::optional<DistortionTable> table_;
    double cx_, cy_;
};

/// A standard normal sample from 32 random bits by a 4096-bin inverse-CDF table with linear
/// interpolation (tails truncated at 3.7 sigma; variance within 0.5 % of 1). Deterministic.
float standardNormalFromBits(uint32_t bits);

/// The kNormalTableBins + 1 entries behind standardNormalFromBits, for loops that draw many
/// samples: with b = bits >> 20 and f = (bits & 0xFFFFF) / 2^20 the sample is
/// t[b] + f (t[b + 1] - t[b]). Built on first use; thread-safe.
constexpr int kNormalTableBins = 4096;
const float* standardNormalTable();

/// MT19937-64: the exact output sequence of std::mt19937_64 (same seeding, same tempering), with
/// the state regenerated in blocks by loops the compiler vectorises and tempered in bulk. The
/// noise draws ~2 values per pixel and reseeds per row, so this generator is on the hot path.
class Mt19937_64 {
  public:
    explicit Mt19937_64(uint64_t seed);
    uint64_t operator()() {
        if (next_ == kN) refill();
        return out_[next_++];
    }

  private:
    static constexpr int kN = 312;
    void refill();  // twist the state, temper it into out_
    std::array<uint64_t, kN> state_;
    std::array<uint64_t, kN> out_;
    int next_ = kN;
};

/// splitmix64 finaliser: a well-mixed 64-bit hash used to derive per-frame and per-row seeds.
uint64_t mixSeed(uint64_t x);

}  // namespace plumb::sim
