// SPDX-License-Identifier: Apache-2.0
// Layout estimation on a simulated U-shaped room (u_room.toml): the path of each arm lies behind
// a side wall of the notch between the arms, within the wall's extent but across the notch,
// outside the room; and the notch's west side wall is coplanar with the end of a sideboard across
// the hall, whose top the lines of sight pass over. Rule a ("camera behind it") and the top test
// (estimate_layout.hpp) must look only along the pieces a wall's points cover and count only
// camera positions that face it across the room. The two arms' ends lie on one plane and must be
// two walls of the layout, each with its own segment.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "backend/layout/estimate_layout.hpp"
#include "common/eval/layout_metrics.hpp"
#include "drivers/sim/sim_source.hpp"
#include "tests/backend/layout/sim_scan.hpp"

namespace plumb::layout {
namespace {

/// One loop of the walk at 0.25 m/s (the walk slows at the arms' ends and the notch and needs
/// that to close its loop), scanned as scanSimRoomCi does.
const testing::SimScan& uRoomScan() {
    static const testing::SimScan scan = testing::scanSimRoomCi(PLUMB_U_ROOM_SCENE, 0.25);
    return scan;
}

/// The ids of the ground-truth walls on the line x = x0 (axis 0) or y = x0 (axis 1) of the scene:
/// the notch's side walls run along x = 1.7 and 3.5, the ends of both arms along y = 4.2.
std::vector<int> gtWallsOnLine(const Layout& gt, int axis, double x0) {
    std::vector<int> ids;
    for (const LayoutPlane* w : gt.walls()) {
        if (std::abs(w->start_L[axis] - x0) < 1e-6 && std::abs(w->end_L[axis] - x0) < 1e-6) {
            ids.push_back(w->id);
        }
    }
    return ids;
}

/// The ids of the ground-truth walls matched by estimated walls within 1 degree and 3 cm.
std::vector<int> matchedGtWalls(const eval::LayoutMetrics& m) {
    std::vector<int> ids;
    for (const eval::PlaneError& e : m.walls) {
        if (e.angle_error_deg <= 1.0 && std::abs(e.offset_error_m) <= 0.03) ids.push_back(e.gt_id);
    }
    return ids;
}

bool contains(const std::vector<int>& ids, int id) {
    return std::find(ids.begin(), ids.end(), id) != ids.end();
}

TEST(URoomLayout, TheNotchSideWallsAreWallsAndTheArmsEndsTwoWalls) {
    const testing::SimScan& scan = uRoomScan();
    ASSERT_FALSE(scan.fragments.empty());
    const std::vector<int> west = gtWallsOnLine(scan.gt, 0, 1.7);
    const std::vector<int> ends = gtWallsOnLine(scan.gt, 1, 4.2);
    ASSERT_EQ(west.size(), 1u);
    ASSERT_EQ(ends.size(), 2u);

    // The premise: the east arm's path lies behind the west side wall (x > 1.8) within its
    // extent (2.4 <= y <= 4.2), far more than rule a tolerates.
    int within = 0, behind = 0;
    for (const Eigen::Vector3d& c : scan.path_W) {
        if (c.y() < 2.4 || c.y() > 4.2) continue;
        ++within;
        behind += c.x() > 1.8 ? 1 : 0;
    }
    LayoutConfig cfg;
    ASSERT_GT(within, 0);
    EXPECT_GT(static_cast<double>(behind) / within, 3.0 * cfg.max_camera_behind_fraction);

    auto est = estimateLayout(scan.fragments, scan.planes, scan.T_W_F, cfg);
    ASSERT_TRUE(est.isOk()) << est.status().toString();
    for (const WallDecision& w : est->diagnostics.walls) {
        std::printf("plane %d: %s (camera behind %.2f, top gap %.2f m, top seen over %.2f)\n",
                    w.plane_id, w.reason.c_str(), w.camera_behind_fraction, w.top_gap_m,
                    w.top_seen_fraction);
    }
    auto m = eval::evaluateLayout(est->layout, scan.gt);
    ASSERT_TRUE(m.isOk()) << m.status().toString();
    for (const eval::PlaneError& e : m->walls) {
        std::printf("gt wall %d: estimated %d, %.2f deg, %.3f m\n", e.gt_id, e.est_id,
                    e.angle_error_deg, e.offset_error_m);
    }
    const std::vector<int> matched = matchedGtWalls(*m);
    // No wall at furniture: every estimated wall is one of the room's, within 1 degree and 3 cm.
    EXPECT_TRUE(m->unmatched_est_walls.empty());
    EXPECT_EQ(matched.size(), m->walls.size());
    // The west side wall of the notch: the east arm's path behind it, and a sideboard's end on
    // its plane across the hall, whose top the lines of sight pass over.
    EXPECT_TRUE(contains(matched, west[0]));
    // The ends of both arms lie on one plane; each is a wall of the layout, with its own segment.
    EXPECT_TRUE(contains(matched, ends[0]));
    EXPECT_TRUE(contains(matched, ends[1]));
    EXPECT_GE(matched.size(), 6u);

    // One wall per plane (the plane's longest edge) leaves one of the arms' ends out.
    cfg.wall_split_min_edge_m = 0.0;
    auto single = estimateLayout(scan.fragments, scan.planes, scan.T_W_F, cfg);
    ASSERT_TRUE(single.isOk()) << single.status().toString();
    auto ms = eval::evaluateLayout(single->layout, scan.gt);
    ASSERT_TRUE(ms.isOk()) << ms.status().toString();
    const std::vector<int> matched_single = matchedGtWalls(*ms);
    EXPECT_FALSE(contains(matched_single, ends[0]) && contains(matched_single, ends[1]));
}

}  // namespace
}  // namespace plumb::layout
