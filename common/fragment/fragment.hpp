// SPDX-License-Identifier: Apache-2.0
#pragma once

// A fragment: the surface fused from a run of consecutive frames (default 50), in its own frame F
// = the camera frame of its first frame (reference §2.7). The device produces fragments; the
// backend registers them. Everything needed to re-integrate the raw frames later is kept.
//
// Thread-safety: value types; const access from several threads is safe, a write needs
// exclusive access.

#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "common/cloud/point_cloud.hpp"
#include "common/geometry/lie.hpp"

namespace plumb {

/// Why a fragment was closed.
enum class FragmentEnd : uint8_t {
    kFrameCount = 0,    ///< reached the configured number of frames
    kTrackingLost = 1,  ///< tracking failed; closed early and marked
    kBlockBudget = 2,   ///< the TSDF block budget was reached; closed early
    kEndOfStream = 3,   ///< the source ended (or the sensor vanished)
};

const char* toString(FragmentEnd end);

struct FragmentFrame {
    int64_t frame_index = 0;   ///< index of the frame in the capture stream
    double timestamp_s = 0.0;  ///< capture time, seconds
    /// Camera -> fragment pose from tracking (T_F_C of the first frame is the identity).
    Eigen::Isometry3d T_F_C = Eigen::Isometry3d::Identity();
    bool tracking_ok = true;  ///< false when tracking failed on this frame (not integrated)
};

struct Fragment {
    uint32_t id = 0;       ///< 0-based, consecutive within a session
    uint32_t segment = 0;  ///< tracking segment; a restart after loss begins a new segment
    FragmentEnd end = FragmentEnd::kFrameCount;
    /// Fragment -> world pose from odometry (T_W_F of fragment 0 is the identity).
    Eigen::Isometry3d T_W_F = Eigen::Isometry3d::Identity();
    PointCloud points_F;                ///< oriented surface points in the fragment frame, metres
    std::vector<FragmentFrame> frames;  ///< the frames fused into this fragment, in order
    double voxel_size_m = 0.0;          ///< TSDF voxel size the surface was extracted at
    /// Mean ICP inlier fraction over the fragment's frames, in [0, 1] (1 for the first frame).
    double tracking_quality = 1.0;
    /// How well the tracker observed this fragment's pose relative to the previous fragment of
    /// its segment: J^T J (rotation first, 1 / m^2 of point-to-plane residual, the photometric
    /// term weighed in) of the alignment of this fragment's first frame to the previous
    /// fragment's model, for the left perturbation T_P_F <- Exp(xi) T_P_F in the previous
    /// fragment's frame P. Along a plain corridor without colour its translation block is
    /// nearly singular. Zero when unknown (the first fragment of a segment, older data).
    Matrix6d odometry_information = Matrix6d::Zero();
};

}  // namespace plumb
