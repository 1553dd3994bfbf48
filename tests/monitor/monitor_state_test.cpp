// SPDX-License-Identifier: Apache-2.0
// The monitor's model: top-view geometry, coverage gaps, pose-graph parsing and the state JSON.

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "common/geometry/polygon.hpp"
#include "tests/monitor/monitor_fixtures.hpp"
#include "tools/monitor/monitor_state.hpp"
#include "tools/monitor/top_view.hpp"

namespace plumb::monitor {
namespace {

using nlohmann::json;

double polygonArea(const std::vector<Eigen::Vector2d>& p) {
    double a = 0;
    for (size_t i = 0; i < p.size(); ++i) {
        const auto& u = p[i];
        const auto& v = p[(i + 1) % p.size()];
        a += u.x() * v.y() - v.x() * u.y();
    }
    return a / 2;
}

TEST(TopView, ConvexHullOfSquareWithInteriorAndCollinearPoints) {
    std::vector<Eigen::Vector2d> pts = {{0, 0},   {2, 0},     {2, 1},   {0, 1}, {1, 0},
                                        {1, 0.5}, {0.3, 0.7}, {2, 0.5}, {0, 0}};
    const auto hull = convexHull(pts);
    ASSERT_EQ(hull.size(), 4u);
    EXPECT_NEAR(polygonArea(hull), 2.0, 1e-12);  // positive: counter-clockwise
}

TEST(TopView, WithoutLayoutUpIsMinusCameraY) {
    const Eigen::Isometry3d T_V_W = viewFromWorld(nullptr);
    EXPECT_NEAR(T_V_W.linear().determinant(), 1.0, 1e-12);
    const Eigen::Vector3d up_V = T_V_W * Eigen::Vector3d(0, -1, 0);
    EXPECT_NEAR((up_V - Eigen::Vector3d::UnitZ()).norm(), 0.0, 1e-12);
    const Eigen::Vector3d forward_V = T_V_W * Eigen::Vector3d(0, 0, 1);
    EXPECT_NEAR(forward_V.z(), 0.0, 1e-12);  // the camera's forward direction lies in the map
}

TEST(TopView, WithLayoutTheViewIsTheLayoutFrame) {
    const Layout layout = testing::roomLayout();
    const Eigen::Isometry3d T_V_W = viewFromWorld(&layout);
    // The first camera sits 0.5 m in +x from the room centre, 1.5 m above the floor.
    const Eigen::Vector3d c_V = T_V_W * Eigen::Vector3d::Zero();
    EXPECT_NEAR((c_V - Eigen::Vector3d(2.5, 1.5, 1.5)).norm(), 0.0, 1e-12);
}

TEST(Coverage, HalfCoveredRoomHasTheOtherHalfAsGaps) {
    // 4 m x 3 m room, 0.25 m cells: 16 x 12 cells. Points at the centres of the cells with x < 2.
    const std::vector<Eigen::Vector2d> room = {{0, 0}, {4, 0}, {4, 3}, {0, 3}};
    std::vector<Eigen::Vector2d> pts;
    for (double x = 0.125; x < 2.0; x += 0.25) {
        for (double y = 0.125; y < 3.0; y += 0.25) pts.push_back({x, y});
    }
    CoverageConfig config;
    config.cell_m = 0.25;
    const CoverageGrid g = computeCoverage(pts, room, config);
    EXPECT_TRUE(g.room_polygon);
    EXPECT_EQ(g.width, 16);
    EXPECT_EQ(g.height, 12);
    EXPECT_EQ(g.cells_of_interest, 192);
    EXPECT_EQ(g.covered_of_interest, 96);
    EXPECT_DOUBLE_EQ(g.coverageFraction(), 0.5);
    ASSERT_EQ(g.gaps.size(), 96u);
    for (const auto& c : g.gaps) EXPECT_GE(c.x(), 8) << c.transpose();
}

TEST(Coverage, WithoutLayoutHolesInsideTheHullAreGaps) {
    // A 2 m x 2 m block of points with a 0.5 m x 0.5 m hole in the middle: 4 of 64 cells.
    std::vector<Eigen::Vector2d> pts;
    for (double x = 0.125; x < 2.0; x += 0.25) {
        for (double y = 0.125; y < 2.0; y += 0.25) {
            if (x > 0.75 && x < 1.25 && y > 0.75 && y < 1.25) continue;
            pts.push_back({x, y});
        }
    }
    const CoverageGrid g = computeCoverage(pts, {}, CoverageConfig{});
    EXPECT_FALSE(g.room_polygon);
    ASSERT_EQ(g.gaps.size(), 4u);
    for (const auto& c : g.gaps) {
        const Eigen::Vector2d centre =
            g.origin_V + g.cell_m * (c.cast<double>().array() + 0.5).matrix();
        EXPECT_NEAR(centre.x(), 1.0, 0.3);
        EXPECT_NEAR(centre.y(), 1.0, 0.3);
    }
}

TEST(PoseGraphJson, ParsesTheRegistrationFormat) {
    const json j = json::parse(testing::poseGraphJsonText(6));
    auto g = poseGraphFromJson(j, "pose_graph.json");
    ASSERT_TRUE(g.isOk()) << g.status().message();
    EXPECT_EQ(g->T_W_F.size(), 6u);
    ASSERT_EQ(g->edges.size(), 7u);  // 5 odometry + 2 loops
    EXPECT_EQ(g->edges[5].kind, "loop");
    EXPECT_TRUE(g->edges[5].kept);
    EXPECT_DOUBLE_EQ(g->edges[5].line_process, 0.9);
    EXPECT_FALSE(g->edges[6].kept);
    EXPECT_EQ(g->edges[6].reason, "line process 0.10 < 0.25");
}

TEST(PoseGraphJson, MalformedContentNamesTheField) {
    json j = json::parse(testing::poseGraphJsonText(4));
    json bad = j;
    bad["edges"][0]["target"] = 9;
    auto r = poseGraphFromJson(bad, "pg");
    ASSERT_FALSE(r.isOk());
    EXPECT_EQ(r.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(r.status().message().find("edges[0].target"), std::string::npos)
        << r.status().message();

    bad = j;
    bad["edges"][1]["kind"] = "magic";
    r = poseGraphFromJson(bad, "pg");
    ASSERT_FALSE(r.isOk());
    EXPECT_NE(r.status().message().find("edges[1].kind"), std::string::npos);

    bad = j;
    bad["edges"][2]["line_process"] = 1.5;
    r = poseGraphFromJson(bad, "pg");
    ASSERT_FALSE(r.isOk());
    EXPECT_NE(r.status().message().find("line_process"), std::string::npos);

    bad = j;
    bad["nodes"][1]["T_W_F"][0][0] = 3.0;  // not a rotation
    r = poseGraphFromJson(bad, "pg");
    ASSERT_FALSE(r.isOk());
    EXPECT_NE(r.status().message().find("nodes[1]"), std::string::npos);

    EXPECT_FALSE(poseGraphFromJson(json::array(), "pg").isOk());
    EXPECT_FALSE(poseGraphFromJson(json{{"nodes", 1}}, "pg").isOk());
}

TEST(MonitorState, JsonHasFragmentsEdgesLayoutDevice) {
    MonitorState state;
    const uint64_t v0 = state.version();
    for (int k = 0; k < 3; ++k) state.addFragment(testing::roomFragment(k), 7, "lcm");
    EXPECT_GT(state.version(), v0);
    json j = state.toJson();
    ASSERT_EQ(j["fragments"].size(), 3u);
    const json& f1 = j["fragments"][1];
    EXPECT_EQ(f1["id"], 1);
    EXPECT_EQ(f1["session"], 7);
    EXPECT_EQ(f1["frames"], json::array({10, 19}));
    EXPECT_EQ(f1["num_points"], testing::roomFragment(1).points_F.size());
    EXPECT_EQ(f1["pose_source"], "odometry");
    // The pose is the fragment's odometry T_W_F.
    const Eigen::Isometry3d T = testing::roomFragment(1).T_W_F;
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) {
            EXPECT_NEAR(f1["pose"][r][c].get<double>(), T.matrix()(r, c), 1e-12);
        }
    }
    EXPECT_GE(f1["outline_V"].size(), 3u);
    // Before a pose graph exists, consecutive fragments imply provisional odometry edges.
    ASSERT_EQ(j["edges"].size(), 2u);
    EXPECT_EQ(j["edges"][0]["source"], 0);
    EXPECT_EQ(j["edges"][0]["target"], 1);
    EXPECT_EQ(j["edges"][0]["provisional"], true);
    EXPECT_TRUE(j["layout"].is_null());
    EXPECT_TRUE(j["device"].is_null());

    messages::DeviceStatus d;
    d.session_id = 7;
    d.fps = 29.5;
    d.tracking = messages::TrackingState::kLost;
    d.frames_processed = 12;
    d.frames_dropped = 4;
    d.spool_fragments = 2;
    state.setDevice(d, 1000, 12);
    state.setLayout(testing::roomLayout());
    auto graph = poseGraphFromJson(json::parse(testing::poseGraphJsonText(3)), "pg");
    ASSERT_TRUE(graph.isOk());
    state.setPoseGraph(*graph);
    j = state.toJson();
    EXPECT_EQ(j["device"]["tracking"], "lost");
    EXPECT_DOUBLE_EQ(j["device"]["fps"].get<double>(), 29.5);
    EXPECT_EQ(j["device"]["frames_dropped"], 4);
    EXPECT_DOUBLE_EQ(j["device"]["processed_fraction"].get<double>(), 0.75);  // 12 of 16
    EXPECT_EQ(j["device"]["spool_fragments"], 2);
    EXPECT_EQ(j["layout"]["room_polygon_V"].size(), 4u);
    EXPECT_EQ(j["layout"]["walls_V"].size(), 4u);
    EXPECT_EQ(j["view"]["frame"], "layout");
    EXPECT_EQ(j["fragments"][2]["pose_source"], "pose_graph");
    // The graph's 2 odometry edges replace the provisional ones (n = 3: no loops).
    ASSERT_EQ(j["edges"].size(), 2u);
    EXPECT_EQ(j["edges"][0]["provisional"], false);
    // In the layout frame a fragment origin is its camera position, (2.5, 1.5) for fragment 0,
    // moved by the graph's 1 cm along the first camera's x axis (x right = -y in L).
    EXPECT_NEAR(j["fragments"][0]["position_V"][0].get<double>(), 2.5, 1e-5);
    EXPECT_NEAR(j["fragments"][0]["position_V"][1].get<double>(), 1.49, 1e-5);
}

TEST(MonitorState, CoverageGrowsAsFragmentsArrive) {
    MonitorState state;
    state.setLayout(testing::roomLayout());
    double last = -1.0;
    for (int k = 0; k < 8; ++k) {
        state.addFragment(testing::roomFragment(k), 1, "store");
        const json j = state.toJson();
        const double fraction = j["coverage"]["fraction"].get<double>();
        EXPECT_GT(fraction, last) << "fragment " << k;
        last = fraction;
        EXPECT_EQ(j["coverage"]["region"], "room_polygon");
        EXPECT_EQ(j["coverage"]["cells_of_interest"], 16 * 12);
    }
    // All eight wedges together cover the floor except the patch the cameras stand around and
    // behind: within walk radius 0.5 m + minimum range 0.3 m of the centre (plus half a cell).
    const json j = state.toJson();
    EXPECT_GT(last, 0.8);
    EXPECT_LT(last, 1.0);
    ASSERT_FALSE(j["coverage"]["gaps"].empty());
    for (const json& gap : j["coverage"]["gaps"]) {
        const double x = 0.25 * (gap[0].get<double>() + 0.5),
                     y = 0.25 * (gap[1].get<double>() + 0.5);
        EXPECT_LT(std::hypot(x - 2.0, y - 1.5), 0.8 + 0.18) << x << " " << y;
    }
}

TEST(MonitorState, ARoomTheLayoutHasNotClosedHasNoRoomCoverage) {
    // The layout of a scan that saw two walls: its outline follows them for half its length
    // and the seen floor's edge for the rest. Coverage against that outline would read complete
    // for any scan, so the room's coverage is unknown; holes in the seen area are still gaps.
    MonitorState state;
    Layout partial = testing::roomLayout();
    std::vector<LayoutPlane> kept;
    for (const LayoutPlane& p : partial.planes) {
        if (p.kind != LayoutPlaneKind::kWall || kept.size() < 4) kept.push_back(p);
    }
    partial.planes = kept;  // floor, ceiling and the first two walls
    ASSERT_EQ(partial.walls().size(), 2u);
    state.setLayout(partial);
    for (int k = 0; k < 8; ++k) state.addFragment(testing::roomFragment(k), 1, "store");
    json j = state.toJson();
    EXPECT_EQ(j["coverage"]["room_closed"], false);
    EXPECT_TRUE(j["coverage"]["room_fraction"].is_null());
    EXPECT_EQ(j["coverage"]["region"], "convex_hull");
    EXPECT_NEAR(j["coverage"]["wall_bounded_fraction"].get<double>(), 0.5, 1e-9);  // 4 + 3 of 14 m

    // The whole room closed by its four walls: coverage against it.
    state.setLayout(testing::roomLayout());
    j = state.toJson();
    EXPECT_EQ(j["coverage"]["room_closed"], true);
    EXPECT_EQ(j["coverage"]["region"], "room_polygon");
    EXPECT_DOUBLE_EQ(j["coverage"]["room_fraction"].get<double>(),
                     j["coverage"]["fraction"].get<double>());
}

TEST(MonitorState, WaitForChangeWakesOnUpdate) {
    MonitorState state;
    const uint64_t v = state.version();
    EXPECT_EQ(state.waitForChange(v, std::chrono::milliseconds(1)), v);  // nothing changed
    state.addError("x");
    EXPECT_EQ(state.waitForChange(v, std::chrono::milliseconds(1)), v + 1);
    // The cached text follows the version.
    uint64_t tv = 0;
    const std::string a = state.toJsonText(&tv);
    EXPECT_EQ(tv, v + 1);
    EXPECT_EQ(json::parse(a)["errors"][0], "x");
}

}  // namespace
}  // namespace plumb::monitor
