// SPDX-License-Identifier: Apache-2.0
#include "backend/registration/prepared_fragment.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "backend/registration/cloud_ops.hpp"

namespace plumb::registration {

void describe(config::Schema& s, PrepareConfig& c) {
    s.field("voxel_size_m", c.voxel_size_m,
            "voxel edge of the downsampled cloud used for features and loop closure", "m")
        .positive()
        .max(1.0);
    s.field("recompute_normals", c.recompute_normals,
            "recompute normals by PCA instead of averaging the fragment's fused normals");
    s.field("normal_radius_m", c.normal_radius_m, "PCA normal neighbourhood radius", "m")
        .positive();
    s.field("normal_max_nn", c.normal_max_nn, "PCA normal: maximum neighbours").min(3);
    s.field("fpfh_radius_m", c.fpfh_radius_m, "FPFH neighbourhood radius (Open3D: 5 x voxel)", "m")
        .positive();
    s.field("fpfh_max_nn", c.fpfh_max_nn, "FPFH: maximum neighbours (Open3D: 100)").min(2);
    s.field("num_threads", c.num_threads, "worker threads, 0 = all; results do not depend on it")
        .min(0);
}

PointCloud voxelDownsample(const PointCloud& cloud, double voxel_m) {
    return detail::voxelDownsample(cloud, voxel_m);
}

std::vector<Eigen::Vector3f> estimateNormals(const std::vector<Eigen::Vector3f>& points,
                                             double radius_m, int max_nn,
                                             const Eigen::Vector3f& viewpoint, int num_threads) {
    std::vector<Eigen::Vector3f> normals(points.size(), Eigen::Vector3f::UnitZ());
    if (points.empty()) return normals;
    const detail::KdTree3 tree(points);
    const float r2 = static_cast<float>(radius_m * radius_m);
    const size_t k = static_cast<size_t>(std::max(3, max_nn));
    detail::parallelFor(num_threads, points.size(), [&](size_t i) {
        std::vector<uint32_t> idx(k);
        std::vector<float> d2(k);
        const size_t n = tree.knnWithin(points[i], k, r2, idx.data(), d2.data());
        Eigen::Vector3f to_view = viewpoint - points[i];
        Eigen::Vector3f normal = to_view.normalized();
        if (n >= 3) {
            Eigen::Vector3d mean = Eigen::Vector3d::Zero();
            for (size_t j = 0; j < n; ++j) mean += points[idx[j]].cast<double>();
            mean /= static_cast<double>(n);
            Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
            for (size_t j = 0; j < n; ++j) {
                const Eigen::Vector3d d = points[idx[j]].cast<double>() - mean;
                cov += d * d.transpose();
            }
            Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
            es.computeDirect(cov);
            const Eigen::Vector3f e = es.eigenvectors().col(0).cast<float>();
            if (e.allFinite() && e.norm() > 0.5f) normal = e.normalized();
        }
        if (normal.dot(to_view) < 0.0f) normal = -normal;
        normals[i] = normal;
    });
    return normals;
}

namespace {

/// Darboux-frame pair features (alpha, phi, theta) of Rusu et al. 2009, Eq. (1)-(3), with the
/// source/target choice of the original (the point whose normal is closer to the connecting line
/// is the source). Returns false for coincident points or a degenerate frame.
bool pairFeatures(const Eigen::Vector3f& p1, const Eigen::Vector3f& n1, const Eigen::Vector3f& p2,
                  const Eigen::Vector3f& n2, float* f_alpha, float* f_phi, float* f_theta) {
    Eigen::Vector3f dp = p2 - p1;
    const float dist = dp.norm();
    if (dist == 0.0f) return false;
    Eigen::Vector3f ns = n1, nt = n2;
    const float a1 = n1.dot(dp) / dist;
    const float a2 = n2.dot(dp) / dist;
    float phi = a1;
    if (std::abs(a1) < std::abs(a2)) {  // acos(|a1|) > acos(|a2|)
        ns = n2;
        nt = n1;
        dp = -dp;
        phi = -a2;
    }
    Eigen::Vector3f v = dp.cross(ns);
    const float vn = v.norm();
    if (vn == 0.0f) return false;
    v /= vn;
    const Eigen::Vector3f w = ns.cross(v);
    *f_theta = std::atan2(w.dot(nt), ns.dot(nt));  // angle in [-pi, pi]
    *f_alpha = v.dot(nt);                          // in [-1, 1]
    *f_phi = phi;                                  // in [-1, 1]
    return true;
}

inline int bin11(float x, float lo, float hi) {
    const int b = static_cast<int>(std::floor(11.0f * (x - lo) / (hi - lo)));
    return std::clamp(b, 0, 10);
}

}  // namespace

std::vector<Fpfh33> computeFpfh(const PointCloud& cloud, double radius_m, int max_nn,
                                int num_threads) {
    const size_t n = cloud.size();
    std::vector<Fpfh33> fpfh(n);
    if (n == 0 || !cloud.hasNormals()) return fpfh;
    const detail::KdTree3 tree(cloud.points);
    const float r2 = static_cast<float>(radius_m * radius_m);
    const size_t k = static_cast<size_t>(std::max(2, max_nn));
    // Neighbour lists (self first, as the hybrid search returns it) shared by both passes.
    std::vector<uint32_t> nbr(n * k);
    std::vector<float> nbr_d2(n * k);
    std::vector<uint32_t> count(n);
    std::vector<Fpfh33> spfh(n);
    detail::parallelFor(num_threads, n, [&](size_t i) {
        uint32_t* idx = &nbr[i * k];
        float* d2 = &nbr_d2[i * k];
        const size_t m = tree.knnWithin(cloud.points[i], k, r2, idx, d2);
        count[i] = static_cast<uint32_t>(m);
        // Simplified point feature histogram (SPFH) of point i, Rusu 2009 §IV.
        Fpfh33& h = spfh[i];
        h.fill(0.0f);
        if (m <= 1) return;
        const float incr = 100.0f / static_cast<float>(m - 1);
        for (size_t j = 0; j < m; ++j) {
            if (idx[j] == i) continue;
            float fa = 0.0f, fp = 0.0f, ft = 0.0f;
            if (!pairFeatures(cloud.points[i], cloud.normals[i], cloud.points[idx[j]],
                              cloud.normals[idx[j]], &fa, &fp, &ft)) {
                continue;
            }
            h[bin11(ft, -std::numbers::pi_v<float>, std::numbers::pi_v<float>)] += incr;
            h[11 + bin11(fa, -1.0f, 1.0f)] += incr;
            h[22 + bin11(fp, -1.0f, 1.0f)] += incr;
        }
    });
    // FPFH(p) = SPFH(p) + normalised sum_k SPFH(p_k) / |p - p_k|^2  (Rusu 2009, Eq. (4), with the
    // squared-distance weight and per-block normalisation to 100 used by Open3D).
    detail::parallelFor(num_threads, n, [&](size_t i) {
        Fpfh33 acc;
        acc.fill(0.0f);
        const uint32_t* idx = &nbr[i * k];
        const float* d2 = &nbr_d2[i * k];
        for (size_t j = 0; j < count[i]; ++j) {
            if (idx[j] == i || d2[j] == 0.0f) continue;
            const float w = 1.0f / d2[j];
            const Fpfh33& s = spfh[idx[j]];
            for (int b = 0; b < 33; ++b) acc[b] += w * s[b];
        }
        for (int block = 0; block < 3; ++block) {
            float sum = 0.0f;
            for (int b = 0; b < 11; ++b) sum += acc[block * 11 + b];
            const float scale = sum > 0.0f ? 100.0f / sum : 0.0f;
            for (int b = 0; b < 11; ++b) acc[block * 11 + b] *= scale;
        }
        for (int b = 0; b < 33; ++b) acc[b] += spfh[i][b];
        fpfh[i] = acc;
    });
    return fpfh;
}

Result<PreparedFragment> prepareFragment(const Fragment& fragment, const PrepareConfig& config) {
    const std::string name = "fragment " + std::to_string(fragment.id);
    if (!(config.voxel_size_m > 0.0) || !(config.fpfh_radius_m > 0.0) ||
        !(config.normal_radius_m > 0.0) || config.fpfh_max_nn < 2 || config.normal_max_nn < 3) {
        return invalidArgument(name + ": invalid preparation config (voxel, radii, neighbours)");
    }
    if (!fragment.points_F.isConsistent()) {
        return invalidArgument(name + ": normals or colours do not match the point count");
    }
    PointCloud source;
    source.points = fragment.points_F.points;
    if (fragment.points_F.hasNormals() && !config.recompute_normals) {
        source.normals = fragment.points_F.normals;
    }
    // Colours, when the device fused them, are averaged per voxel like the points.
    if (fragment.points_F.hasColors()) source.colors = fragment.points_F.colors;
    PreparedFragment out;
    out.id = fragment.id;
    out.points = detail::voxelDownsample(source, config.voxel_size_m);
    if (out.points.empty()) {
        // A fragment without (finite) points is legitimate (a short tail, tracking lost at once):
        // it is prepared empty and registration keeps it on its odometry edge.
        out.points.normals.clear();
        return out;
    }
    if (!out.points.hasNormals()) {
        // Orient towards the fragment's mean camera centre (reference §3.1).
        Eigen::Vector3d centre = Eigen::Vector3d::Zero();
        for (const FragmentFrame& f : fragment.frames) centre += f.T_F_C.translation();
        if (!fragment.frames.empty()) centre /= static_cast<double>(fragment.frames.size());
        out.points.normals =
            estimateNormals(out.points.points, config.normal_radius_m, config.normal_max_nn,
                            centre.cast<float>(), config.num_threads);
    }
    out.fpfh =
        computeFpfh(out.points, config.fpfh_radius_m, config.fpfh_max_nn, config.num_threads);
    return out;
}

}  // namespace plumb::registration
