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

#include <algorithm>
#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

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

/// The measured Redwood distortion table: 80x80 image cells (8x6 px at 640x480) x 5 depth bins
/// centred at 1, 3, 5, 7, 9 m of multiplicative factors (reference §1.4.A).
class DistortionTable {
  public:
    /// Parses the dist-model.txt format: 5 header lines, then one number per line, '%' starts a
    /// comment; 23 numbers per cell (y-major), factors at offset 15, a cell is zero (invalid) if
    /// all of its 5 counts at offset 3 are below 8000. `source` names the text in errors.
    static Result<DistortionTable> parse(const std::string& text, const std::string& source);
    /// Reads and parses a file.
    static Result<DistortionTable> load(const std::filesystem::path& path);
    /// A table of the given factors, cell (x, y) at index y * kCellsPerSide + x, bins in order
    /// (1, 3, 5, 7, 9 m); a cell of five zeros is invalid. PLUMB_CHECKs the cell count.
    static DistortionTable fromCells(std::vector<std::array<float, 5>> cells);
    /// Every factor 1: the undistorted sensor.
    static DistortionTable neutral();

    /// The table in the dist-model.txt format parse() reads: the 5 header lines, then per cell
    /// (y-major) "10 5 2" and four "% 5 1" blocks of 5 numbers (counts, two sums, factors), one
    /// number per line. Only the factors are kept by a DistortionTable: a valid cell is written
    /// with counts of kValidCount (the smallest count parse() takes as measured) and zero sums, an
    /// invalid cell with zero counts and zero factors. Factors are written with 17 significant
    /// digits, so parse(format()) gives back the same floats.
    std::string format() const;
    /// format() into a file; kIoError names the path when it cannot be written.
    Status save(const std::filesystem::path& path) const;
    static constexpr double kValidCount = 8000.0;

    /// Table cells along x and along y, depth bins per cell, and the depth of bin i's centre.
    static constexpr int kCellsPerSide = 80;
    static constexpr int kBins = 5;
    static double binCentreM(int i) { return 2.0 * i + 1.0; }
    /// The bins of depth z and their interpolation weights, as cellFactor() uses them:
    /// f(z) = (1 - a) * f[lo] + a * f[hi] with lo, hi in [0, 4] (lo == hi at both ends).
    struct BinWeights {
        int lo, hi;
        double a;
    };
    static BinWeights binWeights(double z) {
        const int i2 = static_cast<int>((z + 1.0) / 2.0);
        const int i1 = i2 - 1;
        return {std::clamp(i1, 0, 4), std::min(i2, 4), (z - (2.0 * i1 + 1.0)) / 2.0};
    }
    /// The 5 factors of cell (cell_x, cell_y).
    const std::array<float, 5>& cell(int cell_x, int cell_y) const {
        return cells_[static_cast<size_t>(cell_y) * kCells + cell_x];
    }

    /// Factor f for pixel (x, y) of a 640x480 image and depth z (metres), interpolated between
    /// depth bins (A.3). 0 marks an invalid cell.
    float factor(int x640, int y480, double z) const {
        return cellFactor(cellX(x640), cellY(y480), z);
    }
    /// The cell column of x640 and row of y480 (clamped to the table): factor() in two steps, so
    /// that per-image loops can look cells up once per column and row.
    static int cellX(int x640);
    static int cellY(int y480);
    /// factor() of the cell (cell_x, cell_y) from cellX, cellY. Inline: once per noisy pixel.
    float cellFactor(int cell_x, int cell_y, double z) const {
        // Eq. A.3: bins centred at 1, 3, 5, 7, 9 m, linear in between, clamped at both ends.
        const BinWeights b = binWeights(z);
        const std::array<float, 5>& c = cell(cell_x, cell_y);
        return static_cast<float>((1.0 - b.a) * c[b.lo] + b.a * c[b.hi]);
    }

  private:
    static constexpr int kCells = kCellsPerSide;
    std::vector<std::array<float, 5>> cells_;  // 80 * 80
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
