// SPDX-License-Identifier: Apache-2.0
#pragma once

// A scanned room for the monitor's tests: a 4 m x 3 m room (layout frame L, z up, floor z = 0,
// walls 2.5 m high) scanned by a camera at 1.5 m height walking a circle of radius 0.5 m around the
// room centre and looking outwards. Fragment k looks along yaw k * 45 degrees from
// centre + 0.5 m * (cos yaw, sin yaw) and holds the floor and wall points within a 60 degree wedge
// in front of it (beyond 0.3 m), so fragments 0..7 together see the room except a patch around
// the centre, and any subset leaves known gaps. The world frame W is the first camera's frame
// (x right, y down, z forward).

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <vector>

#include "common/fragment/fragment.hpp"
#include "common/layout/layout.hpp"

namespace plumb::monitor::testing {

inline constexpr double kRoomX = 4.0;
inline constexpr double kRoomY = 3.0;
inline constexpr double kRoomHeight = 2.5;
inline constexpr double kCameraHeight = 1.5;
inline constexpr double kYawStepDeg = 45.0;
inline constexpr double kHalfFovDeg = 30.0;
inline constexpr double kWalkRadius = 0.5;

/// Camera -> layout pose of fragment k (camera z forward along yaw, y down = -z_L).
inline Eigen::Isometry3d cameraInLayout(int k) {
    const double yaw = k * kYawStepDeg * std::numbers::pi / 180.0;
    const Eigen::Vector3d forward(std::cos(yaw), std::sin(yaw), 0.0);
    const Eigen::Vector3d down(0.0, 0.0, -1.0);
    const Eigen::Vector3d right = down.cross(forward);  // x = y cross z for a right-handed frame
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear().col(0) = right;
    T.linear().col(1) = down;
    T.linear().col(2) = forward;
    T.translation() = Eigen::Vector3d(kRoomX / 2 + kWalkRadius * forward.x(),
                                      kRoomY / 2 + kWalkRadius * forward.y(), kCameraHeight);
    return T;
}

/// World = first camera frame: T_W_L = T_L_C0^-1.
inline Eigen::Isometry3d worldFromLayout() { return cameraInLayout(0).inverse(); }

inline Layout roomLayout() {
    Layout layout =
        makeRoomLayout({{0, 0}, {kRoomX, 0}, {kRoomX, kRoomY}, {0, kRoomY}}, kRoomHeight).value();
    layout.T_W_L = worldFromLayout();
    return layout;
}

/// Fragment k: floor and wall points (step `step_m`) inside its wedge, in the fragment frame.
inline Fragment roomFragment(int k, double step_m = 0.05, int frames_per_fragment = 10) {
    const Eigen::Isometry3d T_L_F = cameraInLayout(k);
    const Eigen::Isometry3d T_F_L = T_L_F.inverse();
    const double yaw = k * kYawStepDeg * std::numbers::pi / 180.0;
    const double half_fov = kHalfFovDeg * std::numbers::pi / 180.0;
    const Eigen::Vector2d centre = T_L_F.translation().head<2>();  // the camera
    auto inWedge = [&](const Eigen::Vector2d& p) {
        const Eigen::Vector2d d = p - centre;
        if (d.norm() < 0.3) return false;
        double a = std::atan2(d.y(), d.x()) - yaw;
        a = std::remainder(a, 2 * std::numbers::pi);
        return std::abs(a) <= half_fov;
    };
    Fragment f;
    f.id = static_cast<uint32_t>(k);
    f.T_W_F = worldFromLayout() * T_L_F;
    f.voxel_size_m = 0.02;
    auto add = [&](const Eigen::Vector3d& p_L, const Eigen::Vector3d& n_L) {
        f.points_F.points.push_back((T_F_L * p_L).cast<float>());
        f.points_F.normals.push_back((T_F_L.linear() * n_L).cast<float>());
    };
    for (double x = step_m / 2; x < kRoomX; x += step_m) {
        for (double y = step_m / 2; y < kRoomY; y += step_m) {
            if (inWedge({x, y})) add({x, y, 0.0}, Eigen::Vector3d::UnitZ());
        }
    }
    // Walls: sample the boundary at 3 heights.
    for (double z : {0.5, 1.25, 2.0}) {
        for (double s = 0.0; s < 2 * (kRoomX + kRoomY); s += step_m) {
            Eigen::Vector2d p;
            Eigen::Vector3d n;
            if (s < kRoomX) {
                p = {s, 0};
                n = Eigen::Vector3d::UnitY();
            } else if (s < kRoomX + kRoomY) {
                p = {kRoomX, s - kRoomX};
                n = -Eigen::Vector3d::UnitX();
            } else if (s < 2 * kRoomX + kRoomY) {
                p = {2 * kRoomX + kRoomY - s, kRoomY};
                n = -Eigen::Vector3d::UnitY();
            } else {
                p = {0, 2 * (kRoomX + kRoomY) - s};
                n = Eigen::Vector3d::UnitX();
            }
            if (inWedge(p)) add({p.x(), p.y(), z}, n);
        }
    }
    for (int i = 0; i < frames_per_fragment; ++i) {
        FragmentFrame fr;
        fr.frame_index = static_cast<int64_t>(k) * frames_per_fragment + i;
        fr.timestamp_s = static_cast<double>(fr.frame_index) / 30.0;
        f.frames.push_back(fr);
    }
    return f;
}

/// pose_graph.json in the registration stage's format (backend/report/registration_outputs.cpp) for
/// fragments 0..n-1: odometry edges i -> i+1, a kept loop 0 -> n-1 (weight 0.9) and a pruned
/// loop 1 -> n-2 (weight 0.1).
inline std::string poseGraphJsonText(int n) {
    using nlohmann::json;
    auto matrix = [](const Eigen::Matrix4d& m) {
        json rows = json::array();
        for (int r = 0; r < 4; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
        return rows;
    };
    json j;
    j["convention"] = "T_source_target maps target-fragment points into the source frame";
    j["nodes"] = json::array();
    for (int i = 0; i < n; ++i) {
        Eigen::Isometry3d T = worldFromLayout() * cameraInLayout(i);
        T.translation() += Eigen::Vector3d(0.01, 0.0, 0.0);  // "optimised": 1 cm off odometry
        j["nodes"].push_back({{"id", i}, {"T_W_F", matrix(T.matrix())}});
    }
    j["edges"] = json::array();
    auto edge = [&](int a, int b, const char* kind, double l, bool kept, const char* reason) {
        j["edges"].push_back({{"source", a},
                              {"target", b},
                              {"kind", kind},
                              {"kept", kept},
                              {"reason", reason},
                              {"overlap", 0.4},
                              {"inlier_rmse_m", 0.012},
                              {"line_process", l}});
    };
    for (int i = 0; i + 1 < n; ++i) edge(i, i + 1, "odometry", 1.0, true, "");
    if (n >= 4) {
        edge(0, n - 1, "loop", 0.9, true, "");
        edge(1, n - 2, "loop", 0.1, false, "line process 0.10 < 0.25");
    }
    j["optimisation"] = {{"iterations", 3}};
    return j.dump(2) + "\n";
}

}  // namespace plumb::monitor::testing
