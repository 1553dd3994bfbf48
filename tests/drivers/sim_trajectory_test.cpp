// SPDX-License-Identifier: Apache-2.0
// Handheld trajectories of the simulated scanner (reference §1.3).
#include <gtest/gtest.h>

#include <cmath>

#include "common/geometry/lie.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/trajectory.hpp"

namespace plumb::sim {
namespace {

struct Motion {
    double max_speed = 0.0;
    double mean_speed = 0.0;
    double max_angular_dps = 0.0;
};

Motion measure(const io::Trajectory& t, double rate_hz) {
    Motion m;
    double sum = 0.0;
    for (size_t k = 1; k < t.size(); ++k) {
        const double v = (t[k].T_W_C.translation() - t[k - 1].T_W_C.translation()).norm() * rate_hz;
        const double w = lie::rotationAngle(t[k - 1].T_W_C.inverse() * t[k].T_W_C) * rate_hz;
        m.max_speed = std::max(m.max_speed, v);
        m.max_angular_dps = std::max(m.max_angular_dps, w * 180.0 / M_PI);
        sum += v;
    }
    m.mean_speed = sum / (t.size() - 1);
    return m;
}

double wallDistance(const Scene& s, const Eigen::Vector2d& p) {
    double best = 1e9;
    for (int k = 0; k < s.numWalls(); ++k) {
        const Eigen::Vector2d a = s.polygon[k], b = s.polygon[(k + 1) % s.numWalls()];
        const double t = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
        best = std::min(best, (a + t * (b - a) - p).norm());
    }
    return best;
}

// Smallest distance between camera positions more than `gap` frames apart.
double closestRevisit(const io::Trajectory& t, size_t gap) {
    double best = 1e9;
    for (size_t i = 0; i < t.size(); i += 3) {
        for (size_t j = i + gap; j < t.size(); j += 3) {
            best = std::min(best, (t[i].T_W_C.translation() - t[j].T_W_C.translation()).norm());
        }
    }
    return best;
}

TEST(SimTrajectory, HandheldLimitsHoldInEveryBuiltinScene) {
    for (const std::string& name : builtinSceneNames()) {
        const Scene scene = *builtinScene(name);
        for (const bool loop : {true, false}) {
            TrajectoryConfig config;
            config.loop = loop;
            config.num_frames = 900;
            auto traj = generateTrajectory(scene, config);
            ASSERT_TRUE(traj.isOk()) << name << ": " << traj.status().toString();
            ASSERT_EQ(traj->size(), 900U);
            const Motion m = measure(*traj, config.rate_hz);
            EXPECT_LE(m.max_speed, 0.5) << name << (loop ? " loop" : " no-loop");
            EXPECT_GE(m.mean_speed, 0.15) << name << (loop ? " loop" : " no-loop");
            EXPECT_LE(m.max_angular_dps, 30.0) << name << (loop ? " loop" : " no-loop");
            for (const io::StampedPose& p : *traj) {
                ASSERT_TRUE(lie::isValidPose(p.T_W_C, 1e-9));
                const Eigen::Vector3d x = p.T_W_C.translation();
                ASSERT_TRUE(insidePolygon(scene.polygon, x.head<2>())) << name;
                EXPECT_GT(wallDistance(scene, x.head<2>()), 0.3) << name;
                EXPECT_GT(x.z(), 1.2);
                EXPECT_LT(x.z(), 1.6);
            }
            EXPECT_DOUBLE_EQ((*traj)[30].timestamp_s, 1.0);
        }
    }
}

TEST(SimTrajectory, LoopReturnsToItsStartAndNoLoopNeverRevisits) {
    const Scene scene = *builtinScene("living_room");
    TrajectoryConfig config;
    config.num_frames = 1500;  // enough for one full loop at walking speed
    config.loop = true;
    const io::Trajectory loop = *generateTrajectory(scene, config);
    const Eigen::Vector3d start = loop.front().T_W_C.translation();
    double farthest = 0.0;
    for (const auto& p : loop)
        farthest = std::max(farthest, (p.T_W_C.translation() - start).norm());
    EXPECT_GT(farthest, 1.5);
    EXPECT_LT((loop.back().T_W_C.translation() - start).head<2>().norm(), 0.05);
    // The camera also looks the same way again (loop closure possible): same heading.
    const Eigen::Vector3d z0 = loop.front().T_W_C.linear().col(2);
    const Eigen::Vector3d z1 = loop.back().T_W_C.linear().col(2);
    EXPECT_GT(z0.head<2>().normalized().dot(z1.head<2>().normalized()), std::cos(10 * M_PI / 180));
    EXPECT_LT(closestRevisit(loop, 300), 0.1);

    config.loop = false;
    config.num_frames = 900;  // walks 3/4 of the loop without standing still
    const io::Trajectory open = *generateTrajectory(scene, config);
    EXPECT_GT(closestRevisit(open, 300), 0.75);
}

TEST(SimTrajectory, SeededAndDeterministic) {
    const Scene scene = *builtinScene("l_shape");
    TrajectoryConfig config;
    config.num_frames = 200;
    const io::Trajectory a = *generateTrajectory(scene, config);
    const io::Trajectory b = *generateTrajectory(scene, config);
    config.seed = 2;
    const io::Trajectory c = *generateTrajectory(scene, config);
    double diff_ab = 0.0, diff_ac = 0.0;
    for (size_t k = 0; k < a.size(); ++k) {
        diff_ab = std::max(diff_ab, (a[k].T_W_C.matrix() - b[k].T_W_C.matrix()).norm());
        diff_ac = std::max(diff_ac,
                           (a[k].T_W_C.translation() - c[k].T_W_C.translation()).head<2>().norm());
    }
    EXPECT_EQ(diff_ab, 0.0);
    EXPECT_GT(diff_ac, 1e-4);  // a different hand shake
    EXPECT_LT(diff_ac, 0.02);  // on the same path (shake of a few millimetres)
}

TEST(SimTrajectory, RollSwayTurnsTheCameraAboutItsAxisAndLeavesThePathAlone) {
    const Scene scene = *builtinScene("living_room");
    TrajectoryConfig config;
    config.num_frames = 300;
    const io::Trajectory level = *generateTrajectory(scene, config);
    config.roll_sway_deg = 40.0;
    const io::Trajectory rolled = *generateTrajectory(scene, config);
    ASSERT_EQ(level.size(), rolled.size());
    double max_roll_deg = 0.0, max_axis_change = 0.0, max_position_change = 0.0;
    for (size_t k = 0; k < level.size(); ++k) {
        const Eigen::Matrix3d& A = level[k].T_W_C.linear();
        const Eigen::Matrix3d& B = rolled[k].T_W_C.linear();
        // The image x axis of the rolled camera, seen in the level camera's image plane.
        const Eigen::Vector3d x = A.transpose() * B.col(0);
        max_roll_deg = std::max(max_roll_deg, std::abs(std::atan2(x.y(), x.x())) * 180.0 / M_PI);
        max_axis_change = std::max(max_axis_change, (A.col(2) - B.col(2)).norm());
        max_position_change =
            std::max(max_position_change,
                     (level[k].T_W_C.translation() - rolled[k].T_W_C.translation()).norm());
    }
    EXPECT_NEAR(max_roll_deg, 40.0, 1.0);  // a 10 s scan passes the sway's extremes
    EXPECT_LT(max_axis_change, 0.02);      // the optical axis stays (up to the hand shake)
    EXPECT_EQ(max_position_change, 0.0);   // and so does the path
}

TEST(SimTrajectory, CameraAxesFollowConventions) {
    // yaw 0, pitch 0: optical axis +x, image right -y, image down -z (world z up).
    const Eigen::Matrix3d R = cameraRotation(0.0, 0.0, 0.0);
    EXPECT_TRUE(R.col(2).isApprox(Eigen::Vector3d::UnitX()));
    EXPECT_TRUE(R.col(0).isApprox(-Eigen::Vector3d::UnitY()));
    EXPECT_TRUE(R.col(1).isApprox(-Eigen::Vector3d::UnitZ()));
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    const Eigen::Matrix3d Rp = cameraRotation(0.3, -0.2, 0.1);
    EXPECT_NEAR(Rp.determinant(), 1.0, 1e-12);
    EXPECT_NEAR(std::asin(Rp.col(2).z()), -0.2, 1e-12);
}

TEST(SimTrajectory, RejectsAnInsetThatLeavesTheRoom) {
    Scene scene = *builtinScene("corridor");
    scene.path_inset_m = 1.5;  // the corridor is 2.4 m wide
    auto traj = generateTrajectory(scene, {});
    ASSERT_FALSE(traj.isOk());
    EXPECT_NE(traj.status().message().find("path_inset_m"), std::string::npos)
        << traj.status().message();
}

}  // namespace
}  // namespace plumb::sim
