// SPDX-License-Identifier: Apache-2.0
#pragma once

// The depth distortion table of a structured-light sensor (reference §1.4.A.3): per image cell
// and depth bin a multiplicative factor f, with the sensor model d_meas = d / f(u, v, d). The
// simulator applies it (drivers/sim/noise.hpp), DepthCalibration inverts it
// (common/calibration/depth_calibration.hpp) and backend/calibration estimates it from a scan.
//
// Thread-safety: a value type; const members may run concurrently, a write needs exclusive
// access.

#include <algorithm>
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "common/core/status.hpp"

namespace plumb {

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

}  // namespace plumb
