// SPDX-License-Identifier: Apache-2.0
#pragma once

// Pairwise fragment registration (reference §3.2-3.4): multi-scale point-to-plane ICP (coloured
// ICP, coloured_icp.hpp, when both fragments carry colour; reference §7b.3), FPFH feature matching
// with seeded RANSAC, and the overlap / information-matrix evaluation of an alignment. Transforms
// follow the pose-graph convention (backend/posegraph/pose_graph.hpp): T_source_target maps
// target-fragment points into the source frame (p_s = T_s_t p_t).
//
// All functions are deterministic: RANSAC draws from std::mt19937_64 seeded by the caller, and
// parallel sums are reduced over fixed chunks in a fixed order, so results do not depend on the
// thread count. The free functions keep no state between calls and may run concurrently;
// IndexedCloud is immutable after construction and its queries are thread-safe.

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "backend/registration/prepared_fragment.hpp"
#include "common/cloud/point_cloud.hpp"
#include "common/config/schema.hpp"
#include "common/geometry/lie.hpp"

namespace plumb::registration {

struct IcpConfig {
    /// Voxel sizes of the ICP pyramid, coarse to fine (Open3D refine: 0.05, 0.025, 0.0125).
    std::vector<double> voxel_sizes_m = {0.05, 0.025, 0.0125};
    /// Iterations per level (Open3D refine: 50, 30, 14).
    std::vector<int64_t> iterations = {50, 30, 14};
    /// Correspondence distance per level = factor x the level's voxel size (Open3D: 1.4).
    double distance_factor = 1.4;
    /// Stop a level when both fitness and RMSE (metres) change by less than this from one
    /// iteration to the next (Open3D's refine: 1e-6). 1e-4 (0.1 mm of RMSE) stops levels that
    /// only shuffle correspondences.
    double relative_change = 1e-4;
    /// Solution remapping (Zhang, Kaess, Singh, ICRA 2016), as in the tracker: a translation t
    /// is not solved for when mean (n.t)^2 over the correspondences (an eigenvalue of
    /// sum n n^T / count) is below this, and the alignment keeps its start along it. Two
    /// fragments that see little more than a wall and the floor otherwise slide along the line
    /// where they meet, on noise. 0 = plain Gauss-Newton (Open3D), the default for depth-only
    /// pairs.
    double min_normal_spread = 0.0;
    /// min_normal_spread of the coloured pairs (fragments tracked with colour): their odometry
    /// start is reliable along the directions RGB-D tracking observed, so translations that
    /// neither the geometry nor the colour of the pair constrains keep it.
    double coloured_min_normal_spread = 0.005;
    /// Coloured ICP (Park, Zhou, Koltun ICCV 2017; coloured_icp.hpp) instead of point-to-plane
    /// at every level where both fragments carry colour; fragments without colour (depth-only
    /// scans) keep point-to-plane either way.
    bool colour = true;
    /// δ of the joint objective (1 - δ) E_C + δ E_G (Park Eq. (1); Open3D lambda_geometric:
    /// 0.968), in (0, 1]. E_G is in squared metres, E_C in squared intensity ([0, 1]).
    double lambda_geometric = 0.968;
    /// Neighbourhood of the per-point intensity gradient fit (Park Eq. (6)): radius = this
    /// factor x the level's voxel size (Open3D: 2 x the correspondence distance = 2.8 voxels).
    double colour_gradient_radius_factor = 2.8;
    /// At most this many neighbours in the gradient fit (Open3D: 30).
    int colour_gradient_max_nn = 30;
    /// At most this many target points take part at a level of the multi-scale ICP (every k-th,
    /// k the smallest stride that fits); the source, whose points are the correspondences'
    /// partners, keeps all of its. A 50-frame fragment has some 50 000 points at 1.25 cm: ten
    /// thousand of them pin a pair as well as all (nine scans within 2 %, BENCHMARKS.md) at a
    /// fraction of the nearest-neighbour searches. 0 = every point.
    int max_target_points = 10000;
    /// Worker threads (0 = all); results do not depend on it.
    int num_threads = 0;
};
void describe(config::Schema& s, IcpConfig& c);

struct RansacConfig {
    /// Inlier distance of a correspondence, metres (Open3D: 1.4 x voxel = 0.07).
    double max_correspondence_distance_m = 0.07;
    /// Keep only mutual nearest neighbours in feature space (when at least 10 remain).
    bool mutual_filter = true;
    /// Edge-length checker: each sample edge ratio must be at least this (Open3D: 0.9).
    double edge_length_similarity = 0.9;
    /// Iteration cap and early-exit confidence (Open3D 0.16: max_iteration, confidence).
    int max_iterations = 100000;
    double confidence = 0.999;
    /// Fewer inlier correspondences than this is a failure.
    int min_inliers = 10;
    /// Worker threads of the feature matching (0 = all); results do not depend on it.
    int num_threads = 0;
};
void describe(config::Schema& s, RansacConfig& c);

/// A cloud with its k-d tree. The cloud is owned and never moves, so the object is move-only.
class IndexedCloud {
  public:
    IndexedCloud();
    explicit IndexedCloud(PointCloud cloud);
    ~IndexedCloud();
    IndexedCloud(IndexedCloud&&) noexcept;
    IndexedCloud& operator=(IndexedCloud&&) noexcept;

    const PointCloud& cloud() const;
    size_t size() const;
    /// Nearest point within sqrt(max_dist_sq); false when none. Thread-safe.
    bool nearest(const Eigen::Vector3f& q, float max_dist_sq, uint32_t* index,
                 float* dist_sq) const;
    /// The same, starting from a point that may be near (KdTree3::nearest with a hint).
    bool nearest(const Eigen::Vector3f& q, float max_dist_sq, uint32_t hint, uint32_t* index,
                 float* dist_sq) const;
    /// Up to `k` nearest points within sqrt(radius_sq), closest first; returns the count.
    /// Thread-safe.
    size_t knnWithin(const Eigen::Vector3f& q, size_t k, float radius_sq, uint32_t* indices,
                     float* dists_sq) const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// What coloured ICP needs of one ICP level's points (coloured_icp.hpp), one entry per point.
struct LevelColour {
    std::vector<float> intensity;           ///< C(p), BT.601 luma in [0, 1]
    std::vector<Eigen::Vector3f> gradient;  ///< d_p ⟂ n_p (Park Eq. (6)), intensity per metre
};

/// Everything pair registration needs of one fragment, built once: the prepared (feature) level
/// with its tree, the ICP pyramid and the features as a 33 x n matrix.
struct FragmentIndex {
    uint32_t id = 0;
    IndexedCloud coarse;               ///< a copy of the prepared cloud, indexed
    std::vector<IndexedCloud> levels;  ///< one per IcpConfig level
    /// One per level when the fragment carries colour and IcpConfig::colour is on, else empty.
    std::vector<LevelColour> level_colours;
    Eigen::MatrixXf features;          ///< 33 x n, column i = fpfh of point i
    Eigen::VectorXf feature_sq_norms;  ///< |f_i|^2
};

/// Builds the index of a fragment: ICP levels are voxel-downsampled from the full fragment cloud
/// (fused normals averaged; PCA normals when the fragment has none; colours averaged). With
/// colour (fragment colours and IcpConfig::colour) each level also gets its intensities and
/// intensity gradients.
FragmentIndex buildFragmentIndex(const Fragment& fragment, const PreparedFragment& prepared,
                                 const IcpConfig& config);

/// Result of a pairwise registration, with its evaluation.
struct PairResult {
    bool success = false;
    std::string reason;  ///< why it failed, empty on success
    Eigen::Isometry3d T_source_target = Eigen::Isometry3d::Identity();
    Matrix6d information = Matrix6d::Zero();  ///< Choi's Λ (reference §3.4)
    /// Σ_q J_q^T J_q over the same correspondences, J_q = [(q x n_q)^T, n_q^T] with q and its
    /// unit normal n_q in the target frame (rotation first): the point-to-plane information,
    /// nearly singular along what the overlap's geometry does not pin (trace of its translation
    /// block = the correspondence count).
    Matrix6d plane_information = Matrix6d::Zero();
    double overlap = 0.0;         ///< fraction of the smaller fragment matched
    double inlier_rmse_m = 0.0;   ///< RMSE of the correspondences within τ
    int num_correspondences = 0;  ///< Λ(5,5)
    int ransac_inliers = 0;       ///< feature correspondences agreeing (RANSAC only)
    int iterations = 0;           ///< RANSAC or ICP iterations run
};

/// Point-to-plane ICP of `target` onto `source` (source carries normals) from `init`, one level.
/// Minimises Σ (n_p · (T q - p))^2 over nearest neighbours within `max_distance_m`;
/// Gauss-Newton with left updates T <- Exp(ξ) T. Returns the final transform, fitness in `overlap`
/// (fraction of target points matched) and RMSE; fails with fewer than 6 correspondences.
/// Translations with a normal spread below `min_normal_spread` keep `init` (IcpConfig).
PairResult icpPointToPlane(const IndexedCloud& source, const PointCloud& target,
                           const Eigen::Isometry3d& init, double max_distance_m, int max_iterations,
                           double relative_change, double min_normal_spread, int num_threads);

/// Gauss-Newton step of the normal equations H ξ = -g with solution remapping (Zhang, Kaess,
/// Singh, ICRA 2016): translations along eigenvectors of `spread` (the translation block of H
/// per correspondence, in units of mean (n·t)^2) whose eigenvalue is below min_normal_spread
/// are left out of the solve, so the step does not move along them; the three rotations are
/// always solved. With none left out (or min_normal_spread = 0) this is the plain LDLT solve.
Vector6d remappedStep(const Matrix6d& H, const Vector6d& g, const Eigen::Matrix3d& spread,
                      double min_normal_spread);

/// Multi-scale ICP over the pyramids of both fragments (reference §3.2): at each level coloured
/// ICP (icpColoured) when both fragments have colour at that level (FragmentIndex::level_colours,
/// IcpConfig::colour), otherwise point-to-plane. Fails when a level fails.
PairResult multiScaleIcp(const FragmentIndex& source, const FragmentIndex& target,
                         const Eigen::Isometry3d& init, const IcpConfig& config);

/// Evaluates an alignment on the prepared clouds with correspondence distance `tau_m`: the
/// information matrix over target points with a source neighbour within τ, the overlap (fraction
/// of the smaller fragment's points with a neighbour in the other, Choi's ≥ 30 % test) and the
/// inlier RMSE. Sets success = true.
PairResult evaluateAlignment(const FragmentIndex& source, const FragmentIndex& target,
                             const Eigen::Isometry3d& T_source_target, double tau_m,
                             int num_threads);

/// FPFH matching (nearest neighbour in feature space, optionally mutual) and RANSAC over triples
/// of correspondences with the edge-length and distance checkers (reference §3.3), seeded with
/// `seed`. The best hypothesis (most inlier correspondences, then lowest RMSE) is refitted to its
/// inliers. Fails when no hypothesis reaches min_inliers. Information/overlap are not filled.
PairResult ransacFeatureMatching(const FragmentIndex& source, const FragmentIndex& target,
                                 const RansacConfig& config, uint64_t seed);

/// Closed-form rigid fit (Kabsch/Umeyama without scale) minimising Σ |T q_i - p_i|^2.
Eigen::Isometry3d fitRigid(const std::vector<Eigen::Vector3d>& p,
                           const std::vector<Eigen::Vector3d>& q);

}  // namespace plumb::registration
