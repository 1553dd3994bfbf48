// SPDX-License-Identifier: Apache-2.0
#include "common/calibration/depth_calibration.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

namespace plumb {

Result<DepthCalibration> DepthCalibration::load(const std::filesystem::path& path) {
    auto table = DistortionTable::load(path);
    if (!table.isOk()) return table.status();
    return DepthCalibration(std::move(table).value(), path.string());
}

DepthCalibration::DepthCalibration(DistortionTable table, std::string source)
    : table_(std::move(table)), source_(std::move(source)) {}

namespace {

/// The piece of A.3's factor that holds depth z: -1 below the first bin centre (the factor is
/// the first bin's), 4 from the last one on (the last bin's), else k for z in [2k + 1, 2k + 3),
/// where the factor is linear between bins k and k + 1.
int pieceOf(double z) {
    constexpr int kLast = DistortionTable::kBins - 1;
    if (z < DistortionTable::binCentreM(0)) return -1;
    if (z >= DistortionTable::binCentreM(kLast)) return kLast;
    return static_cast<int>((z - 1.0) / 2.0);
}

/// The root of d = measured * f(d) with f extended linearly from one piece, f(d) = alpha + beta d
/// there: d = measured * alpha / (1 - measured * beta). nullopt when 1 - measured * beta <= 0
/// (the factor is then no contraction, and the closed form does not apply).
std::optional<double> rootOnPiece(const std::array<float, 5>& f, int piece, double measured) {
    constexpr int kLast = DistortionTable::kBins - 1;
    double alpha = 0.0, beta = 0.0;
    if (piece < 0 || piece >= kLast) {
        alpha = f[static_cast<size_t>(std::clamp(piece, 0, kLast))];
    } else {
        beta = (double{f[piece + 1]} - double{f[piece]}) / 2.0;
        alpha = double{f[piece]} - beta * DistortionTable::binCentreM(piece);
    }
    const double denominator = 1.0 - measured * beta;
    if (!(denominator > 0.0)) return std::nullopt;
    return measured * alpha / denominator;
}

/// The fixed point d = measured * f(d) in closed form, f piecewise linear in depth (A.3) with
/// every factor > 0; nullopt where measured * f'(d) >= 1. While measured * f'(d) < 1,
/// measured * f(d) - d falls with d, so a root outside the piece it was solved on says on which
/// side the fixed point lies: start on the measured depth's piece and step towards it.
std::optional<double> closedFormDepth(const std::array<float, 5>& f, double measured) {
    int piece = pieceOf(measured);
    for (int step = 0; step <= DistortionTable::kBins; ++step) {
        const std::optional<double> d = rootOnPiece(f, piece, measured);
        if (!d) return std::nullopt;
        const int holder = pieceOf(*d);
        if (holder == piece) return d;
        piece += holder > piece ? 1 : -1;
    }
    return std::nullopt;
}

}  // namespace

double DepthCalibration::undistortDepth(int cell_x, int cell_y, double measured) const {
    double z = measured;
    for (int i = 0; i < kMaxIterations; ++i) {
        const double next = measured * static_cast<double>(table_.cellFactor(cell_x, cell_y, z));
        const bool converged = std::abs(next - z) < kTolerance;
        z = next;
        if (converged || z <= 0.0) return z;
    }
    // Where the factor is steep (a few cells beyond 7 m on the Redwood table) the iteration
    // contracts slowly: the closed form on the factor's linear pieces finishes it.
    const std::array<float, 5>& f = table_.cell(cell_x, cell_y);
    if (std::all_of(f.begin(), f.end(), [](float x) { return x > 0.0F; })) {
        if (const std::optional<double> d = closedFormDepth(f, measured)) return *d;
    }
    return z;
}

namespace {

/// undistortDepth() along one image row, reusing the last depth for a reading that repeats the
/// last one in the same cell (quantised depth on flat surfaces, the pixels of one disparity
/// block): the same floats.
class RowUndistorter {
  public:
    RowUndistorter(const DepthCalibration& calibration, int cell_y)
        : calibration_(calibration), cell_y_(cell_y) {}

    /// The undistorted depth of a valid reading (> 0) of cell column `cell_x`.
    float operator()(int cell_x, float measured) {
        if (measured != last_measured_ || cell_x != last_cell_) {
            last_measured_ = measured;
            last_cell_ = cell_x;
            last_depth_ =
                static_cast<float>(calibration_.undistortDepth(cell_x, cell_y_, measured));
        }
        return last_depth_;
    }

  private:
    const DepthCalibration& calibration_;
    const int cell_y_;
    float last_measured_ = 0.0F, last_depth_ = 0.0F;
    int last_cell_ = -1;
};

}  // namespace

DepthImage DepthCalibration::undistort(DepthImage depth) const {
    const int w = depth.width();
    const int h = depth.height();
    // The table's cells are defined on a 640x480 image and, as in the sensor model (reference
    // §1.4.A.2-3), looked up at the origin of the pixel's 2x2 disparity block.
    std::vector<int> cell_x(static_cast<size_t>(w));
    for (int u = 0; u < w; ++u) cell_x[u] = DistortionTable::cellX((u - u % 2) * 640 / w);
    // Rows are independent: any split gives the same image.
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), [&](const tbb::blocked_range<int>& rows) {
        for (int v = rows.begin(); v < rows.end(); ++v) {
            RowUndistorter row(*this, DistortionTable::cellY((v - v % 2) * 480 / h));
            for (int u = 0; u < w; ++u) {
                const float measured = depth(u, v);
                // Invalid stays invalid, NaN included.
                depth(u, v) = measured > 0.0F ? row(cell_x[u], measured) : 0.0F;
            }
        }
    });
    return depth;
}

DepthImage DepthCalibration::undistortBlockOrigins(const DepthImage& depth) const {
    const int w = depth.width();
    const int h = depth.height();
    DepthImage out((w + 1) / 2, (h + 1) / 2);
    tbb::parallel_for(
        tbb::blocked_range<int>(0, out.height(), 8), [&](const tbb::blocked_range<int>& rows) {
            for (int j = rows.begin(); j < rows.end(); ++j) {
                RowUndistorter row(*this, DistortionTable::cellY(2 * j * 480 / h));
                for (int i = 0; i < out.width(); ++i) {
                    const float measured = depth(2 * i, 2 * j);
                    out(i, j) = measured > 0.0F
                                    ? row(DistortionTable::cellX(2 * i * 640 / w), measured)
                                    : 0.0F;
                }
            }
        });
    return out;
}

}  // namespace plumb
