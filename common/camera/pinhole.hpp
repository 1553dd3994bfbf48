// SPDX-License-Identifier: Apache-2.0
#pragma once

// Pinhole camera: x right, y down, z forward (DESIGN.md). A pixel (u, v) with depth z back-projects
// to p_C = z * ((u - cx)/fx, (v - cy)/fy, 1). A negative fy (ICL-NUIM's y-flip) is allowed: the
// formulas are unchanged and the image is simply mirrored vertically.
//
// Thread-safety: value types; const access from several threads is safe, a write needs
// exclusive access.

#include <Eigen/Core>
#include <string>

#include "common/core/status.hpp"

namespace plumb {

struct PinholeCamera {
    int width = 640;    ///< image width in pixels
    int height = 480;   ///< image height in pixels
    double fx = 525.0;  ///< focal length along x in pixels
    double fy = 525.0;  ///< focal length along y in pixels; may be negative (ICL-NUIM)
    double cx = 319.5;  ///< principal point x in pixels (pixel centres at integers)
    double cy = 239.5;  ///< principal point y in pixels

    /// Projects a camera-frame point (z > 0) to continuous pixel coordinates.
    Eigen::Vector2d project(const Eigen::Vector3d& p_C) const {
        return {fx * p_C.x() / p_C.z() + cx, fy * p_C.y() / p_C.z() + cy};
    }
    /// Back-projects pixel (u, v) at z-depth `depth_m` into the camera frame.
    Eigen::Vector3d unproject(double u, double v, double depth_m) const {
        return {(u - cx) / fx * depth_m, (v - cy) / fy * depth_m, depth_m};
    }
    /// Ray direction through pixel (u, v) with z component 1 (unnormalised): hit t equals z-depth.
    Eigen::Vector3d ray(double u, double v) const { return {(u - cx) / fx, (v - cy) / fy, 1.0}; }

    /// True when the continuous pixel (u, v) rounds to a pixel inside the image.
    bool contains(double u, double v) const {
        return u > -0.5 && v > -0.5 && u < width - 0.5 && v < height - 0.5;
    }
    /// The camera of an image scaled by `factor` (0.5 = one pyramid level down), pixel centres
    /// kept.
    PinholeCamera scaled(double factor) const;
    /// The 3x3 intrinsic matrix K.
    Eigen::Matrix3d K() const;
    /// Ok when sizes are positive and focal lengths finite and non-zero.
    Status validate() const;
    /// "640x480 fx=525 fy=525 cx=319.5 cy=239.5"
    std::string toString() const;
};

/// Named intrinsics presets: "primesense" (525/525/319.5/239.5, Redwood and augmented ICL-NUIM),
/// "icl-nuim" (481.20/-480.00/319.5/239.5), "tum-fr1", "tum-fr2", "tum-fr3" (TUM RGB-D, depth
/// registered to colour), "7-scenes" (585/585/320/240), "ci" (160x120, f/4 of primesense).
Result<PinholeCamera> cameraPreset(const std::string& name);

}  // namespace plumb
