// SPDX-License-Identifier: Apache-2.0
#include "backend/registration/pair_registration.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "backend/registration/cloud_ops.hpp"
#include "backend/registration/coloured_icp.hpp"
#include "common/geometry/solution_remapping.hpp"

namespace plumb::registration {

void describe(config::Schema& s, IcpConfig& c) {
    s.field("voxel_sizes_m", c.voxel_sizes_m, "voxel sizes of the ICP pyramid, coarse to fine", "m")
        .positive();
    s.field("iterations", c.iterations, "ICP iterations per pyramid level").min(1);
    s.field("distance_factor", c.distance_factor,
            "correspondence distance per level = factor x level voxel size")
        .positive();
    s.field("relative_change", c.relative_change,
            "stop a level when fitness and RMSE change by less than this")
        .min(0.0);
    s.field("min_normal_spread", c.min_normal_spread,
            "translations t with mean (n.t)^2 over the correspondences below this are not solved "
            "for and keep the start (solution remapping; 0 = plain Gauss-Newton)")
        .min(0.0);
    s.field("coloured_min_normal_spread", c.coloured_min_normal_spread,
            "min_normal_spread of pairs of fragments tracked with colour (coloured ICP): their "
            "odometry start is reliable along what RGB-D tracking observed")
        .min(0.0);
    s.field("colour", c.colour,
            "coloured ICP (Park et al. 2017) instead of point-to-plane where both fragments "
            "carry colour; depth-only fragments keep point-to-plane");
    s.field("lambda_geometric", c.lambda_geometric,
            "coloured ICP: weight delta of the geometric term in (1 - delta) E_colour + delta "
            "E_geometric (Open3D: 0.968)")
        .greaterThan(0.0)
        .max(1.0);
    s.field("colour_gradient_radius_factor", c.colour_gradient_radius_factor,
            "coloured ICP: radius of the intensity gradient fit = factor x the level's voxel size "
            "(Open3D: 2.8)",
            "voxels")
        .positive();
    s.field("colour_gradient_max_nn", c.colour_gradient_max_nn,
            "coloured ICP: at most this many neighbours in the intensity gradient fit", "points")
        .min(3);
    s.field("max_target_points", c.max_target_points,
            "at most this many target points take part at a level of the multi-scale ICP "
            "(evenly strided; the source keeps all of its points); 0 = every point",
            "points")
        .min(0);
    s.field("num_threads", c.num_threads, "worker threads, 0 = all; results do not depend on it")
        .min(0);
}

void describe(config::Schema& s, RansacConfig& c) {
    s.field("max_correspondence_distance_m", c.max_correspondence_distance_m,
            "inlier distance of a feature correspondence", "m")
        .positive();
    s.field("mutual_filter", c.mutual_filter,
            "keep only mutual nearest neighbours in feature space");
    s.field("edge_length_similarity", c.edge_length_similarity,
            "edge-length checker: minimum ratio of corresponding sample edges")
        .range(0.0, 1.0);
    s.field("max_iterations", c.max_iterations, "RANSAC iteration cap").min(1);
    s.field("confidence", c.confidence, "RANSAC early-exit confidence").range(0.0, 1.0);
    s.field("min_inliers", c.min_inliers, "fewer inlier correspondences is a failure").min(3);
    s.field("num_threads", c.num_threads,
            "worker threads of the feature matching, 0 = all; results do not depend on it")
        .min(0);
}

// ---- IndexedCloud ----

struct IndexedCloud::Impl {
    explicit Impl(PointCloud c) : cloud(std::move(c)), tree(cloud.points) {}
    PointCloud cloud;
    detail::KdTree3 tree;
};

IndexedCloud::IndexedCloud() : impl_(std::make_unique<Impl>(PointCloud{})) {}
IndexedCloud::IndexedCloud(PointCloud cloud) : impl_(std::make_unique<Impl>(std::move(cloud))) {}
IndexedCloud::~IndexedCloud() = default;
IndexedCloud::IndexedCloud(IndexedCloud&&) noexcept = default;
IndexedCloud& IndexedCloud::operator=(IndexedCloud&&) noexcept = default;
const PointCloud& IndexedCloud::cloud() const { return impl_->cloud; }
size_t IndexedCloud::size() const { return impl_->cloud.size(); }
bool IndexedCloud::nearest(const Eigen::Vector3f& q, float max_dist_sq, uint32_t* index,
                           float* dist_sq) const {
    return impl_->tree.nearest(q, max_dist_sq, index, dist_sq);
}
bool IndexedCloud::nearest(const Eigen::Vector3f& q, float max_dist_sq, uint32_t hint,
                           uint32_t* index, float* dist_sq) const {
    return impl_->tree.nearest(q, max_dist_sq, hint, index, dist_sq);
}
size_t IndexedCloud::knnWithin(const Eigen::Vector3f& q, size_t k, float radius_sq,
                               uint32_t* indices, float* dists_sq) const {
    return impl_->tree.knnWithin(q, k, radius_sq, indices, dists_sq);
}

FragmentIndex buildFragmentIndex(const Fragment& fragment, const PreparedFragment& prepared,
                                 const IcpConfig& config) {
    FragmentIndex index;
    index.id = prepared.id;
    index.coarse = IndexedCloud(prepared.points);
    PointCloud full;
    full.points = fragment.points_F.points;
    if (fragment.points_F.hasNormals()) full.normals = fragment.points_F.normals;
    const bool with_colour = config.colour && fragment.points_F.hasColors();
    if (with_colour) full.colors = fragment.points_F.colors;
    for (const double v : config.voxel_sizes_m) {
        PointCloud level = detail::voxelDownsample(full, v);
        if (!level.hasNormals()) {
            // Without fused normals use the prepared normals' recipe: PCA over 2 voxels.
            level.normals = estimateNormals(level.points, 2.0 * v, 30, Eigen::Vector3f::Zero(),
                                            config.num_threads);
        }
        index.levels.emplace_back(std::move(level));
        if (with_colour) {
            const IndexedCloud& indexed = index.levels.back();
            LevelColour colour;
            colour.intensity = intensitiesOf(indexed.cloud().colors);
            colour.gradient = intensityGradients(indexed, colour.intensity,
                                                 config.colour_gradient_radius_factor * v,
                                                 config.colour_gradient_max_nn, config.num_threads);
            index.level_colours.push_back(std::move(colour));
        }
    }
    const size_t n = prepared.fpfh.size();
    index.features.resize(33, static_cast<Eigen::Index>(n));
    for (size_t i = 0; i < n; ++i) {
        for (int b = 0; b < 33; ++b)
            index.features(b, static_cast<Eigen::Index>(i)) = prepared.fpfh[i][b];
    }
    index.feature_sq_norms = index.features.colwise().squaredNorm().transpose();
    return index;
}

// ---- ICP ----

namespace {

struct IcpAcc {
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Vector6d g = Vector6d::Zero();
    double err = 0.0;
    int64_t count = 0;
};

constexpr size_t kChunk = 256;

}  // namespace

Vector6d remappedStep(const Matrix6d& H, const Vector6d& g, const Eigen::Matrix3d& spread,
                      double min_normal_spread) {
    if (min_normal_spread > 0.0) {
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> spread_eigen(spread);
        if (!(spread_eigen.eigenvalues()(0) >= min_normal_spread)) {
            using Square = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 6, 6>;
            using Vector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 6, 1>;
            const remapping::Basis basis =
                remapping::solvedDirections(spread_eigen, min_normal_spread);
            const Square H_reduced = basis.transpose() * H * basis;
            const Vector g_reduced = basis.transpose() * g;
            return basis * Vector(H_reduced.ldlt().solve(-g_reduced));
        }
    }
    return H.ldlt().solve(-g);
}

PairResult icpPointToPlane(const IndexedCloud& source, const PointCloud& target,
                           const Eigen::Isometry3d& init, double max_distance_m, int max_iterations,
                           double relative_change, double min_normal_spread, int num_threads) {
    PairResult out;
    out.T_source_target = init;
    const PointCloud& src = source.cloud();
    if (!src.hasNormals() || src.empty() || target.empty()) {
        out.reason = "ICP: empty cloud or source without normals";
        return out;
    }
    const float max_d2 = static_cast<float>(max_distance_m * max_distance_m);
    Eigen::Isometry3d T = init;
    double prev_fitness = -1.0, prev_rmse = -1.0;
    const IcpAcc zero;
    // Each target point's nearest source point of the previous iteration: the next search
    // starts from it (IndexedCloud::nearest with a hint; the same correspondences).
    constexpr uint32_t kNoHint = std::numeric_limits<uint32_t>::max();
    std::vector<uint32_t> previous(target.size(), kNoHint);
    for (int it = 0; it < max_iterations; ++it) {
        const Eigen::Matrix3f R = T.rotation().cast<float>();
        const Eigen::Vector3f t = T.translation().cast<float>();
        const IcpAcc acc = detail::chunkedReduce(
            num_threads, target.size(), kChunk, zero,
            [&](IcpAcc& a, size_t i) {
                const Eigen::Vector3f x = R * target.points[i] + t;
                uint32_t j = 0;
                float d2 = 0.0f;
                uint32_t& hint = previous[i];  // this iteration's chunk of i alone writes it
                if (!source.nearest(x, max_d2, hint, &j, &d2)) {
                    hint = kNoHint;
                    return;
                }
                hint = j;
                const Eigen::Vector3d n = src.normals[j].cast<double>();
                const Eigen::Vector3d xd = x.cast<double>();
                const double r = n.dot(xd - src.points[j].cast<double>());
                // d(n·(Exp(ξ) x - p))/dξ = n^T [-[x]_x | I] = [(x × n)^T, n^T].
                Vector6d J;
                J.head<3>() = xd.cross(n);
                J.tail<3>() = n;
                a.H.noalias() += J * J.transpose();
                a.g.noalias() += J * r;
                a.err += r * r;
                ++a.count;
            },
            [](IcpAcc& total, const IcpAcc& part) {
                total.H += part.H;
                total.g += part.g;
                total.err += part.err;
                total.count += part.count;
            });
        out.iterations = it + 1;
        if (acc.count < 6) {
            out.reason =
                "ICP: fewer than 6 correspondences within " + std::to_string(max_distance_m) + " m";
            out.T_source_target = T;
            return out;
        }
        const double fitness = static_cast<double>(acc.count) / static_cast<double>(target.size());
        const double rmse = std::sqrt(acc.err / static_cast<double>(acc.count));
        out.overlap = fitness;
        out.inlier_rmse_m = rmse;
        out.num_correspondences = static_cast<int>(acc.count);
        if (it > 0 && std::abs(fitness - prev_fitness) < relative_change &&
            std::abs(rmse - prev_rmse) < relative_change) {
            break;
        }
        prev_fitness = fitness;
        prev_rmse = rmse;
        // Spread = Σ n n^T / count, H's translation block per correspondence.
        const Vector6d xi = remappedStep(
            acc.H, acc.g, acc.H.bottomRightCorner<3, 3>() / static_cast<double>(acc.count),
            min_normal_spread);
        if (!xi.allFinite()) {
            out.reason = "ICP: singular normal equations";
            out.T_source_target = T;
            return out;
        }
        T = lie::orthonormalized(lie::expSE3(xi) * T);
    }
    out.T_source_target = T;
    out.success = true;
    return out;
}

namespace {

/// A level's target points for ICP: the cloud itself, or every k-th point (and intensity) with
/// the smallest k that leaves at most max_points (> 0).
class StridedTarget {
  public:
    StridedTarget(const PointCloud& cloud, const std::vector<float>* intensity, int max_points)
        : cloud_(&cloud), intensity_(intensity) {
        const size_t n = cloud.size();
        if (max_points <= 0 || n <= static_cast<size_t>(max_points)) return;
        const size_t cap = static_cast<size_t>(max_points);
        const size_t stride = (n + cap - 1) / cap;
        strided_ = true;
        strided_cloud_.points.reserve(n / stride + 1);
        for (size_t i = 0; i < n; i += stride) {
            strided_cloud_.points.push_back(cloud.points[i]);
            if (intensity != nullptr) strided_intensity_.push_back((*intensity)[i]);
        }
    }
    const PointCloud& cloud() const { return strided_ ? strided_cloud_ : *cloud_; }
    /// Empty when there is no intensity.
    const std::vector<float>& intensity() const {
        static const std::vector<float> kNone;
        if (intensity_ == nullptr) return kNone;
        return strided_ ? strided_intensity_ : *intensity_;
    }

  private:
    const PointCloud* cloud_;
    const std::vector<float>* intensity_;
    bool strided_ = false;
    PointCloud strided_cloud_;
    std::vector<float> strided_intensity_;
};

}  // namespace

PairResult multiScaleIcp(const FragmentIndex& source, const FragmentIndex& target,
                         const Eigen::Isometry3d& init, const IcpConfig& config) {
    PairResult r;
    r.T_source_target = init;
    const size_t levels = std::min(source.levels.size(), target.levels.size());
    int total_iterations = 0;
    for (size_t l = 0; l < levels && l < config.voxel_sizes_m.size(); ++l) {
        const int iters =
            l < config.iterations.size() ? static_cast<int>(config.iterations[l]) : 30;
        const double max_distance_m = config.distance_factor * config.voxel_sizes_m[l];
        const bool coloured =
            config.colour && l < source.level_colours.size() && l < target.level_colours.size();
        const StridedTarget strided(target.levels[l].cloud(),
                                    coloured ? &target.level_colours[l].intensity : nullptr,
                                    config.max_target_points);
        PairResult step =
            coloured ? icpColoured(source.levels[l], source.level_colours[l].intensity,
                                   source.level_colours[l].gradient, strided.cloud(),
                                   strided.intensity(), r.T_source_target, max_distance_m, iters,
                                   config.relative_change, config.lambda_geometric,
                                   config.coloured_min_normal_spread, config.num_threads)
                     : icpPointToPlane(source.levels[l], strided.cloud(), r.T_source_target,
                                       max_distance_m, iters, config.relative_change,
                                       config.min_normal_spread, config.num_threads);
        total_iterations += step.iterations;
        if (!step.success) {
            step.reason += " (level " + std::to_string(l) + ")";
            step.iterations = total_iterations;
            return step;
        }
        r = step;
    }
    r.iterations = total_iterations;
    r.success = true;
    return r;
}

// ---- Evaluation ----

PairResult evaluateAlignment(const FragmentIndex& source, const FragmentIndex& target,
                             const Eigen::Isometry3d& T_source_target, double tau_m,
                             int num_threads) {
    PairResult out;
    out.T_source_target = T_source_target;
    const PointCloud& tgt = target.coarse.cloud();
    const PointCloud& src = source.coarse.cloud();
    const float tau2 = static_cast<float>(tau_m * tau_m);
    const Eigen::Matrix3f R = T_source_target.rotation().cast<float>();
    const Eigen::Vector3f t = T_source_target.translation().cast<float>();
    struct Acc {
        Matrix6d info = Matrix6d::Zero();
        Matrix6d plane = Matrix6d::Zero();
        double err = 0.0;
        int64_t count = 0;
    };
    const bool normals = tgt.hasNormals();
    // Λ = Σ_q G_q^T G_q over target points q (target frame) with a source neighbour within τ,
    // G_q = [-[q]_x | I_3] (reference §3.4).
    const Acc acc = detail::chunkedReduce(
        num_threads, tgt.size(), kChunk, Acc{},
        [&](Acc& a, size_t i) {
            const Eigen::Vector3f& q = tgt.points[i];
            uint32_t j = 0;
            float d2 = 0.0f;
            if (!source.coarse.nearest(R * q + t, tau2, &j, &d2)) return;
            Eigen::Matrix<double, 3, 6> G = lie::pointJacobian(q.cast<double>());
            a.info.noalias() += G.transpose() * G;
            if (normals) {
                const Eigen::Vector3d n = tgt.normals[i].cast<double>();
                Vector6d J;
                J << q.cast<double>().cross(n), n;
                a.plane.noalias() += J * J.transpose();
            }
            a.err += d2;
            ++a.count;
        },
        [](Acc& total, const Acc& part) {
            total.info += part.info;
            total.plane += part.plane;
            total.err += part.err;
            total.count += part.count;
        });
    out.information = acc.info;
    out.plane_information = acc.plane;
    out.num_correspondences = static_cast<int>(acc.count);
    out.inlier_rmse_m = acc.count > 0 ? std::sqrt(acc.err / static_cast<double>(acc.count)) : 0.0;
    // Overlap over the smaller fragment (Choi's test: ≥ 30 % of it within τ of the other).
    int64_t matched = 0;
    size_t smaller = 0;
    if (tgt.size() <= src.size()) {
        matched = acc.count;
        smaller = tgt.size();
    } else {
        const Eigen::Isometry3d T_ts = T_source_target.inverse();
        const Eigen::Matrix3f Ri = T_ts.rotation().cast<float>();
        const Eigen::Vector3f ti = T_ts.translation().cast<float>();
        matched = detail::chunkedReduce(
            num_threads, src.size(), kChunk, int64_t{0},
            [&](int64_t& a, size_t i) {
                uint32_t j = 0;
                float d2 = 0.0f;
                if (target.coarse.nearest(Ri * src.points[i] + ti, tau2, &j, &d2)) ++a;
            },
            [](int64_t& total, const int64_t& part) { total += part; });
        smaller = src.size();
    }
    out.overlap = smaller > 0 ? static_cast<double>(matched) / static_cast<double>(smaller) : 0.0;
    out.success = true;
    return out;
}

// ---- RANSAC ----

Eigen::Isometry3d fitRigid(const std::vector<Eigen::Vector3d>& p,
                           const std::vector<Eigen::Vector3d>& q) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    const size_t n = std::min(p.size(), q.size());
    if (n < 3) return T;
    Eigen::Vector3d mp = Eigen::Vector3d::Zero(), mq = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < n; ++i) {
        mp += p[i];
        mq += q[i];
    }
    mp /= static_cast<double>(n);
    mq /= static_cast<double>(n);
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
    for (size_t i = 0; i < n; ++i) S += (p[i] - mp) * (q[i] - mq).transpose();
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(S, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
    if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0) D(2, 2) = -1.0;
    const Eigen::Matrix3d R = svd.matrixU() * D * svd.matrixV().transpose();
    T.linear() = R;
    T.translation() = mp - R * mq;
    return T;
}

namespace {

/// Nearest neighbours in feature space both ways by blocked dense products:
/// |a - b|^2 = |a|^2 + |b|^2 - 2 a·b. Ties go to the lower index. The target columns are cut into
/// fixed chunks (independent of the thread count); each chunk finds its columns' nearest sources
/// and its own best target per source, and the chunks' bests are merged in chunk order, so the
/// result equals the serial scan. Source rows are blocked so a block of products stays in cache.
void matchFeatures(const FragmentIndex& source, const FragmentIndex& target, int num_threads,
                   std::vector<int>* target_to_source, std::vector<int>* source_to_target) {
    const Eigen::Index ns = source.features.cols(), nt = target.features.cols();
    target_to_source->assign(static_cast<size_t>(nt), -1);
    source_to_target->assign(static_cast<size_t>(ns), -1);
    constexpr Eigen::Index kColumns = 256, kRows = 512;
    const size_t num_chunks = static_cast<size_t>((nt + kColumns - 1) / kColumns);
    struct Best {
        std::vector<float> d;
        std::vector<int> index;
    };
    std::vector<Best> chunk_best(num_chunks);
    detail::parallelFor(num_threads, num_chunks, [&](size_t chunk) {
        const Eigen::Index c0 = static_cast<Eigen::Index>(chunk) * kColumns;
        const Eigen::Index cn = std::min(kColumns, nt - c0);
        Best& best_s = chunk_best[chunk];
        best_s.d.assign(static_cast<size_t>(ns), std::numeric_limits<float>::max());
        best_s.index.assign(static_cast<size_t>(ns), -1);
        std::vector<float> best_t(static_cast<size_t>(cn), std::numeric_limits<float>::max());
        std::vector<int> best_t_index(static_cast<size_t>(cn), -1);
        std::vector<float> column(static_cast<size_t>(kRows));
        Eigen::MatrixXf dots;
        for (Eigen::Index r0 = 0; r0 < ns; r0 += kRows) {
            const int rn = static_cast<int>(std::min(kRows, ns - r0));
            dots.noalias() =
                source.features.middleCols(r0, rn).transpose() * target.features.middleCols(c0, cn);
            const float* __restrict source_norms = source.feature_sq_norms.data() + r0;
            float* __restrict best_d = best_s.d.data() + r0;
            int* __restrict best_index = best_s.index.data() + r0;
            float* __restrict d = column.data();
            for (Eigen::Index c = 0; c < cn; ++c) {
                const float tn = target.feature_sq_norms[c0 + c];
                const float* __restrict dot = &dots(0, c);
                const int target_index = static_cast<int>(c0 + c);
                // Branch-free so that it vectorises: the source's best is replaced only by a
                // strictly smaller distance (the lower target index keeps a tie).
                for (int r = 0; r < rn; ++r) {
                    d[r] = source_norms[r] + tn - 2.0f * dot[r];
                    const int closer = -static_cast<int>(d[r] < best_d[r]);
                    best_d[r] = std::min(best_d[r], d[r]);
                    best_index[r] = (target_index & closer) | (best_index[r] & ~closer);
                }
                // The column's nearest source: the first row at the minimum.
                const float m = Eigen::Map<const Eigen::VectorXf>(d, rn).minCoeff();
                if (m < best_t[static_cast<size_t>(c)]) {
                    int r = 0;
                    while (r + 1 < rn && d[r] != m) ++r;
                    best_t[static_cast<size_t>(c)] = m;
                    best_t_index[static_cast<size_t>(c)] = static_cast<int>(r0) + r;
                }
            }
        }
        std::copy(best_t_index.begin(), best_t_index.end(), target_to_source->begin() + c0);
    });
    std::vector<float> best(static_cast<size_t>(ns), std::numeric_limits<float>::max());
    for (const Best& chunk : chunk_best) {
        for (size_t r = 0; r < static_cast<size_t>(ns); ++r) {
            if (chunk.d[r] < best[r]) {
                best[r] = chunk.d[r];
                (*source_to_target)[r] = chunk.index[r];
            }
        }
    }
}

}  // namespace

PairResult ransacFeatureMatching(const FragmentIndex& source, const FragmentIndex& target,
                                 const RansacConfig& config, uint64_t seed) {
    PairResult out;
    const PointCloud& src = source.coarse.cloud();
    const PointCloud& tgt = target.coarse.cloud();
    if (src.size() < 3 || tgt.size() < 3 ||
        source.features.cols() != static_cast<Eigen::Index>(src.size()) ||
        target.features.cols() != static_cast<Eigen::Index>(tgt.size())) {
        out.reason = "RANSAC: fewer than 3 points or features missing";
        return out;
    }
    std::vector<int> t2s, s2t;
    matchFeatures(source, target, config.num_threads, &t2s, &s2t);
    // Correspondences (p = source point, q = target point).
    std::vector<std::pair<int, int>> corr;
    for (size_t i = 0; i < t2s.size(); ++i) {
        const int j = t2s[i];
        if (j < 0) continue;
        if (!config.mutual_filter || s2t[static_cast<size_t>(j)] == static_cast<int>(i)) {
            corr.emplace_back(j, static_cast<int>(i));
        }
    }
    if (config.mutual_filter && corr.size() < 10) {
        corr.clear();
        for (size_t i = 0; i < t2s.size(); ++i) {
            if (t2s[i] >= 0) corr.emplace_back(t2s[i], static_cast<int>(i));
        }
    }
    if (corr.size() < 3) {
        out.reason = "RANSAC: fewer than 3 feature correspondences";
        return out;
    }
    const size_t m = corr.size();
    std::vector<Eigen::Vector3d> P(m), Q(m);
    for (size_t k = 0; k < m; ++k) {
        P[k] = src.points[static_cast<size_t>(corr[k].first)].cast<double>();
        Q[k] = tgt.points[static_cast<size_t>(corr[k].second)].cast<double>();
    }
    const double tau = config.max_correspondence_distance_m;
    const double tau2 = tau * tau;
    std::mt19937_64 rng(seed);
    std::uniform_int_distribution<size_t> pick(0, m - 1);
    int best_inliers = 0;
    double best_err = std::numeric_limits<double>::max();
    Eigen::Isometry3d best_T = Eigen::Isometry3d::Identity();
    int needed = config.max_iterations;
    int it = 0;
    std::vector<Eigen::Vector3d> sp(3), sq(3);
    for (; it < needed; ++it) {
        size_t s[3];
        s[0] = pick(rng);
        do {
            s[1] = pick(rng);
        } while (s[1] == s[0] && m > 1);
        do {
            s[2] = pick(rng);
        } while ((s[2] == s[0] || s[2] == s[1]) && m > 2);
        // Edge-length checker (Open3D CorrespondenceCheckerBasedOnEdgeLength).
        bool ok = true;
        for (int a = 0; a < 3 && ok; ++a) {
            for (int b = a + 1; b < 3 && ok; ++b) {
                const double dp = (P[s[a]] - P[s[b]]).norm();
                const double dq = (Q[s[a]] - Q[s[b]]).norm();
                if (dp < config.edge_length_similarity * dq ||
                    dq < config.edge_length_similarity * dp) {
                    ok = false;
                }
            }
        }
        if (!ok) continue;
        for (int a = 0; a < 3; ++a) {
            sp[a] = P[s[a]];
            sq[a] = Q[s[a]];
        }
        const Eigen::Isometry3d T = fitRigid(sp, sq);
        // Distance checker on the sample.
        for (int a = 0; a < 3 && ok; ++a) ok = (T * sq[a] - sp[a]).squaredNorm() < tau2;
        if (!ok) continue;
        int inliers = 0;
        double err = 0.0;
        for (size_t k = 0; k < m; ++k) {
            const double d2 = (T * Q[k] - P[k]).squaredNorm();
            if (d2 < tau2) {
                ++inliers;
                err += d2;
            }
        }
        if (inliers > best_inliers || (inliers == best_inliers && inliers > 0 && err < best_err)) {
            best_inliers = inliers;
            best_err = err;
            best_T = T;
            // Early exit (Open3D 0.16): iterations for `confidence` at this inlier ratio.
            const double w = static_cast<double>(inliers) / static_cast<double>(m);
            const double w3 = w * w * w;
            if (w3 >= 1.0) {
                needed = it + 1;
            } else if (w3 > 0.0) {
                const double k = std::log(1.0 - config.confidence) / std::log(1.0 - w3);
                if (k < static_cast<double>(needed)) needed = static_cast<int>(std::ceil(k));
            }
        }
    }
    out.iterations = it;
    if (best_inliers < config.min_inliers) {
        out.reason = "RANSAC: best hypothesis has " + std::to_string(best_inliers) +
                     " inlier correspondences (< " + std::to_string(config.min_inliers) + ")";
        return out;
    }
    // Refit to all inliers of the best hypothesis.
    std::vector<Eigen::Vector3d> ip, iq;
    for (size_t k = 0; k < m; ++k) {
        if ((best_T * Q[k] - P[k]).squaredNorm() < tau2) {
            ip.push_back(P[k]);
            iq.push_back(Q[k]);
        }
    }
    out.T_source_target = fitRigid(ip, iq);
    out.ransac_inliers = best_inliers;
    out.success = true;
    return out;
}

}  // namespace plumb::registration
