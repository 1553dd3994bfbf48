// SPDX-License-Identifier: Apache-2.0
#pragma once

// Oriented point clouds and triangle meshes: the geometry exchanged between every stage.
// Coordinates are float metres in the frame the owner names (points_F, points_W, ...).
//
// Thread-safety: value types; const access from several threads is safe, a write needs
// exclusive access.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

namespace plumb {

using Color3u8 = Eigen::Matrix<uint8_t, 3, 1>;

struct PointCloud {
    std::vector<Eigen::Vector3f> points;   ///< positions, metres
    std::vector<Eigen::Vector3f> normals;  ///< unit normals, empty or one per point
    std::vector<Color3u8> colors;          ///< RGB, empty or one per point

    size_t size() const { return points.size(); }
    bool empty() const { return points.empty(); }
    bool hasNormals() const { return !normals.empty() && normals.size() == points.size(); }
    bool hasColors() const { return !colors.empty() && colors.size() == points.size(); }
    /// Attributes are either absent or one per point.
    bool isConsistent() const {
        return (normals.empty() || normals.size() == points.size()) &&
               (colors.empty() || colors.size() == points.size());
    }
    void reserve(size_t n, bool with_normals, bool with_colors);
    /// Appends `other` (attribute presence must match unless this cloud is empty).
    void append(const PointCloud& other);
};

struct TriangleMesh {
    std::vector<Eigen::Vector3f> vertices;  ///< positions, metres
    std::vector<Eigen::Vector3f> normals;   ///< per-vertex unit normals, empty or one per vertex
    std::vector<Color3u8> colors;           ///< per-vertex RGB, empty or one per vertex
    std::vector<Eigen::Vector3i>
        triangles;  ///< vertex indices, counter-clockwise seen from outside

    bool empty() const { return vertices.empty(); }
};

/// Returns T * cloud (points transformed, normals rotated).
PointCloud transformed(const PointCloud& cloud, const Eigen::Isometry3d& T);
TriangleMesh transformed(const TriangleMesh& mesh, const Eigen::Isometry3d& T);

}  // namespace plumb
