// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>

#include "common/eval/layout_metrics.hpp"
#include "common/geometry/lie.hpp"
#include "common/layout/layout.hpp"
#include "common/layout/layout_json.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

std::vector<Eigen::Vector2d> lShapedRoom() {
    // Counter-clockwise seen from above: a 4 x 3 m rectangle with a 1.5 x 1 m notch.
    return {{0.0, 0.0}, {4.0, 0.0}, {4.0, 3.0}, {1.5, 3.0}, {1.5, 2.0}, {0.0, 2.0}};
}

TEST(Layout, RoomFromPolygonHasInwardWallsFloorAndCeiling) {
    const auto polygon = lShapedRoom();
    auto layout = makeRoomLayout(polygon, 2.6);
    ASSERT_TRUE(layout.isOk()) << layout.status().toString();
    ASSERT_EQ(layout->planes.size(), polygon.size() + 2);
    const LayoutPlane* floor = layout->firstOf(LayoutPlaneKind::kFloor);
    const LayoutPlane* ceiling = layout->firstOf(LayoutPlaneKind::kCeiling);
    ASSERT_NE(floor, nullptr);
    ASSERT_NE(ceiling, nullptr);
    EXPECT_EQ(floor->normal_L, Eigen::Vector3d(0, 0, 1));
    EXPECT_EQ(floor->d_L, 0.0);
    EXPECT_EQ(ceiling->normal_L, Eigen::Vector3d(0, 0, -1));
    EXPECT_EQ(ceiling->d_L, 2.6);
    EXPECT_DOUBLE_EQ(layout->ceiling_height_m, 2.6);

    // A point inside the room is on the positive side of every plane; its distance to each wall
    // is known in closed form.
    const Eigen::Vector3d inside(3.0, 1.0, 1.2);
    const auto walls = layout->walls();
    ASSERT_EQ(walls.size(), polygon.size());
    const double expected[] = {1.0, 1.0, 2.0, 1.5, 1.0, 3.0};  // edges 0..5
    for (size_t k = 0; k < walls.size(); ++k) {
        const LayoutPlane& w = *walls[k];
        EXPECT_EQ(w.id, static_cast<int>(2 + k));
        EXPECT_NEAR(w.normal_L.norm(), 1.0, 1e-15);
        EXPECT_EQ(w.normal_L.z(), 0.0);
        EXPECT_NEAR(w.normal_L.dot(inside) + w.d_L, expected[k], 1e-12) << "wall " << k;
        // The segment endpoints lie on the wall plane.
        EXPECT_NEAR(w.normal_L.head<2>().dot(w.start_L) + w.d_L, 0.0, 1e-12);
        EXPECT_NEAR(w.normal_L.head<2>().dot(w.end_L) + w.d_L, 0.0, 1e-12);
        EXPECT_EQ(w.start_L, polygon[k]);
        EXPECT_EQ(w.end_L, polygon[(k + 1) % polygon.size()]);
    }
    EXPECT_NEAR(floor->normal_L.dot(inside) + floor->d_L, 1.2, 1e-12);
    EXPECT_NEAR(ceiling->normal_L.dot(inside) + ceiling->d_L, 1.4, 1e-12);
}

TEST(Layout, RoomFromPolygonRejectsBadInput) {
    auto cw = lShapedRoom();
    std::reverse(cw.begin(), cw.end());
    auto r = makeRoomLayout(cw, 2.5);
    ASSERT_FALSE(r.isOk());
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(r.status().message().find("clockwise"), std::string::npos);

    EXPECT_FALSE(makeRoomLayout({{0, 0}, {1, 0}}, 2.5).isOk());
    EXPECT_FALSE(makeRoomLayout(lShapedRoom(), 0.0).isOk());
    EXPECT_FALSE(makeRoomLayout(lShapedRoom(), std::nan("")).isOk());
    // Positive signed area, but edge 2 crosses edge 0.
    auto crossing = makeRoomLayout({{0, 0}, {4, 0}, {4, 3}, {2, -1}, {0, 3}}, 2.5);
    ASSERT_FALSE(crossing.isOk());
    EXPECT_NE(crossing.status().message().find("edges 0 and 2 intersect"), std::string::npos);
    auto repeated = makeRoomLayout({{0, 0}, {1, 0}, {1, 0}, {1, 1}}, 2.5);
    ASSERT_FALSE(repeated.isOk());
    EXPECT_NE(repeated.status().message().find("shorter than 1 mm"), std::string::npos);
}

TEST(Layout, PolygonEdgesKnowTheWallsThatBoundThem) {
    // The full room: every edge on its own wall (ids 2 + k), the whole perimeter bounded.
    Layout room = makeRoomLayout(lShapedRoom(), 2.6).value();
    const std::vector<int> all = polygonEdgeWalls(room);
    ASSERT_EQ(all.size(), 6u);
    for (size_t k = 0; k < all.size(); ++k) EXPECT_EQ(all[k], static_cast<int>(2 + k));
    EXPECT_DOUBLE_EQ(wallBoundedFraction(room), 1.0);

    // Only the walls along y = 0 and x = 4 were seen: the two edges on them are bounded, the
    // rest of the outline (the seen floor's edge) is not. Perimeter 14 m, 4 + 3 m on walls.
    Layout partial = room;
    partial.planes.erase(partial.planes.begin() + 4, partial.planes.end());
    const std::vector<int> seen = polygonEdgeWalls(partial);
    EXPECT_EQ(seen, (std::vector<int>{2, 3, -1, -1, -1, -1}));
    EXPECT_NEAR(wallBoundedFraction(partial), 7.0 / 14.0, 1e-12);

    // A wall's line alone is not enough: an edge beyond the wall's segment is not on it, nor
    // is one 10 cm off the line.
    Layout shifted = room;
    shifted.planes[2].end_L = {1.0, 0.0};  // the y = 0 wall spans x in [0, 1] only
    shifted.planes[3].d_L -= 0.10;         // the x = 4 wall moved 10 cm
    const std::vector<int> off = polygonEdgeWalls(shifted);
    EXPECT_EQ(off[0], -1);  // the edge's midpoint, x = 2, lies beyond the wall's [0, 1]
    EXPECT_EQ(off[1], -1);
    EXPECT_EQ(off[2], 4);  // the others keep their walls
}

TEST(Layout, PlaneTransformKeepsPointsOnThePlane) {
    const HessianPlane plane_A{Eigen::Vector3d(1, 2, 2).normalized(), -0.7};
    Vector6d xi;
    xi << 0.3, -0.2, 0.9, 1.5, -2.0, 0.4;
    const Eigen::Isometry3d T_B_A = lie::expSE3(xi);
    const HessianPlane plane_B = transformPlane(plane_A, T_B_A);
    // Points on the plane in A map to points on the plane in B; offsets along n are preserved.
    const Eigen::Vector3d u = plane_A.normal.unitOrthogonal();
    const Eigen::Vector3d v = plane_A.normal.cross(u);
    const Eigen::Vector3d on_A = -plane_A.d * plane_A.normal + 0.8 * u - 1.3 * v;
    for (double offset : {0.0, 0.25, -1.0}) {
        const Eigen::Vector3d x_A = on_A + offset * plane_A.normal;
        EXPECT_NEAR(plane_B.signedDistance(T_B_A * x_A), offset, 1e-12);
    }
    const HessianPlane back = transformPlane(plane_B, T_B_A.inverse());
    EXPECT_NEAR((back.normal - plane_A.normal).norm(), 0.0, 1e-12);
    EXPECT_NEAR(back.d, plane_A.d, 1e-12);
}

Layout awkwardLayout() {
    Layout layout = makeRoomLayout(lShapedRoom(), 2.6).value();
    Vector6d xi;
    xi << 0.01, -0.02, 1.1, 0.1234567890123, -3.3, 0.7;
    layout.T_W_L = lie::expSE3(xi);
    layout.planes[3].manhattan_snapped = true;
    layout.planes[4].d_L = 1.0 / 3.0;
    layout.planes[5].normal_L = Eigen::Vector3d(0.1, 0.7, -0.3).normalized();
    layout.planes[6].start_L = {M_PI, -std::exp(1.0)};
    layout.planes[7].id = 42;
    return layout;
}

void expectSameLayout(const Layout& a, const Layout& b) {
    EXPECT_EQ(a.T_W_L.matrix(), b.T_W_L.matrix());
    EXPECT_EQ(a.ceiling_height_m, b.ceiling_height_m);
    EXPECT_EQ(a.room_polygon_L, b.room_polygon_L);
    ASSERT_EQ(a.planes.size(), b.planes.size());
    for (size_t i = 0; i < a.planes.size(); ++i) {
        EXPECT_EQ(a.planes[i].id, b.planes[i].id);
        EXPECT_EQ(a.planes[i].kind, b.planes[i].kind);
        EXPECT_EQ(a.planes[i].normal_L, b.planes[i].normal_L);  // bit-exact
        EXPECT_EQ(a.planes[i].d_L, b.planes[i].d_L);
        EXPECT_EQ(a.planes[i].start_L, b.planes[i].start_L);
        EXPECT_EQ(a.planes[i].end_L, b.planes[i].end_L);
        EXPECT_EQ(a.planes[i].manhattan_snapped, b.planes[i].manhattan_snapped);
    }
}

TEST(LayoutJson, RoundTripIsBitExact) {
    const auto dir = testing::freshTempDir("layout_json_round_trip");
    const Layout layout = awkwardLayout();
    ASSERT_TRUE(io::writeLayoutJson(dir / "layout.json", layout).isOk());
    auto back = io::readLayoutJson(dir / "layout.json");
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    expectSameLayout(layout, *back);
    // The file carries the format tag.
    std::ifstream in(dir / "layout.json");
    const auto doc = nlohmann::json::parse(in);
    EXPECT_EQ(doc.at("format"), "plumb-layout-1");
    EXPECT_EQ(doc.at("planes").at(0).at("kind"), "floor");
}

TEST(LayoutJson, AnUnseenCeilingIsNullNotZero) {
    Layout layout = awkwardLayout();
    layout.ceiling_height_m = 0.0;  // the ceiling was never seen
    const nlohmann::json doc = io::layoutToJson(layout);
    EXPECT_TRUE(doc.at("ceiling_height_m").is_null()) << doc.at("ceiling_height_m");
    auto back = io::layoutFromJson(doc, "test.json");
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    expectSameLayout(layout, *back);
    // Files written before null was used (0 for unknown) still read.
    nlohmann::json old = doc;
    old["ceiling_height_m"] = 0.0;
    auto old_back = io::layoutFromJson(old, "old.json");
    ASSERT_TRUE(old_back.isOk()) << old_back.status().toString();
    EXPECT_EQ(old_back->ceiling_height_m, 0.0);
    // A seen ceiling is a number.
    EXPECT_EQ(io::layoutToJson(awkwardLayout()).at("ceiling_height_m"), 2.6);
}

/// Parses `doc` after `edit` and returns the error.
Status errorAfter(const std::function<void(nlohmann::json&)>& edit) {
    nlohmann::json doc = io::layoutToJson(awkwardLayout());
    edit(doc);
    auto r = io::layoutFromJson(doc, "test.json");
    return r.isOk() ? Status::ok() : r.status();
}

TEST(LayoutJson, MalformedContentNamesTheField) {
    struct Case {
        std::function<void(nlohmann::json&)> edit;
        StatusCode code;
        std::string message_part;
    };
    const std::vector<Case> cases = {
        {[](auto& j) { j.erase("format"); }, StatusCode::kCorrupt, "missing field \"format\""},
        {[](auto& j) { j["format"] = "plumb-layout-9"; }, StatusCode::kUnsupported,
         "plumb-layout-9"},
        {[](auto& j) { j.erase("T_W_L"); }, StatusCode::kCorrupt, "\"T_W_L\""},
        {[](auto& j) { j["T_W_L"][0][0] = 2.0; }, StatusCode::kCorrupt, "T_W_L: rotation"},
        {[](auto& j) { j["T_W_L"][3][0] = 1.0; }, StatusCode::kCorrupt, "last row"},
        {[](auto& j) { j["ceiling_height_m"] = "high"; }, StatusCode::kCorrupt,
         "test.json.ceiling_height_m: expected a number"},
        {[](auto& j) { j["room_polygon_L"][2] = {1.0}; }, StatusCode::kCorrupt,
         "room_polygon_L[2]"},
        {[](auto& j) { j["planes"][3].erase("d_L"); }, StatusCode::kCorrupt,
         "test.json.planes[3]: missing field \"d_L\""},
        {[](auto& j) { j["planes"][2]["kind"] = "door"; }, StatusCode::kCorrupt,
         "planes[2].kind: unknown layout plane kind 'door'"},
        {[](auto& j) {
             j["planes"][4]["normal_L"] = {0.0, 0.0, 2.0};
         },
         StatusCode::kCorrupt, "planes[4].normal_L: normal has length 2"},
        {[](auto& j) { j["planes"][1]["normal_L"][1] = nullptr; }, StatusCode::kCorrupt,
         "planes[1].normal_L[1]: expected a number"},
        {[](auto& j) { j["planes"][0]["id"] = 1.5; }, StatusCode::kCorrupt,
         "planes[0].id: expected an integer"},
        {[](auto& j) { j["planes"][0]["manhattan_snapped"] = 1; }, StatusCode::kCorrupt,
         "manhattan_snapped"},
        {[](auto& j) { j["planes"] = 3; }, StatusCode::kCorrupt, "expected an array of planes"},
    };
    for (size_t i = 0; i < cases.size(); ++i) {
        const Status s = errorAfter(cases[i].edit);
        EXPECT_EQ(s.code(), cases[i].code) << "case " << i << ": " << s.toString();
        EXPECT_NE(s.message().find(cases[i].message_part), std::string::npos)
            << "case " << i << ": " << s.toString();
    }
}

TEST(LayoutJson, FileErrorsAreSpecific) {
    const auto dir = testing::freshTempDir("layout_json_errors");
    auto missing = io::readLayoutJson(dir / "nope.json");
    ASSERT_FALSE(missing.isOk());
    EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
    EXPECT_NE(missing.status().message().find("nope.json"), std::string::npos);

    std::ofstream(dir / "bad.json") << "{\"format\": \"plumb-layout-1\", ";
    auto bad = io::readLayoutJson(dir / "bad.json");
    ASSERT_FALSE(bad.isOk());
    EXPECT_EQ(bad.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(bad.status().message().find("invalid JSON"), std::string::npos);

    std::ofstream(dir / "array.json") << "[1, 2]";
    auto array = io::readLayoutJson(dir / "array.json");
    ASSERT_FALSE(array.isOk());
    EXPECT_NE(array.status().message().find("expected a JSON object"), std::string::npos);

    EXPECT_EQ(io::writeLayoutJson(dir / "no_such_dir" / "x.json", Layout{}).code(),
              StatusCode::kIoError);
}

// ---- layout metrics ----

LayoutPlane* planeWithId(Layout* layout, int id) {
    for (LayoutPlane& p : layout->planes) {
        if (p.id == id) return &p;
    }
    return nullptr;
}

/// A 5 x 4 x 2.7 m ground truth placed in the world by G, and an estimate with known errors
/// expressed in its own layout frame X.
struct PerturbedRoom {
    Layout gt;
    Layout est;
    double wall_rotation_deg = 2.0;
    double wall_shift_m = 0.03;
    double floor_tilt_deg = 1.0;
    double ceiling_raise_m = 0.05;
};

PerturbedRoom perturbedRoom() {
    PerturbedRoom r;
    r.gt = makeRoomLayout({{0, 0}, {5, 0}, {5, 4}, {0, 4}}, 2.7).value();
    Vector6d g, x;
    g << 0.0, 0.0, 0.4, 1.0, -2.0, 0.1;
    x << 0.2, -0.1, 2.0, -3.0, 0.5, 1.2;
    r.gt.T_W_L = lie::expSE3(g);
    // Perturb a copy in L_gt, then re-express it in L_est.
    Layout e = r.gt;
    const double rot = r.wall_rotation_deg * M_PI / 180.0;
    LayoutPlane* w2 = planeWithId(&e, 2);  // y = 0 wall, normal +y, centre (2.5, 0, 1.35)
    w2->normal_L = Eigen::AngleAxisd(rot, Eigen::Vector3d::UnitZ()) * w2->normal_L;
    w2->d_L = -w2->normal_L.dot(Eigen::Vector3d(2.5, 0.0, 1.35));
    planeWithId(&e, 3)->d_L += r.wall_shift_m;  // x = 5 wall moved outwards
    LayoutPlane* w4 = planeWithId(&e, 4);       // y = 4 wall with its normal flipped
    w4->normal_L = -w4->normal_L;
    w4->d_L = -w4->d_L;
    e.planes.erase(std::find_if(e.planes.begin(), e.planes.end(),
                                [](const LayoutPlane& p) { return p.id == 5; }));
    LayoutPlane extra;  // a spurious wall far outside the room
    extra.id = 99;
    extra.normal_L = Eigen::Vector3d(1, 1, 0).normalized();
    extra.d_L = -10.0;
    e.planes.push_back(extra);
    LayoutPlane* floor = planeWithId(&e, 0);  // tilted about the x axis through (2.5, 2, 0)
    floor->normal_L = Eigen::AngleAxisd(r.floor_tilt_deg * M_PI / 180.0, Eigen::Vector3d::UnitX()) *
                      floor->normal_L;
    floor->d_L = -floor->normal_L.dot(Eigen::Vector3d(2.5, 2.0, 0.0));
    planeWithId(&e, 1)->d_L += r.ceiling_raise_m;
    e.ceiling_height_m += r.ceiling_raise_m;
    std::reverse(e.planes.begin(), e.planes.end());
    const Eigen::Isometry3d X = lie::expSE3(x);
    const Eigen::Isometry3d T_Lest_Lgt = X.inverse() * r.gt.T_W_L;
    for (LayoutPlane& p : e.planes) {
        const HessianPlane moved = transformPlane({p.normal_L, p.d_L}, T_Lest_Lgt);
        p.normal_L = moved.normal;
        p.d_L = moved.d;
    }
    e.T_W_L = X;
    r.est = e;
    return r;
}

TEST(LayoutMetrics, RecoversKnownPerturbations) {
    const PerturbedRoom r = perturbedRoom();
    auto m = eval::evaluateLayout(r.est, r.gt);
    ASSERT_TRUE(m.isOk()) << m.status().toString();
    EXPECT_EQ(m->num_gt_walls, 4u);
    EXPECT_EQ(m->num_est_walls, 4u);
    ASSERT_EQ(m->walls.size(), 3u);
    EXPECT_EQ(m->unmatched_gt_walls, std::vector<int>{5});
    EXPECT_EQ(m->unmatched_est_walls, std::vector<int>{99});
    const eval::PlaneError& w2 = m->walls[0];
    const eval::PlaneError& w3 = m->walls[1];
    const eval::PlaneError& w4 = m->walls[2];
    EXPECT_EQ(w2.gt_id, 2);
    EXPECT_EQ(w2.est_id, 2);
    EXPECT_NEAR(w2.angle_error_deg, r.wall_rotation_deg, 1e-9);
    EXPECT_NEAR(w2.centre_distance_m, 0.0, 1e-9);
    // Rotating about the centre (2.5, 0, 1.35) changes d in L_gt by 2.5 sin(2 deg).
    EXPECT_NEAR(w2.offset_error_m, 2.5 * std::sin(r.wall_rotation_deg * M_PI / 180.0), 1e-9);
    EXPECT_EQ(w3.est_id, 3);
    EXPECT_NEAR(w3.angle_error_deg, 0.0, 1e-6);
    EXPECT_NEAR(w3.offset_error_m, r.wall_shift_m, 1e-9);
    EXPECT_NEAR(w3.centre_distance_m, r.wall_shift_m, 1e-9);
    EXPECT_FALSE(w3.flipped);
    EXPECT_EQ(w4.est_id, 4);
    EXPECT_TRUE(w4.flipped);
    EXPECT_NEAR(w4.angle_error_deg, 0.0, 1e-6);
    EXPECT_NEAR(w4.offset_error_m, 0.0, 1e-9);
    EXPECT_NEAR(m->max_wall_angle_error_deg, r.wall_rotation_deg, 1e-9);
    EXPECT_NEAR(m->mean_wall_angle_error_deg, r.wall_rotation_deg / 3.0, 1e-6);
    EXPECT_NEAR(m->max_abs_wall_offset_error_m, w2.offset_error_m, 1e-12);

    ASSERT_TRUE(m->floor.has_value());
    EXPECT_NEAR(m->floor->angle_error_deg, r.floor_tilt_deg, 1e-9);
    EXPECT_NEAR(m->floor->centre_distance_m, 0.0, 1e-9);  // tilted about the polygon centre
    ASSERT_TRUE(m->ceiling.has_value());
    EXPECT_NEAR(m->ceiling->angle_error_deg, 0.0, 1e-6);
    EXPECT_NEAR(m->ceiling->offset_error_m, r.ceiling_raise_m, 1e-9);
    ASSERT_TRUE(m->ceiling_height_error_m.has_value());
    EXPECT_NEAR(*m->ceiling_height_error_m, r.ceiling_raise_m, 1e-12);

    // Pairs among walls 2, 3, 4: GT angles 90, 180, 90; only pairs with wall 2 are off, by 2 deg.
    ASSERT_EQ(m->wall_pairs.size(), 3u);
    EXPECT_NEAR(m->wall_pairs[0].gt_angle_deg, 90.0, 1e-9);
    EXPECT_NEAR(m->wall_pairs[1].gt_angle_deg, 180.0, 1e-9);
    EXPECT_NEAR(m->wall_pairs[0].error_deg, r.wall_rotation_deg, 1e-6);
    EXPECT_NEAR(m->wall_pairs[1].error_deg, r.wall_rotation_deg, 1e-6);
    EXPECT_NEAR(m->wall_pairs[2].error_deg, 0.0, 1e-6);
    EXPECT_NEAR(m->max_wall_pair_angle_error_deg, r.wall_rotation_deg, 1e-6);
}

TEST(LayoutMetrics, WorldFrameKeepsAnglesAndCentreDistances) {
    const PerturbedRoom r = perturbedRoom();
    eval::LayoutMetricsConfig world;
    world.frame = eval::LayoutFrame::kWorld;
    const auto in_gt = eval::evaluateLayout(r.est, r.gt).value();
    const auto in_w = eval::evaluateLayout(r.est, r.gt, world).value();
    ASSERT_EQ(in_w.walls.size(), in_gt.walls.size());
    for (size_t i = 0; i < in_w.walls.size(); ++i) {
        EXPECT_EQ(in_w.walls[i].est_id, in_gt.walls[i].est_id);
        EXPECT_NEAR(in_w.walls[i].angle_error_deg, in_gt.walls[i].angle_error_deg, 1e-6);
        EXPECT_NEAR(in_w.walls[i].centre_distance_m, in_gt.walls[i].centre_distance_m, 1e-9);
    }
    // A pure shift changes d by the same amount in any frame.
    EXPECT_NEAR(in_w.walls[1].offset_error_m, r.wall_shift_m, 1e-9);
    // Reported planes are in the requested frame: the matched estimate of wall 3 in W equals
    // the GT wall 3 moved by T_W_L_gt, shifted by 3 cm.
    const LayoutPlane& gt3 = r.gt.planes[3];
    ASSERT_EQ(gt3.id, 3);
    const HessianPlane gt3_W = planeInWorld(r.gt, gt3);
    EXPECT_NEAR((in_w.walls[1].estimate.normal - gt3_W.normal).norm(), 0.0, 1e-9);
    EXPECT_NEAR(in_w.walls[1].estimate.d - gt3_W.d, r.wall_shift_m, 1e-9);
}

TEST(LayoutMetrics, IdenticalLayoutsHaveZeroError) {
    const Layout gt = makeRoomLayout(lShapedRoom(), 2.4).value();
    const auto m = eval::evaluateLayout(gt, gt).value();
    EXPECT_EQ(m.walls.size(), 6u);
    EXPECT_TRUE(m.unmatched_gt_walls.empty());
    EXPECT_TRUE(m.unmatched_est_walls.empty());
    for (const auto& w : m.walls) EXPECT_EQ(w.gt_id, w.est_id);
    EXPECT_EQ(m.max_wall_angle_error_deg, 0.0);
    EXPECT_EQ(m.max_abs_wall_offset_error_m, 0.0);
    EXPECT_EQ(m.wall_pairs.size(), 15u);
    Layout bad = gt;
    bad.planes[2].normal_L *= 2.0;
    EXPECT_EQ(eval::evaluateLayout(bad, gt).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace plumb
