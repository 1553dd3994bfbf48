// SPDX-License-Identifier: Apache-2.0
#pragma once

// Self-calibration of the depth distortion table from a scan (reference §7c; CLAMS, Teichman,
// Miller and Thrun, RSS 2013). The table is the one of the sensor model (§1.4.A.3, common/
// calibration/distortion_table.hpp): per image cell (80 x 80 cells of 8 x 6 px at 640x480) and
// depth bin (centres 1, 3, 5, 7, 9 m) a factor f, linear in depth between bins, with
//
//   z_true = f(u, v, z_true) * z_raw.
//
// Estimation (DistortionEstimator): every raw depth z_raw is compared with the depth z_model of
// a model of the scene rendered at the frame's pose; each such sample is an observation
//
//   r = z_model / z_raw = (1 - a) f[lo] + a f[hi],   (lo, hi, a) = binWeights(z_model)   (Eq. 1)
//
// of the two factors of its cell that bracket z_model. Per cell the five factors are the robust
// least-squares solution of Eq. (1) over the cell's samples (iteratively reweighted: Huber weights
// at huber_k robust sigmas, samples beyond outlier_sigmas dropped, the sigma from the median
// absolute residual), plus a small penalty bin_smoothness * (f[i] - f[i+1])^2 that keeps the
// system regular when the samples sit at one depth between two bins.
//
// Coverage: a bin of a cell is covered when the squares of the inlier samples' interpolation
// weights on it sum to at least min_samples. Factors of uncovered bins are not unknowns: they take
// the value of the nearest covered bin of the same cell (flat in depth beyond the data, which is
// what the samples next to them are fitted with). A cell with no covered bin keeps the neutral
// factor 1 in every bin and is reported as not covered.
//
// Gauge (§7c): the global scale of all factors is not observable from self-consistency alone
// (scaling every depth and the model together fits equally well). It is fixed by dividing every
// estimated factor by the mean factor of the 1 m bin over the cells covered there (or, when no
// cell is covered at 1 m, of the nearest bin with coverage): the near bin's mean factor is 1.
//
// Alternation (selfCalibrate): undistort the raw depth with the current table, fuse a TSDF with
// the poses, raycast it at every frame's pose, estimate the table against it (each estimate
// compares the raw depth with the new model, so estimates do not compound), move the table
// towards the estimate (over-relaxed, see SelfCalibrationConfig::relaxation), repeat until the
// median change of the covered factors is below change_tolerance. With compare_at_block_origin
// the model is fused from and rendered at the 2x2 block origins only (a camera of half the
// resolution through pixels (2i, 2j)): the depth of a block belongs to its origin.
//
// Poses: fixed poses (ground truth) make the distortion observable through the views' mutual
// consistency. Poses tracked from the same raw frames absorb part of the distortion (odometry
// bends with the depth it aligns), and re-tracking every step (PoseProvider) recovers only part
// of it; a joint optimisation of poses and table (Zhou & Koltun 2014, §7c) is not done here.
//
// Thread-safety: the functions and const members may run concurrently on distinct objects; results
// never depend on num_threads.

#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "backend/calibration/planar_distortion.hpp"
#include "backend/calibration/right_angles.hpp"
#include "common/calibration/distortion_table.hpp"
#include "common/camera/pinhole.hpp"
#include "common/config/schema.hpp"
#include "common/core/status.hpp"
#include "common/image/image.hpp"
#include "common/tsdf/raycast.hpp"
#include "common/tsdf/tsdf_volume.hpp"

namespace plumb::calibration {

struct SelfCalibrationConfig {
    /// Samples: model depths outside [min_depth_m, max_depth_m] are not used, metres. Keep the
    /// upper limit below the sensor's range limit (4 m for the simulated sensor) by a few
    /// quantisation steps: near the limit only the raw depths that fall inside it survive, which
    /// biases their ratio upwards.
    double min_depth_m = 0.4;
    double max_depth_m = 3.5;
    /// Samples: pixels whose model surface is seen at a smaller |cos| of the viewing angle are not
    /// used (the model and the sensor are both least reliable at grazing angles).
    double min_view_cos = 0.3;
    /// Samples: ratios z_model / z_raw further than this from 1 are not used (depth edges, parts
    /// of the scene the model does not hold); the table's factors are within a few per cent of 1.
    double max_ratio_deviation = 0.1;
    /// Samples: every pixel_stride-th pixel along rows and columns is compared.
    int pixel_stride = 1;
    /// Samples: the raw depth at pixel (u, v) is compared with the model's depth at the origin
    /// (u - u % 2, v - v % 2) of its 2x2 disparity block, where a structured-light sensor
    /// measures it (reference §1.4.A.2; DepthCalibration looks the factor up there too), and the
    /// model is fused and rendered at the block origins only; false: at (u, v) itself.
    bool compare_at_block_origin = true;
    /// Coverage: a cell's bin is estimated when the squared interpolation weights of its inlier
    /// samples on it sum to at least this (its diagonal of the normal equations: a sample at the
    /// bin's centre counts 1, one half way to the next bin 1/4), so that a bin is not fitted from
    /// samples that barely depend on it.
    double min_samples = 30.0;
    /// Robust fit: the initial median and each pass's robust sigma are taken over at most this
    /// many of a cell's samples, every k-th in the order they were added (all frames alike);
    /// 0 = over all. The fit itself uses every sample.
    int median_samples = 4096;
    /// Robust fit: reweighting passes after the initial median.
    int robust_iterations = 4;
    /// Robust fit: Huber threshold, in robust sigmas of the cell's residuals.
    double huber_k = 1.345;
    /// Robust fit: residuals beyond this many robust sigmas get weight 0.
    double outlier_sigmas = 4.0;
    /// Robust fit: lower bound of the robust sigma (dimensionless ratio units).
    double min_sigma = 1e-4;
    /// Weight of the penalty (f[i] - f[i+1])^2 between adjacent covered bins, in samples.
    double bin_smoothness = 0.01;
    /// Alternation: at most this many estimate steps.
    int max_iterations = 8;
    /// Alternation: stops when the median |change| of the factors covered in both the previous
    /// and the new table is below this (dimensionless).
    double change_tolerance = 2e-4;
    /// Alternation: from the second step on, the table moves by this multiple of the estimated
    /// change, in log space: f <- f_previous * (f_estimated / f_previous)^relaxation. The model
    /// is fused from the current table, so part of the remaining distortion is seen in the model
    /// too and each plain step (relaxation 1) removes only part of it; over-relaxation in [1, 2)
    /// speeds up that slow convergence (errors the data determine in one step oscillate with
    /// amplitude |1 - relaxation| instead).
    double relaxation = 1.5;
    /// The planar stages of `plumb calibrate` and `plumb reconstruct --self-calibrate`: the bend
    /// from each frame's planes, without poses (planar_distortion.hpp). `plumb calibrate`'s
    /// alternation starts from its table; `--self-calibrate` makes its first reconstruction with
    /// it and learns the bend left after the refined table with it again.
    PlanarDistortionConfig planar;
    /// After each planar stage: the part of the distortion that keeps planes planes, from the
    /// right angles between each frame's planes (right_angles.hpp).
    RightAngleConfig right_angles;
    /// The model: TSDF fused from the undistorted frames at their poses.
    tsdf::TsdfConfig tsdf = defaultTsdf();
    /// The model's depth at each frame's pose: normals from the cell of the crossing (they only
    /// gate the viewing angle) and secant hits, for speed. Rays end at the smaller of its
    /// max_depth_m and the samples' max_depth_m, and rays whose undistorted depth lies beyond
    /// that end are not cast: they would march in full for a sample the depth gate drops.
    tsdf::RaycastConfig raycast = defaultRaycast();
    /// Worker threads of the per-cell fit (0 = TBB default). Results do not depend on it.
    int num_threads = 0;

    static tsdf::TsdfConfig defaultTsdf() {
        tsdf::TsdfConfig c;
        c.voxel_size_m = 0.01F;
        c.truncation_m = 0.06F;
        c.max_depth_m = 3.5F;  // as max_depth_m: truncated ranges would bias the model too
        return c;
    }
    static tsdf::RaycastConfig defaultRaycast() {
        tsdf::RaycastConfig c;
        c.normals = tsdf::RaycastNormals::kCell;
        c.secant_hits = true;
        c.skip_hints_beyond_end = true;
        return c;
    }
};

void describe(config::Schema& s, SelfCalibrationConfig& c);
/// OK, or kInvalidArgument naming the first field out of range.
Status validate(const SelfCalibrationConfig& c);

/// What an estimate found, beside the table.
struct DistortionEstimate {
    DistortionTable table = DistortionTable::neutral();
    /// Per depth bin: cells covered by their own samples.
    std::array<int, DistortionTable::kBins> covered_cells{};
    /// Per cell (y * 80 + x): bit i set when bin i is covered.
    std::vector<uint8_t> covered;
    /// Samples taken (after the depth, angle and ratio gates) and, of those, the fit's outliers.
    size_t samples = 0;
    size_t outliers = 0;
    /// The gauge: the bin whose mean factor is 1 and the scale divided out of every factor.
    int gauge_bin = 0;
    double gauge_scale = 1.0;
    /// Change from the previous table over the factors covered in both (0 when none is):
    double median_change = 0.0;  ///< median |f_new - f_previous|
    double max_change = 0.0;     ///< largest |f_new - f_previous|
    size_t compared_factors = 0;

    bool isCovered(int cell_x, int cell_y, int bin) const {
        return (covered[static_cast<size_t>(cell_y) * DistortionTable::kCellsPerSide + cell_x] >>
                bin) &
               1U;
    }
};

/// Accumulates (raw, model) depth samples of frames of one camera and fits the table.
/// Not thread-safe (one instance per thread); estimate() is const.
class DistortionEstimator {
  public:
    /// Frames of width x height pixels (any size; cells are found by scaling to 640x480).
    DistortionEstimator(int width, int height, const SelfCalibrationConfig& config);

    /// Adds the samples of one frame: `raw` the sensor's depth (metres, 0 = invalid), `model` the
    /// model's depth at the frame's pose (0 = no surface), `view_cos` the |cos| of the model
    /// surface's viewing angle (empty: not gated). `model` and `view_cos` are of the frame's size
    /// or, with compare_at_block_origin, may be the block origins' images ((width + 1) / 2 x
    /// (height + 1) / 2; pixel (i, j) is frame pixel (2i, 2j)). kInvalidArgument when a size is
    /// neither.
    Status addFrame(const DepthImage& raw, const DepthImage& model, const Image<float>& view_cos);

    /// The table fitted to every sample so far, and its change from `previous` (nullptr: from
    /// the neutral table). kFailedPrecondition when no cell has a covered bin.
    Result<DistortionEstimate> estimate(const DistortionTable* previous = nullptr) const;

    size_t numSamples() const { return num_samples_; }

    /// Drops every sample, keeping their memory for the next frames (the next iteration's).
    void clear();

  private:
    struct Sample {
        float z_model;  ///< metres
        float ratio;    ///< z_model / z_raw
    };
    int width_, height_;
    SelfCalibrationConfig config_;
    std::vector<int> cell_of_column_;
    std::vector<int> rows_of_cell_;  ///< first image row of each row of cells, then the height
    /// Per cell, per depth segment (kSegments): samples between the same two bin centres.
    static constexpr int kSegments = DistortionTable::kBins + 1;
    std::vector<std::vector<Sample>> samples_;  ///< [cell * kSegments + segment]
    size_t num_samples_ = 0;
};

/// One step of the alternation.
struct CalibrationIteration {
    int iteration = 0;
    /// The step's estimate; its table is the table after the (over-relaxed) update, its change
    /// figures compare the estimate itself with the table before the step.
    DistortionEstimate estimate;
    size_t fused_blocks = 0;  ///< TSDF blocks of the model the step compared against
};

struct SelfCalibrationResult {
    DistortionTable table = DistortionTable::neutral();  ///< the last estimate
    std::vector<CalibrationIteration> iterations;
    bool converged = false;  ///< the last change was below change_tolerance
    /// The poses the last iteration compared the frames at (refined when an aligner was given).
    std::vector<Eigen::Isometry3d> T_W_C;
};

/// Poses T_W_C of the frames, given their depth undistorted with the current table (for
/// alternations that re-track every iteration). Errors end the alternation.
using PoseProvider =
    std::function<Result<std::vector<Eigen::Isometry3d>>(const std::vector<DepthImage>& depth)>;

/// Refines the pose T_W_C of frame `k` against the model of the current iteration: `depth` is
/// the frame undistorted with the current table as the model fused it, seen by `camera` (the
/// block-origin camera of half the resolution with compare_at_block_origin). Returns the refined
/// pose, or the given one when the frame cannot be aligned; errors end the alternation.
using FrameAligner = std::function<Result<Eigen::Isometry3d>(
    size_t k, const DepthImage& depth, const PinholeCamera& camera, const tsdf::TsdfVolume& model,
    const Eigen::Isometry3d& T_W_C)>;

/// Called after every iteration (for progress output); may be empty.
using IterationObserver = std::function<void(const CalibrationIteration&)>;

/// The alternation of §7c with poses from `poses` (called once per iteration with the frames
/// undistorted by the current table), starting from `initial` (nullptr: neutral).
/// kInvalidArgument: no frames, frames of a size other than the camera's, a pose count that
/// differs from the frame count, a non-finite pose, an invalid camera or config.
/// kFailedPrecondition: the model covers no cell (e.g. the frames hold no depth in range).
Result<SelfCalibrationResult> selfCalibrate(const std::vector<DepthImage>& raw,
                                            const PinholeCamera& camera, const PoseProvider& poses,
                                            const SelfCalibrationConfig& config,
                                            const DistortionTable* initial = nullptr,
                                            const IterationObserver& observer = {});

/// The same from poses T_W_C, one per frame: fixed (e.g. ground truth) when `aligner` is empty;
/// else every iteration refines each frame's pose against that iteration's model before the
/// frame is compared with it, and the refined poses are the next iteration's (poses from a
/// reconstruction of the raw depth are consistent only where the distortion let them be; each
/// frame re-aligned to the model of frames undistorted better is more so).
Result<SelfCalibrationResult> selfCalibrate(const std::vector<DepthImage>& raw,
                                            const PinholeCamera& camera,
                                            const std::vector<Eigen::Isometry3d>& T_W_C,
                                            const SelfCalibrationConfig& config,
                                            const DistortionTable* initial = nullptr,
                                            const IterationObserver& observer = {},
                                            const FrameAligner& aligner = {});

/// How a learned table compares with a reference (e.g. the sensor's measured table).
struct TableComparison {
    /// The global scale divided out of the learned factors first: the median ratio learned /
    /// reference over the covered cells of the 1 m and 3 m bins (the gauge of §7c is arbitrary).
    double scale = 1.0;
    struct Bin {
        size_t cells = 0;                  ///< covered cells with a valid reference factor
        double median_error = 0.0;         ///< median |learned / scale - reference|
        double median_uncalibrated = 0.0;  ///< median |1 - reference| over the same cells
        /// The same after removing from 1/learned - 1/reference (and from 1/reference - 1) its
        /// least-squares affine function of the image coordinates: the part of a table that maps
        /// planes to planes, which no planarity and little of the views' consistency observes.
        double median_error_beyond_projective = 0.0;
        double median_uncalibrated_beyond_projective = 0.0;
    };
    std::array<Bin, DistortionTable::kBins> bins{};
};

/// Compares `learned` with `reference` over the bins `coverage` marks covered.
/// kFailedPrecondition when no covered 1 m or 3 m bin has a valid reference factor.
Result<TableComparison> compareTables(const DistortionTable& learned,
                                      const DistortionEstimate& coverage,
                                      const DistortionTable& reference);

/// |cos| of the viewing angle of each hit of a raycast from camera pose T_V_C: the normal's
/// component along the pixel's unit ray (0 where there is no hit).
Image<float> viewCosines(const tsdf::RaycastResult& ray, const PinholeCamera& camera,
                         const Eigen::Isometry3d& T_V_C);

}  // namespace plumb::calibration
