// SPDX-License-Identifier: Apache-2.0
#pragma once

// Depth calibration of a structured-light sensor. PrimeSense-type cameras bend depth by a
// low-frequency, depth-dependent factor that CLAMS (Teichman, Miller, Thrun 2013) measures per
// image cell; Choi, Zhou and Koltun (CVPR 2015) ship such a measurement as dist-model.txt, and
// the sensor model of reference §1.4.A.3 reports d_meas = d / f(u, v, d). Left in, the bend is
// fixed to the image: on weakly structured views projective ICP follows the pattern rather than
// the room (a camera walking past a wall appears to stand still). Undistorting inverts A.3:
// d = d_meas * f(u, v, d), solved by fixed-point iteration from d = d_meas (f varies by a few per
// cent over metres, so each step shrinks the error by the small factor d * df/dd).
//
// Thread-safety: a DepthCalibration is immutable after loading and its const members are
// thread-safe.

#include <filesystem>
#include <string>

#include "common/calibration/distortion_table.hpp"
#include "common/core/status.hpp"
#include "common/image/image.hpp"

namespace plumb {

class DepthCalibration {
  public:
    /// Reads a CLAMS / Redwood dist-model.txt (80x80 cells of 8x6 pixels at 640x480, five depth
    /// bins centred at 1, 3, 5, 7 and 9 m).
    static Result<DepthCalibration> load(const std::filesystem::path& path);
    DepthCalibration(DistortionTable table, std::string source);

    /// The undistorted image: d = d_meas * f(u, v, d) per valid pixel, f looked up at the origin
    /// of the pixel's 2x2 disparity block scaled to the table's 640x480 grid; pixels in cells the
    /// calibration could not measure (f = 0) become invalid. Any image size.
    /// Works in place on `depth` (pass an rvalue to avoid a copy).
    DepthImage undistort(DepthImage depth) const;

    /// undistort() at the origins of the 2x2 blocks only: pixel (i, j) of the result, an image
    /// of ((width + 1) / 2) x ((height + 1) / 2), is pixel (2i, 2j) of undistort(depth), the
    /// same float, for a quarter of the work.
    DepthImage undistortBlockOrigins(const DepthImage& depth) const;

    /// Where the table came from (for logs).
    const std::string& source() const { return source_; }

    /// Fixed-point iterations of undistort(): at most kMaxIterations, stopping when a step moves
    /// the depth by less than kTolerance metres. Where they have not converged by then (a steep
    /// factor contracts slowly), the fixed point is solved in closed form on the factor's
    /// piece that holds it (f is linear in depth between bin centres).
    static constexpr int kMaxIterations = 8;
    static constexpr double kTolerance = 1e-6;

    /// The depth undistort() gives a pixel of table cell (cell_x, cell_y) (DistortionTable::
    /// cellX, cellY of its block origin) that measured `measured` > 0, before rounding to float.
    double undistortDepth(int cell_x, int cell_y, double measured) const;

  private:
    DistortionTable table_;
    std::string source_;
};

}  // namespace plumb
