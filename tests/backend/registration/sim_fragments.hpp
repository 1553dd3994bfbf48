// SPDX-License-Identifier: Apache-2.0
#pragma once

// Fragments of a simulated loop scan of `living_room` for the registration tests: the device
// FragmentBuilder over the simulator (160x120, Redwood noise without the distortion table), with
// ground truth. Generated once and cached in the temp directory (encoded with the fragment codec;
// every test uses the decoded copy, so cached and fresh runs see identical input).

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "common/io/trajectory.hpp"

namespace plumb::testing {

struct SimScan {
    std::vector<Fragment> fragments;
    /// Ground-truth camera -> world pose of each frame (by frame index).
    io::Trajectory gt_frames;
    /// Ground-truth fragment -> world poses (the GT pose of each fragment's first frame).
    std::vector<Eigen::Isometry3d> gt_T_W_F;
};

struct SimScanOptions {
    std::string scene = "living_room";
    size_t num_frames = 330;
    double rate_hz = 15.0;
    int frames_per_fragment = 25;
    bool loop = true;
    uint64_t seed = 7;
    /// Camera preset and TSDF of the device: half the sensor's resolution and 1 cm voxels (at
    /// 160x120 and 2 cm the TSDF's rounded edges bias the roll of fronto-parallel views and
    /// fragments came out turned by 10-13 degrees, which no registration can undo).
    std::string camera = "qvga";
    float voxel_size_m = 0.01f;
    float truncation_m = 0.04f;
};

/// The scan (cached under temp_directory_path()/plumb-registration-cache).
Result<SimScan> simLoopScan(const SimScanOptions& options = {});

}  // namespace plumb::testing
