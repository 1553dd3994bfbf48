// SPDX-License-Identifier: Apache-2.0
#include "common/cloud/point_cloud.hpp"

#include "common/core/check.hpp"

namespace plumb {

void PointCloud::reserve(size_t n, bool with_normals, bool with_colors) {
    points.reserve(n);
    if (with_normals) normals.reserve(n);
    if (with_colors) colors.reserve(n);
}

void PointCloud::append(const PointCloud& other) {
    if (empty()) {
        *this = other;
        return;
    }
    PLUMB_CHECK(hasNormals() == other.hasNormals() && hasColors() == other.hasColors())
        << "appending clouds with different attributes";
    points.insert(points.end(), other.points.begin(), other.points.end());
    normals.insert(normals.end(), other.normals.begin(), other.normals.end());
    colors.insert(colors.end(), other.colors.begin(), other.colors.end());
}

PointCloud transformed(const PointCloud& cloud, const Eigen::Isometry3d& T) {
    const Eigen::Isometry3f Tf = T.cast<float>();
    const Eigen::Matrix3f R = Tf.linear();
    PointCloud out = cloud;
    for (auto& p : out.points) p = Tf * p;
    for (auto& n : out.normals) n = R * n;
    return out;
}

TriangleMesh transformed(const TriangleMesh& mesh, const Eigen::Isometry3d& T) {
    const Eigen::Isometry3f Tf = T.cast<float>();
    const Eigen::Matrix3f R = Tf.linear();
    TriangleMesh out = mesh;
    for (auto& p : out.vertices) p = Tf * p;
    for (auto& n : out.normals) n = R * n;
    return out;
}

}  // namespace plumb
