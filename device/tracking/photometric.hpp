// SPDX-License-Identifier: Apache-2.0
#pragma once

// The photometric term of RGB-D tracking (reference §7b.1; Steinbrucker, Sturm, Cremers 2011;
// Kerl, Sturm, Cremers 2013). A reference frame R (an earlier tracked frame: its intensity and its
// depth) is warped into the current camera C; the residual of a reference pixel with 3-D point
// p_R and intensity I_R(u) is
//
//   r(u) = a I_C(pi(T_C_R p_R)) + b - I_R(u)                                       (7b.1)
//
// with (a, b) an affine brightness model of C against R (exposure and gain changes). With the
// left update T_M_C <- Exp(xi) T_M_C of the tracker and q = T_M_R p_R fixed in the model frame M,
// p_C = T_C_M Exp(-xi) q, so d p_C / d xi = R_C_M [ [q]_x , -I ]. With g = a (d pi / d p)^T
// grad I_C, the gradient pulled back to a 3-vector in C, and h = R_M_C g:
//
//   J = [ (h x q)^T , -h^T ]                                         (rotation first, as in §0)
//
// Pixels are selected DVO-style where the reference gradient is strong; residuals get Huber
// weights. Algorithms only; no I/O.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/core/status.hpp"
#include "common/geometry/lie.hpp"
#include "common/image/image.hpp"
#include "device/preprocess/preprocess.hpp"

namespace plumb::device {

struct PhotometricConfig {
    /// Track with the photometric term when the frame has colour (depth-only otherwise).
    bool enabled = true;
    /// Relative weight lambda of the photometric term: the tracker minimises
    /// sum (r_icp / depth_sigma_m)^2 + lambda sum rho(r / intensity_sigma)^2, unit-free.
    double weight = 0.1;
    /// Scale of the point-to-plane residual that the photometric term is weighed against, metres.
    double depth_sigma_m = 0.01;
    /// Scale of the intensity residual (intensities in [0, 1]).
    double intensity_sigma = 0.03;
    /// Huber threshold of the intensity residual: beyond it a residual counts linearly.
    float huber_delta = 0.05f;
    /// Residuals above this are occlusions or specularities and are left out (intensity).
    float max_residual = 0.3f;
    /// A reference pixel is used where |grad I| (central differences on the smoothed image,
    /// intensity per pixel of its level) is at least this.
    float min_gradient = 0.01f;
    /// At most this many reference points per pyramid level (taken evenly over the selected
    /// pixels); bounds the cost of one iteration.
    int max_points = 8000;
    /// Fewer selected reference points than this at the finest level: the frame is tracked by
    /// depth only ("too little texture").
    int min_points = 400;
    /// After alignment, when fewer than this fraction of the reference points that land in the
    /// image have |r| <= huber_delta (exposure jump, blur, moving objects), the frame is tracked
    /// again by depth only.
    double min_inlier_fraction = 0.4;
    /// Estimate the affine brightness (a, b) of each frame against its reference.
    bool affine_brightness = true;
    /// Standard deviation of the Gaussian that smooths the intensity before gradients, pixels.
    float smoothing_sigma_px = 1.0f;

    Status validate() const;
};

/// One level of a frame's intensity pyramid, with the same camera as the depth level.
struct IntensityLevel {
    PinholeCamera camera;
    Image<float> intensity;  ///< smoothed intensity in [0, 1]
    Image<float> grad_u;     ///< dI/du, intensity per pixel (central differences)
    Image<float> grad_v;     ///< dI/dv
};

/// A level from an intensity image (already smoothed): its central-difference gradients.
/// `num_threads` workers (0 = TBB default); the result does not depend on it.
IntensityLevel makeIntensityLevel(const PinholeCamera& camera, Image<float> intensity,
                                  int num_threads = 0);

/// Intensity pyramid of a colour image registered to `frame`'s depth: level 0 is the smoothed
/// full-resolution intensity, each next level the 2x2 mean of the finer one (pixel centres kept,
/// as PinholeCamera::scaled), as many levels as `frame` has. `colour` must have the size of
/// level 0 (checked by the caller).
std::vector<IntensityLevel> buildIntensityPyramid(const ColourImage& colour,
                                                  const FramePyramid& frame,
                                                  const PhotometricConfig& config,
                                                  int num_threads = 0);

/// A selected reference pixel: its point in the reference camera R and its intensity.
struct ReferencePoint {
    Eigen::Vector3f p_R;
    float intensity;
};

/// Reference points at every pyramid level of one frame (its depth points and intensity).
struct PhotometricReference {
    std::vector<std::vector<ReferencePoint>> levels;  ///< level 0 = full resolution
    /// Per level, selected pixels / kept points (>= 1): the kept points' sums are scaled by it
    /// so that the term weighs every selected pixel, whatever max_points.
    std::vector<double> level_scale;
    size_t num_selected = 0;  ///< selected pixels at level 0 before thinning to max_points
};

/// Selects the reference points of a tracked frame: pixels with a valid depth point and
/// |grad I| >= min_gradient, at most max_points per level. `num_threads` workers (0 = TBB
/// default); the result does not depend on it.
PhotometricReference selectReference(const FramePyramid& frame,
                                     const std::vector<IntensityLevel>& intensity,
                                     const PhotometricConfig& config, int num_threads = 0);

/// Affine brightness of the current frame against the reference: I_R ~ a I_C + b.
struct Brightness {
    double a = 1.0;
    double b = 0.0;
};

/// Normal equations of the photometric term at one level, Huber-weighted, unscaled (the caller
/// applies the weight). Also the statistics for the next brightness estimate.
struct PhotometricSystem {
    Matrix6d JtJ = Matrix6d::Zero();
    Vector6d Jtr = Vector6d::Zero();
    double r2 = 0.0;         ///< sum of weighted squared residuals
    size_t num_visible = 0;  ///< reference points that land in the current image
    size_t num_used = 0;     ///< of them, with |r| <= max_residual (in the system)
    size_t num_inliers = 0;  ///< of them, with |r| <= huber_delta
    Brightness brightness;   ///< least-squares (a, b) over the used points at this pose
};

/// Builds the system at pose T_M_C for reference points seen from T_M_R, with brightness `br`.
/// Deterministic for every thread count.
PhotometricSystem buildPhotometricSystem(const std::vector<ReferencePoint>& reference,
                                         const IntensityLevel& current,
                                         const Eigen::Isometry3d& T_M_R,
                                         const Eigen::Isometry3d& T_M_C, const Brightness& br,
                                         const PhotometricConfig& config, int num_threads = 0);

/// The residual (7b.1) and its Jacobian for one reference point, as buildPhotometricSystem
/// computes them; false when the point does not land inside the image. For tests.
bool photometricResidual(const ReferencePoint& point, const IntensityLevel& current,
                         const Eigen::Isometry3d& T_M_R, const Eigen::Isometry3d& T_M_C,
                         const Brightness& br, double* r, Vector6d* J);

/// Bilinear sample of `image` at continuous pixel (x, y) (integers at pixel centres); false
/// outside [0, w-1] x [0, h-1].
bool sampleBilinear(const Image<float>& image, float x, float y, float* value);

}  // namespace plumb::device
