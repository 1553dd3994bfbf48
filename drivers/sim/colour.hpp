// SPDX-License-Identifier: Apache-2.0
#pragma once

// The simulated colour camera (reference §7b): the renderer's clean, shaded colour image times a
// per-frame exposure gain, plus per-pixel Gaussian noise on each channel, rounded and clamped to
// 8 bits. The response is linear (no gamma), so a gain g scales every unclipped value by g.
//
// Randomness: the noise of pixel i in frame k is a hash of (seed, k, i) and the exposure drift a
// hash of (seed, lattice frame), on streams of their own: the colour draws nothing from the
// depth noise's generators, and a frame is a pure function of (clean image, config, seed, k),
// whatever the thread count or the order of the frames.

#include <cstdint>
#include <vector>

#include "common/core/status.hpp"
#include "common/image/image.hpp"

namespace plumb::sim {

/// A sudden exposure change: from frame `frame` on, the gain is multiplied by `factor`.
struct ExposureJump {
    uint64_t frame = 0;   ///< first frame with the new exposure
    double factor = 1.0;  ///< gain multiplier, > 0 (e.g. 0.6: 40 % darker)
};

struct ColourConfig {
    /// false: no colour image (Frame::colour stays empty and the renderer skips the textures).
    bool enabled = true;
    /// Std of the additive Gaussian noise on each channel, 8-bit levels (2 = 2/255 of full
    /// scale); 0 = none.
    double noise_std_levels = 2.0;
    /// Std of ln(gain) of a smooth random exposure drift (auto-exposure wander); 0 = constant
    /// exposure (default). 0.1 is about +-10 %.
    double exposure_log_std = 0.0;
    /// Correlation length of the drift, frames: independent values this many frames apart,
    /// smoothly interpolated in between.
    double exposure_period_frames = 90.0;
    /// Sudden exposure changes (cumulative, any order); none by default.
    std::vector<ExposureJump> exposure_jumps;
};

/// Exposure gain of frame `frame_index`: exp(exposure_log_std * z_k) times the factors of every
/// jump at or before the frame, where z_k is a standard normal at every frame (unit variance at
/// every k, not only at the lattice frames) that varies smoothly over exposure_period_frames.
double exposureGain(const ColourConfig& config, uint64_t seed, uint64_t frame_index);

/// The colour camera's noise and exposure. Immutable; apply() is thread-safe.
class ColourNoiseModel {
  public:
    /// `config` must pass validateColourConfig (PLUMB_CHECK).
    explicit ColourNoiseModel(const ColourConfig& config);

    /// The camera's image of frame `frame_index`, per channel
    ///   out = clamp(round(gain * clean) + round(noise_std_levels * z), 0, 255),
    /// gain = exposureGain(), z a standard normal drawn from 12 bits of a hash of (seed, frame,
    /// pixel) by its quantiles (4096 equally likely values, tails at 3.5 sigma). `out` is resized
    /// as needed (a buffer of the right size is reused) and must not alias `clean`. TBB over
    /// rows; the result does not depend on the thread count.
    void apply(const ColourImage& clean, uint64_t seed, uint64_t frame_index,
               ColourImage* out) const;

    double gain(uint64_t seed, uint64_t frame_index) const {
        return exposureGain(config_, seed, frame_index);
    }
    const ColourConfig& config() const { return config_; }

  private:
    static constexpr int kQuantiles = 4096;
    ColourConfig config_;
    std::vector<int16_t> noise_levels_;  // round(noise_std_levels * z_j), j < kQuantiles
};

/// Checks a colour configuration: noise in [0, 255] levels, a finite non-negative drift, a
/// positive period, positive finite jump factors. Errors name the field.
Status validateColourConfig(const ColourConfig& config);

}  // namespace plumb::sim
