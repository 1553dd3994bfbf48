// SPDX-License-Identifier: Apache-2.0
#pragma once

// Self-calibration's first step, from the frames alone: the smooth part of the depth distortion,
// learned from the planes each frame sees (reference §7c). The bend of a structured-light sensor
// (a bowl over the image, growing with depth) curves every plane in every frame; the tracked poses
// of a reconstruction absorb much of that bend (the trajectory bends to fit it), which is why the
// table estimated against a reconstruction of the raw depth (DistortionEstimator) holds only part
// of the bowl. Planarity within one frame needs no pose at all.
//
// Model: the factor of the table (z_true = f * z_raw, self_calibration.hpp) as a polynomial over
// the normalised image coordinates (u, v) in [-1, 1] of the 640x480 table, per depth bin, linear
// in depth between bins exactly as the table interpolates:
//
//   f(u, v, z) = 1 + sum_b w_b(z) sum_k c[b][k] phi_k(u, v),                               (Eq. 1)
//
// phi_k the monomials u^i v^j of degree 2 to 4 (12 of them), each less its least-squares affine
// part a + b u + c v over the table's cells. A factor whose inverse is affine in (u, v) maps every
// plane to a plane (it is a projective map of space fixing the camera centre), so planarity
// cannot see it; the model has none (its factors average 1 over the image, with no tilt). That
// part, the global scale among it, is left to the estimate against the reconstruction.
//
// Data: each frame is reduced to a grid of blocks (grid_columns x grid_rows); a block with enough
// valid pixels and no depth edge inside keeps the mean of its raw points and of their (u, v).
// Every iteration then, per frame: corrects the block points with the current model, computes
// their normals, grows planar segments (neighbours whose normals and depths agree, normals within
// max_segment_spread_deg of the seed's) and fits a plane to each. The residuals
//
//   r_i = n_s . (f(u_i, v_i, z_i) P_i) - d_s                                                (Eq. 2)
//
// of every segment s and block i are minimised over the coefficients and the planes jointly by
// Gauss-Newton: each plane's three parameters are eliminated per segment (Schur complement), the
// coefficient step is solved, the planes are refitted. Residuals are weighed by the sensor's
// depth noise (sigma ~ z^2) and by Huber weights at huber_sigmas robust sigmas of their segment.
// Segments whose block normals spread too far (curved surfaces) or whose fit stays poor are not
// used. Coefficients of a bin with little data are held to the linear extrapolation of their
// neighbours in depth (bin_smoothness).
//
// Optionally (estimate_affine) each bin's affine terms are estimated too. Of those, the factors
//
//   f(u, v, z) = a + z (b + c u + d v),  i.e.  1 / z_raw = a / z + b + c u + d v,             (Eq.
//   3)
//
// an affine map of the disparity, keep every plane a plane (1/z of a plane is affine in (u, v)),
// so planarity cannot see them; after every step the estimated bins' affine coefficients are
// made orthogonal to Eq. 3 (its least-squares fit over the bin centres is removed), which fixes
// that gauge at the neutral factor. What is left is a tilt or scale that does not grow in
// proportion to the depth, and that bends planes spanning depths.
//
// The depth-proportional scale (Eq. 3's b). The basis' gauge sets Eq. 3's part of the model to 0
// over the whole image, but a sensor has no depth in some cells (a border of the image, where its
// pattern does not reach), and over the cells where it has depth the curved terms still hold an
// Eq. 3 part. Of it, the tilts (c, d) are observed later, slowly, by the estimate against the
// reconstruction; the scale that grows with depth (b) is observed by nothing after this stage
// (the alternation passes it on unchanged), and b alone changes a room's depth by tenths of a
// per cent per metre. With scale_gauge_over_data, the fit of Eq. 3 to the model's factors over
// the cells with data (at the estimated bins' centres z) gives b, and (z - z_0) b is removed
// from each estimated bin, z_0 the centre of the nearest estimated bin: that bin's factors, and
// with them the global scale, stay as they were.
//
// Thread-safety: const members may run concurrently; results never depend on num_threads.

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "common/calibration/distortion_table.hpp"
#include "common/camera/pinhole.hpp"
#include "common/config/schema.hpp"
#include "common/core/status.hpp"
#include "common/image/image.hpp"

namespace plumb::calibration {

struct PlanarDistortionConfig {
    /// Blocks per frame along x and y (each frame's pixels are averaged over them); fewer when a
    /// block would be narrower or lower than 4 pixels (40 x 30 at 160x120).
    int grid_columns = 80;
    int grid_rows = 60;
    /// A block is used when at least this share of its pixels hold depth ...
    double min_block_valid = 0.5;
    /// ... and their depths spread by at most this fraction of their mean (no edge inside).
    double max_block_spread = 0.05;
    /// Blocks whose mean depth is outside [min_depth_m, max_depth_m] are not used, metres.
    double min_depth_m = 0.4;
    double max_depth_m = 3.8;
    /// Each raw depth belongs to the origin (u - u % 2, v - v % 2) of its 2x2 disparity block,
    /// where a structured-light sensor measures it (as SelfCalibrationConfig).
    bool at_block_origin = true;
    /// Normals from the neighbours this many blocks away on either side.
    int normal_stencil = 2;
    /// Segments: neighbouring blocks join when their normals differ by at most this ...
    double max_neighbour_angle_deg = 6.0;
    /// ... their depths by at most this fraction of the depth ...
    double max_depth_step = 0.03;
    /// ... and the block's normal is within this of the segment seed's.
    double max_segment_spread_deg = 25.0;
    /// Segments with fewer blocks are not used.
    int min_segment_blocks = 40;
    /// Segments whose weighted residual RMS exceeds this many times the sensor's depth noise at
    /// their depth (after the first iteration) are not used: they are not planes.
    double max_segment_rms_sigmas = 6.0;
    /// The depth noise of one raw pixel, sigma = noise_per_m2 * z^2 (metres); blocks average it.
    double noise_per_m2 = 0.0016;
    /// Huber threshold, in robust sigmas of the segment's residuals.
    double huber_sigmas = 2.0;
    /// Gauss-Newton iterations (each re-segments the frames with the current model).
    int iterations = 6;
    /// Stops early when the largest coefficient change is below this.
    double change_tolerance = 1e-5;
    /// Weight (in blocks) of the penalty c[b+1] - 2 c[b] + c[b-1] = 0 on each coefficient, and of
    /// c[b] - c[b-1] = 0 on the last bins: holds bins with little data to their neighbours.
    double bin_smoothness = 50.0;
    /// A depth bin is estimated when its share of the blocks' interpolation weights is at least
    /// this; the others copy the nearest estimated bin (flat in depth beyond the data).
    double min_bin_share = 0.1;
    /// Ridge added to the normal equations, relative to their largest diagonal entry: holds the
    /// combinations of coefficients the frames hardly observe at 0 (a short scan of one corner).
    double damping = 1e-4;
    /// The two halves of the scan (its first and second half of frames) are fitted apart too;
    /// when their tables differ by more than this (median |f_1 - f_2| over the image beyond a
    /// projective part, worst of the 1 m and 3 m bins), the planes do not determine the bend and
    /// estimate() fails. 0: no check.
    double max_split_disagreement = 0.005;
    /// Also estimate each bin's affine terms (1, u, v), less the part that keeps planes planes
    /// (Eq. 3): with two estimated bins that leaves one tilt along u and one along v, with three
    /// a scale curved in depth and two more tilts. Off: the affine terms stay 0.
    bool estimate_affine = false;
    /// Sets the model's depth-proportional scale (Eq. 3's b) to 0 over the cells with data (see
    /// above) instead of over the whole image.
    bool scale_gauge_over_data = true;
    /// A table cell has data when at least this share of its pixels, over the frames kept, hold
    /// depth.
    double min_cell_valid = 0.1;
    /// Only frames k with k % frame_step == 0 of those added are kept.
    int frame_step = 1;
    /// Worker threads (0 = TBB default). Results do not depend on it.
    int num_threads = 0;
};

void describe(config::Schema& s, PlanarDistortionConfig& c);
/// OK, or kInvalidArgument naming the first field out of range.
Status validate(const PlanarDistortionConfig& c);

/// Eq. 1.
struct PlanarDistortion {
    static constexpr int kDegree = 4;
    /// The monomials of degree 2 to kDegree, each less its affine part ...
    static constexpr int kCurvedTerms = (kDegree + 1) * (kDegree + 2) / 2 - 3;
    /// ... then 1, u and v (estimated only with PlanarDistortionConfig::estimate_affine).
    static constexpr int kTerms = kCurvedTerms + 3;
    static constexpr int kBins = DistortionTable::kBins;
    /// c[b][k]: bin b (centres 1, 3, 5, 7, 9 m), term k of terms().
    std::array<std::array<double, kTerms>, kBins> c{};

    /// The basis phi_k at normalised image coordinates (u, v).
    static std::array<double, kTerms> terms(double u, double v);
    /// f(u, v, z); u = (x640 - 320) / 320, v = (y480 - 240) / 240 on the 640x480 table.
    double factor(double u, double v, double z) const;
    /// The table of Eq. 1 at each cell's centre.
    DistortionTable toTable() const;
};

struct PlanarIteration {
    int iteration = 0;
    size_t segments = 0;      ///< planar segments used
    size_t blocks = 0;        ///< blocks in them
    double rms_sigmas = 0.0;  ///< weighted residual RMS after the step, in noise sigmas
    double max_change = 0.0;  ///< largest coefficient change of the step
};

struct PlanarEstimate {
    PlanarDistortion model;
    std::vector<PlanarIteration> iterations;
    size_t frames = 0;
    /// Bit b set: bin b was estimated from data (the others copy their nearest such bin).
    unsigned estimated_bins = 0;
    /// How far the tables of the scan's two halves differ (see max_split_disagreement).
    double split_disagreement = 0.0;
    /// The depth-proportional scale removed (Eq. 3's b over the cells with data, per metre; 0
    /// when scale_gauge_over_data is off or one bin was estimated) and the cells it was fitted
    /// over.
    double removed_depth_scale_per_m = 0.0;
    size_t cells_with_data = 0;
};

/// One planar segment of one frame, in the camera frame of the depth corrected by a model.
struct SegmentPlane {
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();  ///< unit, towards the camera
    double distance = 0.0;    ///< normal . P = distance for points P of the plane (< 0)
    double mean_depth = 0.0;  ///< mean depth of its blocks, metres
    size_t blocks = 0;
    double rms_sigmas = 0.0;  ///< robust residual RMS, in sensor noise sigmas
};

/// Collects the block grids of raw depth frames of one camera and fits Eq. 1 to them.
/// Not thread-safe; estimate() is const.
class PlanarDistortionEstimator {
  public:
    PlanarDistortionEstimator(const PinholeCamera& camera, const PlanarDistortionConfig& config);

    /// Adds one raw frame (metres, 0 = invalid); frames are counted for frame_step.
    /// kInvalidArgument when its size differs from the camera's.
    Status addFrame(const DepthImage& raw);
    size_t numFrames() const { return frames_.size(); }

    using Observer = std::function<void(const PlanarIteration&)>;
    /// The Gauss-Newton fit of Eq. 2 over the frames kept, starting from the neutral model, and
    /// the check of its two halves, then (scale_gauge_over_data) the depth-proportional scale
    /// over the cells with data removed. kFailedPrecondition when no frame holds a planar
    /// segment or the halves disagree (the message says by how much).
    Result<PlanarEstimate> estimate(const Observer& observer = {}) const;

    /// The planar segments of every frame kept, its depth corrected by `model`: segments grown
    /// and planes fitted as in estimate()'s iterations, those that pass its tests (normal
    /// spread, residual RMS) only. In frame order.
    std::vector<std::vector<SegmentPlane>> framePlanes(const PlanarDistortion& model) const;

    struct Block {
        float x, y, z;  ///< mean raw point in the camera frame, metres (z = 0: not used)
        float u, v;     ///< mean normalised table coordinates
    };

  private:
    Result<PlanarEstimate> fit(size_t begin, size_t end, const Observer& observer) const;

    /// The fits of the scan's two halves must agree (max_split_disagreement); sets
    /// all->split_disagreement.
    Status checkHalves(PlanarEstimate* all) const;
    /// The table cell (y * 80 + x) of pixel (x, y).
    size_t cellOf(int x, int y) const {
        return cell_row_start_[static_cast<size_t>(y)] + cell_column_[static_cast<size_t>(x)];
    }
    /// The table cells whose share of valid pixels over the frames kept reaches min_cell_valid.
    std::vector<bool> cellsWithData() const;

    PinholeCamera camera_;
    PlanarDistortionConfig config_;
    int columns_, rows_;  ///< the grid
    size_t added_ = 0;
    std::vector<std::vector<Block>> frames_;  ///< grid_rows x grid_columns per frame
    /// Per pixel column its table cell's column, per pixel row its cell row's first cell.
    std::vector<size_t> cell_column_, cell_row_start_;
    /// Per table cell (y * 80 + x): pixels of one frame, and valid pixels over the frames kept.
    std::vector<uint32_t> cell_pixels_;
    std::vector<uint64_t> cell_valid_;
};

}  // namespace plumb::calibration
