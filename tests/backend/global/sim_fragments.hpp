// SPDX-License-Identifier: Apache-2.0
#pragma once

// Test fixture: oriented fragments of a simulated room with exact ground truth. Each fragment is
// the union of a few views along the handheld trajectory (drivers/sim), back-projected with
// axial depth noise (Nguyen et al. 2012, reference §1.4.C) and slightly perturbed normals, in
// the frame of the fragment's first camera. Points keep the primitive label they were cast on.

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "common/fragment/fragment.hpp"
#include "common/layout/layout.hpp"
#include "drivers/sim/scene.hpp"

namespace plumb::testing {

struct SimFragmentsOptions {
    std::string scene = "living_room";
    bool loop = true;
    int num_fragments = 12;
    int frames_per_fragment = 75;
    int views_per_fragment = 5;
    int image_width = 80;   ///< rays per row (a 640x480 camera subsampled)
    int image_height = 60;  ///< rays per column
    double max_depth_m = 5.0;
    double normal_noise_deg = 2.0;
    bool depth_noise = true;
    uint64_t seed = 7;
};

struct SimFragments {
    sim::Scene scene;
    std::vector<Fragment> fragments;          ///< T_W_F = ground truth
    std::vector<Eigen::Isometry3d> T_W_F_gt;  ///< ground-truth fragment poses
    std::vector<std::vector<int>> labels;     ///< primitive label per point, per fragment
    Layout layout_gt;                         ///< from the scene polygon and height, T_W_L = I
};

SimFragments makeSimFragments(const SimFragmentsOptions& options);

/// Random rigid perturbation with rotation angle `angle_deg` and translation `dist_m` about
/// random axes / directions (seeded).
Eigen::Isometry3d randomPerturbation(double angle_deg, double dist_m, uint64_t seed);

/// RMS of the position error of the fragments' views (camera centres T_W_F * T_F_C), no
/// alignment (the gauge is fixed by fragment 0), metres.
double cameraPositionRmse(const SimFragments& sim, const std::vector<Eigen::Isometry3d>& T_W_F);

/// Mean distance of every fragment point (placed with T_W_F) to the ground-truth surface,
/// metres. `label_filter` >= 0 restricts to points with that label.
double meanReconstructionError(const SimFragments& sim, const std::vector<Eigen::Isometry3d>& T_W_F,
                               int label_filter = -1);

}  // namespace plumb::testing
