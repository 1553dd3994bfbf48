// SPDX-License-Identifier: Apache-2.0
#pragma once

// Fragments for layout tests: depth frames fused with their ground-truth poses into TSDF
// fragments (common/tsdf), one fragment per run of consecutive frames, each in the frame of its
// first camera (reference §2.7), as the device would cut them but without tracking error.

#include <Eigen/Geometry>
#include <functional>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "common/frame/frame_source.hpp"
#include "common/tsdf/surface.hpp"
#include "common/tsdf/tsdf_volume.hpp"

namespace plumb::testing {

struct FusedFragments {
    std::vector<Fragment> fragments;
    std::vector<Eigen::Isometry3d> T_W_F;  ///< ground truth
};

/// Fuses frames [0, num_frames) (every `step`-th) returned by `frame(k)` with their GT poses.
inline Result<FusedFragments> fuseWithGroundTruth(const std::function<Result<Frame>(size_t)>& frame,
                                                  size_t num_frames, size_t step,
                                                  int frames_per_fragment,
                                                  const PinholeCamera& camera,
                                                  float voxel_m = 0.02f, float max_depth_m = 4.0f) {
    FusedFragments out;
    tsdf::TsdfConfig tc;
    tc.voxel_size_m = voxel_m;
    tc.truncation_m = 3.0f * voxel_m;
    tc.max_depth_m = max_depth_m;
    tsdf::SurfaceConfig sc;
    std::unique_ptr<tsdf::TsdfVolume> volume;
    Fragment current;
    int in_fragment = 0;
    auto close = [&]() {
        if (in_fragment == 0) return;
        current.points_F = tsdf::extractSurfacePoints(*volume, sc);
        current.voxel_size_m = voxel_m;
        if (!current.points_F.empty()) {  // a short tail run may have no twice-seen voxels
            current.id = static_cast<uint32_t>(out.fragments.size());
            out.T_W_F.push_back(current.T_W_F);
            out.fragments.push_back(std::move(current));
        }
        current = Fragment();
        in_fragment = 0;
    };
    for (size_t k = 0; k < num_frames; k += step) {
        Result<Frame> f = frame(k);
        if (!f.isOk()) return f.status();
        if (!f->T_W_C_gt) continue;  // e.g. TUM frames before the motion capture starts
        if (in_fragment == 0) {
            volume = std::make_unique<tsdf::TsdfVolume>(tc);
            current.id = static_cast<uint32_t>(out.fragments.size());
            current.T_W_F = *f->T_W_C_gt;
        }
        const Eigen::Isometry3d T_F_C = current.T_W_F.inverse() * *f->T_W_C_gt;
        auto stats = volume->integrate(f->depth, camera, T_F_C);
        if (!stats.isOk()) return stats.status();
        FragmentFrame ff;
        ff.frame_index = f->index;
        ff.timestamp_s = f->timestamp_s;
        ff.T_F_C = T_F_C;
        current.frames.push_back(ff);
        if (++in_fragment == frames_per_fragment) close();
    }
    close();
    return out;
}

}  // namespace plumb::testing
