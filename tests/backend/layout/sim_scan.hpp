// SPDX-License-Identifier: Apache-2.0
#pragma once

// A simulated scan for layout tests: one loop of the handheld walk round a scene at 0.35 m/s,
// fused with the ground-truth poses (layout_fixtures.hpp), with every fragment's planes.

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "backend/layout/fragment_planes.hpp"
#include "common/layout/layout.hpp"
#include "drivers/sim/sim_source.hpp"
#include "tests/backend/layout/layout_fixtures.hpp"

namespace plumb::testing {

struct SimScan {
    sim::Scene scene;
    Layout gt;  ///< the scene's exact layout
    std::vector<Fragment> fragments;
    std::vector<Eigen::Isometry3d> T_W_F;  ///< ground truth
    std::vector<layout::FragmentPlanes> planes;
    std::vector<Eigen::Vector3d> path_W;  ///< every frame's camera position
};

/// Scans `config`'s scene with its trajectory settings, the frame count set to one loop of the
/// path at `speed_mps` at config.trajectory.rate_hz (slower where the walk turns: a path with
/// tight turns needs a lower figure to close its loop); `frames_per_fragment` consecutive frames
/// make a fragment. Failures are recorded as test failures (the scan is then partial or empty).
inline SimScan scanSimRoom(sim::SimConfig config, int frames_per_fragment,
                           double speed_mps = 0.35) {
    SimScan scan;
    auto scene = sim::resolveScene(config.scene);
    EXPECT_TRUE(scene.isOk()) << scene.status().toString();
    if (!scene.isOk()) return scan;
    auto path = sim::pathControlPoints(*scene);
    EXPECT_TRUE(path.isOk()) << path.status().toString();
    if (!path.isOk()) return scan;
    double perimeter = 0.0;
    for (size_t k = 0; k < path->size(); ++k) {
        perimeter += ((*path)[(k + 1) % path->size()] - (*path)[k]).norm();
    }
    config.trajectory.num_frames =
        static_cast<size_t>(std::ceil(perimeter / speed_mps * config.trajectory.rate_hz));
    auto source = sim::SimSource::create(config);
    EXPECT_TRUE(source.isOk()) << source.status().toString();
    if (!source.isOk()) return scan;
    const sim::SimSource& src = **source;
    scan.scene = src.scene();
    scan.gt = makeRoomLayout(scan.scene.polygon, scan.scene.height_m).value();
    for (const io::StampedPose& p : src.trajectory()) scan.path_W.push_back(p.T_W_C.translation());
    auto fused = fuseWithGroundTruth(
        [&](size_t k) -> Result<Frame> {
            auto f = src.render(k);
            if (!f.isOk()) return f.status();
            return f->frame;
        },
        config.trajectory.num_frames, 1, frames_per_fragment, src.camera());
    EXPECT_TRUE(fused.isOk()) << fused.status().toString();
    if (!fused.isOk()) return scan;
    scan.fragments = std::move(fused->fragments);
    scan.T_W_F = std::move(fused->T_W_F);
    for (const Fragment& f : scan.fragments) {
        auto fp = layout::extractFragmentPlanes(f);
        EXPECT_TRUE(fp.isOk()) << fp.status().toString();
        if (fp.isOk()) scan.planes.push_back(std::move(fp).value());
    }
    return scan;
}

/// `scene` scanned by the default walk with the small "ci" camera at 10 Hz, Redwood noise without
/// the distortion table, fused with the ground-truth poses, 20 frames per fragment, the loop
/// walked at `speed_mps` (scanSimRoom).
inline SimScan scanSimRoomCi(const std::string& scene, double speed_mps = 0.35) {
    sim::SimConfig cfg;
    cfg.scene = scene;
    cfg.camera = cameraPreset("ci").value();
    cfg.noise.distortion = sim::DistortionKind::kNone;
    cfg.trajectory.rate_hz = 10.0;
    return scanSimRoom(cfg, 20, speed_mps);
}

}  // namespace plumb::testing
