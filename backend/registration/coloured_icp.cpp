// SPDX-License-Identifier: Apache-2.0
#include "backend/registration/coloured_icp.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "backend/registration/cloud_ops.hpp"
#include "common/image/image.hpp"

namespace plumb::registration {

std::vector<float> intensitiesOf(const std::vector<Color3u8>& colors) {
    std::vector<float> out(colors.size());
    for (size_t i = 0; i < colors.size(); ++i) {
        out[i] = intensity(Rgb8{colors[i][0], colors[i][1], colors[i][2]});
    }
    return out;
}

namespace {

/// intensityGradients over `cloud`, its neighbours from knn(q, k, radius_sq, indices, dists_sq)
/// (KdTree3::knnWithin's contract).
template <typename Knn>
std::vector<Eigen::Vector3f> fitGradients(const PointCloud& cloud,
                                          const std::vector<float>& intensity, double radius_m,
                                          int max_nn, int num_threads, const Knn& knn) {
    const size_t n = cloud.size();
    std::vector<Eigen::Vector3f> gradient(n, Eigen::Vector3f::Zero());
    const float r2 = static_cast<float>(radius_m * radius_m);
    const size_t k = static_cast<size_t>(std::max(4, max_nn));
    // A neighbourhood spans the tangent plane when the smaller eigenvalue of its second moment
    // (per point) is at least this: nearly collinear neighbours leave one direction unfitted.
    const double min_moment = 0.01 * radius_m * radius_m;
    const auto fit = [&](size_t i, uint32_t* idx, float* d2) {
        const size_t m = knn(cloud.points[i], k, r2, idx, d2);
        if (m < 4) return;  // the point and at least 3 others
        const Eigen::Vector3d p = cloud.points[i].cast<double>();
        const Eigen::Vector3d normal = cloud.normals[i].cast<double>().normalized();
        // Orthonormal tangent basis (e1, e2) of the plane through p with normal n_p. The
        // coordinates of p' - p in it are those of f(p') - p (Eq. (4)): the projection only
        // drops the normal component.
        const Eigen::Vector3d axis =
            std::abs(normal.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
        const Eigen::Vector3d e1 = normal.cross(axis).normalized();
        const Eigen::Vector3d e2 = normal.cross(e1);
        // Eq. (6) in tangent coordinates u: min_g Σ (g·u_k - (C(p_k) - C(p)))^2, normal
        // equations A g = b with A = Σ u u^T, b = Σ u (C(p_k) - C(p)); d_p = g1 e1 + g2 e2
        // satisfies d_p·n_p = 0 exactly.
        Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
        Eigen::Vector2d b = Eigen::Vector2d::Zero();
        const double c_p = intensity[i];
        for (size_t j = 0; j < m; ++j) {
            const Eigen::Vector3d offset = cloud.points[idx[j]].cast<double>() - p;
            const Eigen::Vector2d u(e1.dot(offset), e2.dot(offset));
            A.noalias() += u * u.transpose();
            b.noalias() += u * (static_cast<double>(intensity[idx[j]]) - c_p);
        }
        // Smaller eigenvalue of the symmetric 2x2 A, per point.
        const double half_trace = 0.5 * (A(0, 0) + A(1, 1));
        const double gap =
            std::sqrt(0.25 * (A(0, 0) - A(1, 1)) * (A(0, 0) - A(1, 1)) + A(0, 1) * A(0, 1));
        if (!((half_trace - gap) / static_cast<double>(m) >= min_moment)) return;
        const double det = A(0, 0) * A(1, 1) - A(0, 1) * A(1, 0);
        const Eigen::Vector2d g((A(1, 1) * b(0) - A(0, 1) * b(1)) / det,
                                (A(0, 0) * b(1) - A(1, 0) * b(0)) / det);
        const Eigen::Vector3d d = g(0) * e1 + g(1) * e2;
        if (d.allFinite()) gradient[i] = d.cast<float>();
    };
    // Fixed chunks of points share their neighbour buffers (each point's fit is independent).
    constexpr size_t kPointsPerChunk = 512;
    detail::parallelFor(num_threads, (n + kPointsPerChunk - 1) / kPointsPerChunk, [&](size_t c) {
        std::vector<uint32_t> idx(k);
        std::vector<float> d2(k);
        const size_t end = std::min(n, (c + 1) * kPointsPerChunk);
        for (size_t i = c * kPointsPerChunk; i < end; ++i) fit(i, idx.data(), d2.data());
    });
    return gradient;
}

}  // namespace

std::vector<Eigen::Vector3f> intensityGradients(const PointCloud& cloud,
                                                const std::vector<float>& intensity,
                                                double radius_m, int max_nn, int num_threads) {
    if (cloud.empty() || !cloud.hasNormals() || intensity.size() != cloud.size())
        return std::vector<Eigen::Vector3f>(cloud.size(), Eigen::Vector3f::Zero());
    const detail::KdTree3 tree(cloud.points);
    return fitGradients(cloud, intensity, radius_m, max_nn, num_threads,
                        [&tree](const Eigen::Vector3f& q, size_t k, float r2, uint32_t* idx,
                                float* d2) { return tree.knnWithin(q, k, r2, idx, d2); });
}

std::vector<Eigen::Vector3f> intensityGradients(const IndexedCloud& cloud,
                                                const std::vector<float>& intensity,
                                                double radius_m, int max_nn, int num_threads) {
    const PointCloud& points = cloud.cloud();
    if (points.empty() || !points.hasNormals() || intensity.size() != points.size())
        return std::vector<Eigen::Vector3f>(points.size(), Eigen::Vector3f::Zero());
    return fitGradients(points, intensity, radius_m, max_nn, num_threads,
                        [&cloud](const Eigen::Vector3f& q, size_t k, float r2, uint32_t* idx,
                                 float* d2) { return cloud.knnWithin(q, k, r2, idx, d2); });
}

double colourResidual(const Eigen::Vector3d& p, const Eigen::Vector3d& n_p, double c_p,
                      const Eigen::Vector3d& d_p, const Eigen::Vector3d& x, double c_q,
                      Eigen::Matrix<double, 1, 6>* jacobian) {
    // Eq. (4): f(x) = x - ((x - p)·n_p) n_p; Eq. (5): C_p(f(x)); Eq. (3): minus C(q).
    const Eigen::Vector3d f = x - (x - p).dot(n_p) * n_p;
    const double r = c_p + d_p.dot(f - p) - c_q;
    if (jacobian != nullptr) {
        // d_p^T [-[x]_x | I] = [(x × d_p)^T, d_p^T]  (d_p ⟂ n_p, see the header).
        jacobian->head<3>() = x.cross(d_p).transpose();
        jacobian->tail<3>() = d_p.transpose();
    }
    return r;
}

namespace {

struct ColouredAcc {
    Matrix6d H = Matrix6d::Zero();
    Vector6d g = Vector6d::Zero();
    double err = 0.0;         ///< Σ r_G^2, point-to-plane
    double colour_err = 0.0;  ///< Σ r_C^2
    int64_t count = 0;
};

constexpr size_t kChunk = 256;

/// Two consecutive steps that cancel to within this fraction of the latest one are a limit
/// cycle (see icpColoured).
constexpr double kCycleRatio = 0.1;

}  // namespace

PairResult icpColoured(const IndexedCloud& source, const std::vector<float>& source_intensity,
                       const std::vector<Eigen::Vector3f>& source_gradient,
                       const PointCloud& target, const std::vector<float>& target_intensity,
                       const Eigen::Isometry3d& init, double max_distance_m, int max_iterations,
                       double relative_change, double lambda_geometric, double min_normal_spread,
                       int num_threads) {
    PairResult out;
    out.T_source_target = init;
    const PointCloud& src = source.cloud();
    if (!src.hasNormals() || src.empty() || target.empty()) {
        out.reason = "coloured ICP: empty cloud or source without normals";
        return out;
    }
    if (source_intensity.size() != src.size() || source_gradient.size() != src.size() ||
        target_intensity.size() != target.size()) {
        out.reason = "coloured ICP: intensities or gradients do not match the point counts";
        return out;
    }
    if (!(lambda_geometric > 0.0 && lambda_geometric <= 1.0)) {
        out.reason = "coloured ICP: lambda_geometric must lie in (0, 1]";
        return out;
    }
    const double w_geometric = lambda_geometric;     // δ
    const double w_colour = 1.0 - lambda_geometric;  // 1 - δ
    const float max_d2 = static_cast<float>(max_distance_m * max_distance_m);
    Eigen::Isometry3d T = init;
    double prev_fitness = -1.0, prev_rmse = -1.0, prev_colour_rmse = -1.0;
    Vector6d prev_xi = Vector6d::Zero();
    const ColouredAcc zero;
    // Each target point's nearest source point of the previous iteration: the next search
    // starts from it (IndexedCloud::nearest with a hint; the same correspondences).
    constexpr uint32_t kNoHint = std::numeric_limits<uint32_t>::max();
    std::vector<uint32_t> previous(target.size(), kNoHint);
    for (int it = 0; it < max_iterations; ++it) {
        const Eigen::Matrix3f R = T.rotation().cast<float>();
        const Eigen::Vector3f t = T.translation().cast<float>();
        const ColouredAcc acc = detail::chunkedReduce(
            num_threads, target.size(), kChunk, zero,
            [&](ColouredAcc& a, size_t i) {
                const Eigen::Vector3f x = R * target.points[i] + t;
                uint32_t j = 0;
                float d2 = 0.0f;
                uint32_t& hint = previous[i];  // this iteration's chunk of i alone writes it
                if (!source.nearest(x, max_d2, hint, &j, &d2)) {
                    hint = kNoHint;
                    return;
                }
                hint = j;
                const Eigen::Vector3d p = src.points[j].cast<double>();
                const Eigen::Vector3d n = src.normals[j].cast<double>();
                const Eigen::Vector3d xd = x.cast<double>();
                // Geometric residual, Eq. (2): r_G = n_p·(x - p), J_G = [(x × n_p)^T, n_p^T].
                const double r_g = n.dot(xd - p);
                Vector6d J_g;
                J_g.head<3>() = xd.cross(n);
                J_g.tail<3>() = n;
                // Colour residual, Eq. (3)-(5), with its Jacobian (colourResidual).
                Eigen::Matrix<double, 1, 6> J_c;
                const double r_c =
                    colourResidual(p, n, source_intensity[j], source_gradient[j].cast<double>(), xd,
                                   target_intensity[i], &J_c);
                // Normal equations of Eq. (1): Σ δ J_G^T J_G + (1 - δ) J_C^T J_C and the
                // matching gradient.
                a.H.noalias() += w_geometric * (J_g * J_g.transpose());
                a.H.noalias() += w_colour * (J_c.transpose() * J_c);
                a.g.noalias() += (w_geometric * r_g) * J_g;
                a.g.noalias() += (w_colour * r_c) * J_c.transpose();
                a.err += r_g * r_g;
                a.colour_err += r_c * r_c;
                ++a.count;
            },
            [](ColouredAcc& total, const ColouredAcc& part) {
                total.H += part.H;
                total.g += part.g;
                total.err += part.err;
                total.colour_err += part.colour_err;
                total.count += part.count;
            });
        out.iterations = it + 1;
        if (acc.count < 6) {
            out.reason = "coloured ICP: fewer than 6 correspondences within " +
                         std::to_string(max_distance_m) + " m";
            out.T_source_target = T;
            return out;
        }
        const double fitness = static_cast<double>(acc.count) / static_cast<double>(target.size());
        const double rmse = std::sqrt(acc.err / static_cast<double>(acc.count));
        out.overlap = fitness;
        out.inlier_rmse_m = rmse;
        const double colour_rmse = std::sqrt(acc.colour_err / static_cast<double>(acc.count));
        out.num_correspondences = static_cast<int>(acc.count);
        // The colour RMSE takes part: a slide along a textured wall changes neither the fitness
        // nor the point-to-plane RMSE, only the colour term.
        if (it > 0 && std::abs(fitness - prev_fitness) < relative_change &&
            std::abs(rmse - prev_rmse) < relative_change &&
            std::abs(colour_rmse - prev_colour_rmse) < relative_change) {
            break;
        }
        prev_fitness = fitness;
        prev_rmse = rmse;
        prev_colour_rmse = colour_rmse;
        // Spread in the units of the point-to-plane one (mean (n·t)^2): the combined translation
        // block over δ and the correspondence count. Without colour it is Σ n n^T / count.
        const Eigen::Matrix3d spread =
            acc.H.bottomRightCorner<3, 3>() / (w_geometric * static_cast<double>(acc.count));
        const Vector6d xi = remappedStep(acc.H, acc.g, spread, min_normal_spread);
        if (!xi.allFinite()) {
            out.reason = "coloured ICP: singular normal equations";
            out.T_source_target = T;
            return out;
        }
        // Limit cycle: the colour residual of a point jumps when its nearest neighbour changes
        // (each p has its own tangent-plane model, Eq. (5)), so Gauss-Newton can flip between
        // two poses whose correspondences favour each other. When this step undoes the last one
        // (|ξ_k + ξ_k-1| < kCycleRatio |ξ_k|, radians and metres alike), stop half-way between
        // the two instead of flipping until the iteration cap.
        if (it > 0 && (xi + prev_xi).norm() < kCycleRatio * xi.norm()) {
            T = lie::orthonormalized(lie::expSE3(0.5 * xi) * T);
            break;
        }
        prev_xi = xi;
        T = lie::orthonormalized(lie::expSE3(xi) * T);
    }
    out.T_source_target = T;
    out.success = true;
    return out;
}

}  // namespace plumb::registration
