// SPDX-License-Identifier: Apache-2.0
// Scene model and exact ray casting of the simulated scanner (reference §1.2, §1.5).
#include <gtest/gtest.h>

#include <cmath>

#include "common/camera/pinhole.hpp"
#include "drivers/sim/render.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/trajectory.hpp"

namespace plumb::sim {
namespace {

PinholeCamera ciCamera() { return *cameraPreset("ci"); }

Scene emptyRoom() {
    Scene s;
    s.name = "empty";
    s.polygon = {{0, 0}, {8, 0}, {8, 6}, {0, 6}};
    s.height_m = 3.0;
    return s;
}

Eigen::Isometry3d poseAt(const Eigen::Vector3d& p, double yaw, double pitch) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = cameraRotation(yaw, pitch, 0.0);
    T.translation() = p;
    return T;
}

// Signed distance of p to the surface of the primitive with `label` (0 when on it).
double distanceToPrimitive(const Scene& s, int label, const Eigen::Vector3d& p) {
    if (label == floorLabel()) return std::abs(p.z());
    if (label == ceilingLabel()) return std::abs(p.z() - s.height_m);
    const int nw = s.numWalls();
    if (label < 2 + nw) {
        const int k = label - 2;
        const Eigen::Vector2d a = s.polygon[k], b = s.polygon[(k + 1) % nw];
        const Eigen::Vector2d e = (b - a).normalized();
        const Eigen::Vector2d q = p.head<2>() - a;
        const double along = q.dot(e);
        const double off = std::abs(e.x() * q.y() - e.y() * q.x());
        const double outside = std::max(0.0, std::max(-along, along - (b - a).norm()));
        return off + outside;
    }
    const int nb = static_cast<int>(s.boxes.size());
    if (label < 2 + nw + nb) {
        const Box& box = s.boxes[label - 2 - nw];
        const Eigen::Vector3d q = p - box.center_W;
        const double c = std::cos(box.yaw_rad), sn = std::sin(box.yaw_rad);
        const Eigen::Vector3d l(c * q.x() + sn * q.y(), -sn * q.x() + c * q.y(), q.z());
        const Eigen::Vector3d excess = l.cwiseAbs() - 0.5 * box.size_m;
        // On the surface: the largest excess is 0 and none is positive.
        return std::max(std::abs(excess.maxCoeff()), excess.cwiseMax(0.0).norm());
    }
    const Cylinder& c = s.cylinders[label - 2 - nw - nb];
    const double r = (p.head<2>() - c.center_xy).norm();
    const double side =
        std::abs(r - c.radius_m) + std::max(0.0, std::max(c.z_min_m - p.z(), p.z() - c.z_max_m));
    const double cap = std::min(std::abs(p.z() - c.z_max_m), std::abs(p.z() - c.z_min_m)) +
                       std::max(0.0, r - c.radius_m);
    return std::min(side, cap);
}

bool freeSpace(const Scene& s, const Eigen::Vector3d& p) {
    if (!insidePolygon(s.polygon, p.head<2>()) || p.z() <= 0.0 || p.z() >= s.height_m) {
        return false;
    }
    for (const Box& b : s.boxes) {
        const Eigen::Vector3d q = p - b.center_W;
        const double c = std::cos(b.yaw_rad), sn = std::sin(b.yaw_rad);
        const Eigen::Vector3d l(c * q.x() + sn * q.y(), -sn * q.x() + c * q.y(), q.z());
        if ((l.cwiseAbs() - 0.5 * b.size_m).maxCoeff() < 0.0) return false;
    }
    for (const Cylinder& c : s.cylinders) {
        if ((p.head<2>() - c.center_xy).norm() < c.radius_m && p.z() > c.z_min_m &&
            p.z() < c.z_max_m) {
            return false;
        }
    }
    return true;
}

TEST(SimRender, FrontoParallelPlaneIsExact) {
    const Scene scene = emptyRoom();
    const PinholeCamera camera = ciCamera();
    const Renderer renderer(scene, camera);
    RenderedView view;
    for (const double z : {0.5, 1.0, 2.0, 3.0, 2.37}) {
        // Looking along +x at the wall x = 8 from distance z.
        const Eigen::Isometry3d T_W_C = poseAt({8.0 - z, 3.0, 1.5}, 0.0, 0.0);
        renderer.render(T_W_C, &view);
        double worst_plane = 0.0;
        for (int v = 0; v < camera.height; ++v) {
            for (int u = 0; u < camera.width; ++u) {
                ASSERT_EQ(view.depth(u, v), static_cast<float>(z)) << u << "," << v;
                ASSERT_EQ(view.label(u, v), wallLabel(1));
                const Eigen::Vector3d p_W = T_W_C * camera.unproject(u, v, view.depth(u, v));
                worst_plane = std::max(worst_plane, std::abs(p_W.x() - 8.0));
            }
        }
        EXPECT_LT(worst_plane, 1e-6) << "z = " << z;
    }
}

TEST(SimRender, ObliqueViewPointsLieOnTheirSurfaces) {
    // A yawed, pitched camera in the furnished living room and the L-shaped room: every hit lies
    // on the primitive its label names, and the segment from the camera to it is free space.
    for (const char* name : {"living_room", "l_shape", "weak_manhattan", "corridor"}) {
        const Scene scene = *builtinScene(name);
        const PinholeCamera camera = ciCamera();
        const Renderer renderer(scene, camera);
        TrajectoryConfig tc;
        tc.num_frames = 300;
        const io::Trajectory traj = *generateTrajectory(scene, tc);
        RenderedView view;
        double worst = 0.0;
        int hits = 0, blocked = 0;
        for (size_t k = 0; k < traj.size(); k += 60) {
            const Eigen::Isometry3d& T_W_C = traj[k].T_W_C;
            renderer.render(T_W_C, &view);
            for (int v = 0; v < camera.height; v += 3) {
                for (int u = 0; u < camera.width; u += 3) {
                    if (view.label(u, v) == kNoPrimitive) continue;
                    ++hits;
                    const Eigen::Vector3d p_W =
                        T_W_C * camera.unproject(u, v, static_cast<double>(view.depth(u, v)));
                    worst = std::max(worst, distanceToPrimitive(scene, view.label(u, v), p_W));
                    const Eigen::Vector3d o = T_W_C.translation();
                    for (int i = 1; i < 100; ++i) {
                        const Eigen::Vector3d q = o + (p_W - o) * (i / 100.0 * 0.995);
                        if (!freeSpace(scene, q)) {
                            ++blocked;
                            break;
                        }
                    }
                }
            }
        }
        EXPECT_GT(hits, 5000) << name;
        EXPECT_LT(worst, 1e-5) << name;  // float depth: ~1e-7 relative
        EXPECT_EQ(blocked, 0) << name;
    }
}

TEST(SimRender, OpeningsLetRaysLeaveTheRoom) {
    Scene scene = emptyRoom();
    Opening door;
    door.wall = 1;  // x = 8, from (8, 0) to (8, 6)
    door.offset_m = 2.5;
    door.width_m = 1.0;
    door.z_min_m = 0.0;
    door.z_max_m = 2.0;
    scene.openings = {door};
    ASSERT_TRUE(validateScene(scene).isOk());
    const RayCaster caster(scene);
    const Eigen::Vector3d o(6.0, 3.0, 1.0);
    EXPECT_EQ(caster.cast(o, {1.0, 0.0, 0.0}).label, kNoPrimitive);  // through the door
    EXPECT_EQ(caster.cast(o, {1.0, 0.0, 0.6}).label, wallLabel(1));  // above the lintel
    EXPECT_EQ(caster.cast(o, {1.0, 0.4, 0.0}).label, wallLabel(1));  // beside the door
    EXPECT_DOUBLE_EQ(caster.cast(o, {1.0, 0.4, 0.0}).t, 2.0);
    EXPECT_EQ(caster.cast(o, {1.0, 0.0, -0.6}).label, floorLabel());  // floor before the door
    // Dense samples leave the hole out.
    const PointCloud gt = sampleSurfaces(scene, 0.05);
    for (const Eigen::Vector3f& p : gt.points) {
        const bool in_hole = std::abs(p.x() - 8.0F) < 1e-4F && p.y() > 2.5F && p.y() < 3.5F &&
                             p.z() < 2.0F && p.z() > 0.0F;
        ASSERT_FALSE(in_hole) << p.transpose();
    }
}

TEST(SimRender, DenseSamplesLieOnSurfacesWithExpectedDensity) {
    const Scene scene = *builtinScene("living_room");
    const double spacing = 0.05;
    const PointCloud gt = sampleSurfaces(scene, spacing);
    ASSERT_TRUE(gt.hasNormals());
    // Floor + ceiling + walls minus openings is a lower bound on the sampled area (furniture
    // adds its faces, and hides some floor).
    const double perimeter = 2 * (6.0 + 4.6);
    const double room_area = 2 * 6.0 * 4.6 + perimeter * 2.6 - 0.9 * 2.05 - 1.3 * 1.2;
    const double expected = room_area / (spacing * spacing);
    EXPECT_GT(gt.size(), 0.9 * expected);
    EXPECT_LT(gt.size(), 1.3 * expected);
    // Each sample is on some surface: a ray from just in front of it along -normal hits it.
    const RayCaster caster(scene);
    int checked = 0;
    for (size_t i = 0; i < gt.size(); i += 97) {
        const Eigen::Vector3d p = gt.points[i].cast<double>();
        const Eigen::Vector3d n = gt.normals[i].cast<double>();
        const RayHit hit = caster.cast(p + 0.01 * n, -n);
        ASSERT_NE(hit.label, kNoPrimitive) << p.transpose();
        EXPECT_NEAR(hit.t, 0.01, 1e-6) << p.transpose();
        ++checked;
    }
    EXPECT_GT(checked, 100);
}

TEST(SimScene, BuiltinsAreValidAndLayoutMatchesPolygon) {
    for (const std::string& name : builtinSceneNames()) {
        auto scene = builtinScene(name);
        ASSERT_TRUE(scene.isOk()) << name;
        EXPECT_TRUE(validateScene(*scene).isOk()) << name;
    }
    EXPECT_EQ(builtinScene("nope").status().code(), StatusCode::kNotFound);
    // The weak-Manhattan room has one wall 10-30 degrees off a right angle.
    const Scene wm = *builtinScene("weak_manhattan");
    int oblique = 0;
    for (int k = 0; k < wm.numWalls(); ++k) {
        const Eigen::Vector2d e = wm.polygon[(k + 1) % wm.numWalls()] - wm.polygon[k];
        const double deg = std::atan2(std::abs(e.x()), std::abs(e.y())) * 180.0 / M_PI;
        const double off = std::min(std::abs(deg), std::abs(90.0 - deg));
        if (off > 1e-9) {
            ++oblique;
            EXPECT_GT(off, 10.0);
            EXPECT_LT(off, 30.0);
        }
    }
    EXPECT_EQ(oblique, 1);
}

TEST(SimScene, TomlRoundTripAndErrors) {
    const std::string text = R"(
name = "office"
height_m = 2.7
polygon = [[0, 0], [5, 0], [5, 4], [0, 4]]
[[box]]
center = [2.5, 2.0, 0.4]
size = [1.0, 0.6, 0.8]
yaw_deg = 30
[[cylinder]]
center = [1, 1]
radius_m = 0.3
z_max_m = 1.2
[[opening]]
wall = 2
offset_m = 1.0
width_m = 0.9
z_max_m = 2.0
)";
    auto scene = parseSceneToml(text, "office.toml");
    ASSERT_TRUE(scene.isOk()) << scene.status().toString();
    EXPECT_EQ(scene->name, "office");
    EXPECT_EQ(scene->polygon.size(), 4U);
    ASSERT_EQ(scene->boxes.size(), 1U);
    EXPECT_NEAR(scene->boxes[0].yaw_rad, M_PI / 6, 1e-12);
    EXPECT_EQ(scene->cylinders.size(), 1U);
    EXPECT_EQ(scene->openings.size(), 1U);

    auto bad_key =
        parseSceneToml("height_m = 2.5\npolygon = [[0,0],[1,0],[1,1]]\ncolour = 3\n", "bad.toml");
    ASSERT_FALSE(bad_key.isOk());
    EXPECT_NE(bad_key.status().message().find("bad.toml:3"), std::string::npos)
        << bad_key.status().message();
    EXPECT_NE(bad_key.status().message().find("colour"), std::string::npos);

    auto clockwise =
        parseSceneToml("height_m = 2.5\npolygon = [[0,0],[0,1],[1,1],[1,0]]\n", "cw.toml");
    ASSERT_FALSE(clockwise.isOk());
    EXPECT_NE(clockwise.status().message().find("counter-clockwise"), std::string::npos);

    auto syntax = parseSceneToml("height_m = = 2\n", "syntax.toml");
    ASSERT_FALSE(syntax.isOk());
    EXPECT_NE(syntax.status().message().find("syntax.toml:1"), std::string::npos);
}

TEST(SimRender, CulledRenderMatchesPerPixelCast) {
    // The renderer tests each tile only against the primitives whose screen rectangle overlaps
    // it, with per-frame terms hoisted; the reference casts every pixel's ray against every
    // primitive. Poses: the handheld loop with arbitrary orientations (primitives behind the
    // camera, straddling its plane) and positions 2 cm from a box face.
    for (const char* name : {"living_room", "l_shape", "weak_manhattan", "corridor"}) {
        const Scene scene = *builtinScene(name);
        const PinholeCamera camera = ciCamera();
        const Renderer renderer(scene, camera);
        TrajectoryConfig tc;
        tc.num_frames = 120;
        const io::Trajectory traj = *generateTrajectory(scene, tc);
        std::vector<Eigen::Isometry3d> poses;
        for (size_t k = 0; k < traj.size(); k += 10) {
            Eigen::Isometry3d T = traj[k].T_W_C;
            poses.push_back(T);
            T.linear() = Eigen::Quaterniond::UnitRandom().toRotationMatrix();
            poses.push_back(T);
        }
        for (const Box& box : scene.boxes) {
            const Eigen::Vector3d p =
                box.center_W + Eigen::Vector3d(std::cos(box.yaw_rad), std::sin(box.yaw_rad), 0.0) *
                                   (0.5 * box.size_m.x() + 0.02);
            if (!insidePolygon(scene.polygon, p.head<2>())) continue;
            Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
            T.translation() = p;
            T.linear() = Eigen::Quaterniond::UnitRandom().toRotationMatrix();
            poses.push_back(T);
        }
        RenderedView view;
        for (const Eigen::Isometry3d& T_W_C : poses) {
            renderer.render(T_W_C, &view);
            for (int v = 0; v < camera.height; ++v) {
                for (int u = 0; u < camera.width; ++u) {
                    const Eigen::Vector3d d_C = camera.ray(u, v);
                    const Eigen::Vector3d d = T_W_C.linear() * d_C;
                    const RayHit hit = renderer.caster().cast(T_W_C.translation(), d);
                    const float cosv = hit.label == kNoPrimitive
                                           ? 0.0F
                                           : static_cast<float>(std::abs(hit.normal_W.dot(d)) *
                                                                (1.0 / d_C.norm()));
                    ASSERT_EQ(view.depth(u, v), static_cast<float>(hit.t)) << name << u << "," << v;
                    ASSERT_EQ(view.label(u, v), hit.label) << name << " " << u << "," << v;
                    ASSERT_EQ(view.cos_view(u, v), cosv) << name << " " << u << "," << v;
                }
            }
        }
    }
}

}  // namespace
}  // namespace plumb::sim
