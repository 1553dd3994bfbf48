// SPDX-License-Identifier: Apache-2.0
// Fragment preparation and pairwise registration on a simulated fragment: voxel downsampling,
// FPFH invariance to rigid motion, ICP and RANSAC recovering known transforms, the information
// matrix and the overlap test.

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <limits>
#include <numbers>
#include <random>
#include <set>

#include "backend/registration/guided_search.hpp"
#include "backend/registration/pair_registration.hpp"
#include "backend/registration/prepared_fragment.hpp"
#include "tests/backend/registration/sim_fragments.hpp"

namespace plumb::registration {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

const testing::SimScan& scan() {
    static const testing::SimScan s = [] {
        Result<testing::SimScan> r = testing::simLoopScan();
        PLUMB_CHECK(r.isOk()) << r.status().toString();
        return std::move(r.value());
    }();
    return s;
}

Fragment movedCopy(const Fragment& f, const Eigen::Isometry3d& T_new_old, uint32_t id) {
    Fragment g = f;
    g.id = id;
    g.points_F = transformed(f.points_F, T_new_old);
    return g;
}

TEST(Prepare, DownsamplesWithUnitNormalsAndIsDeterministic) {
    const Fragment& f = scan().fragments.at(0);
    PrepareConfig c;
    Result<PreparedFragment> a = prepareFragment(f, c);
    ASSERT_TRUE(a.isOk()) << a.status().toString();
    EXPECT_GT(a->points.size(), 300u);
    EXPECT_LT(a->points.size(), f.points_F.size() / 4);
    ASSERT_TRUE(a->points.hasNormals());
    ASSERT_EQ(a->fpfh.size(), a->points.size());
    for (const auto& n : a->points.normals) EXPECT_NEAR(n.norm(), 1.0f, 1e-5f);
    // Every output point is the mean of its own voxel: at most one point per voxel.
    std::set<std::array<int64_t, 3>> keys;
    for (const auto& p : a->points.points) {
        keys.insert({static_cast<int64_t>(std::floor(p.x() / c.voxel_size_m)),
                     static_cast<int64_t>(std::floor(p.y() / c.voxel_size_m)),
                     static_cast<int64_t>(std::floor(p.z() / c.voxel_size_m))});
    }
    EXPECT_EQ(keys.size(), a->points.size());
    // 1 thread vs default: identical bits.
    c.num_threads = 1;
    Result<PreparedFragment> b = prepareFragment(f, c);
    ASSERT_TRUE(b.isOk());
    EXPECT_EQ(a->points.points, b->points.points);
    EXPECT_EQ(a->fpfh, b->fpfh);
    // Each FPFH block sums to 200 (normalised neighbour part + the point's own SPFH).
    size_t full = 0;
    for (const Fpfh33& h : a->fpfh) {
        float s0 = 0.0f;
        for (int i = 0; i < 11; ++i) s0 += h[i];
        if (std::abs(s0 - 200.0f) < 0.1f) ++full;
    }
    EXPECT_GT(full, a->fpfh.size() * 9 / 10);
}

TEST(Prepare, FpfhIsInvariantToRigidMotion) {
    const Fragment& f = scan().fragments.at(1);
    PointCloud cloud = voxelDownsample(f.points_F, 0.05);
    const Eigen::Isometry3d T =
        lie::expSE3((Vector6d() << 0.3, -0.5, 0.2, 1.0, -2.0, 0.5).finished());
    const PointCloud moved = transformed(cloud, T);
    const auto a = computeFpfh(cloud, 0.25, 100, 0);
    const auto b = computeFpfh(moved, 0.25, 100, 0);
    ASSERT_EQ(a.size(), b.size());
    double max_diff = 0.0, mean_norm = 0.0;
    for (size_t i = 0; i < a.size(); ++i) {
        double d = 0.0, n = 0.0;
        for (int k = 0; k < 33; ++k) {
            d += (a[i][k] - b[i][k]) * (a[i][k] - b[i][k]);
            n += a[i][k] * a[i][k];
        }
        max_diff = std::max(max_diff, std::sqrt(d));
        mean_norm += std::sqrt(n) / a.size();
    }
    // Float rounding may move a value across a bin edge; such flips are rare and small.
    EXPECT_LT(max_diff, 0.2 * mean_norm);
}

TEST(Prepare, BadFragmentsGiveSpecificErrors) {
    // Empty or all-NaN fragments are prepared empty (kept on their odometry edge later).
    Fragment empty;
    empty.id = 4;
    Result<PreparedFragment> r = prepareFragment(empty, {});
    ASSERT_TRUE(r.isOk());
    EXPECT_EQ(r->id, 4u);
    EXPECT_TRUE(r->points.empty());
    EXPECT_TRUE(r->fpfh.empty());
    Fragment nan;
    nan.points_F.points.assign(10, Eigen::Vector3f::Constant(std::nanf("")));
    ASSERT_TRUE(prepareFragment(nan, {}).isOk());
    EXPECT_TRUE(prepareFragment(nan, {})->points.empty());
    Fragment bad = scan().fragments.at(0);
    bad.id = 9;
    bad.points_F.normals.pop_back();
    Result<PreparedFragment> b = prepareFragment(bad, {});
    EXPECT_EQ(b.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(b.status().message().find("fragment 9"), std::string::npos);
    PrepareConfig c;
    c.voxel_size_m = -1.0;
    EXPECT_EQ(prepareFragment(scan().fragments.at(0), c).status().code(),
              StatusCode::kInvalidArgument);
}

struct Pair {
    Fragment a, b;
    PreparedFragment pa, pb;
    FragmentIndex ia, ib;
};

/// Fragment 2 and a copy moved by T_b_a (so T_source_target = T_a_b = T_b_a^-1).
std::unique_ptr<Pair> makePair(const Eigen::Isometry3d& T_b_a) {
    auto p = std::make_unique<Pair>();
    p->a = scan().fragments.at(2);
    p->a.id = 0;
    p->b = movedCopy(p->a, T_b_a, 1);
    p->pa = prepareFragment(p->a, {}).value();
    p->pb = prepareFragment(p->b, {}).value();
    const IcpConfig icp;
    p->ia = buildFragmentIndex(p->a, p->pa, icp);
    p->ib = buildFragmentIndex(p->b, p->pb, icp);
    return p;
}

double translationError(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
    return (a.inverse() * b).translation().norm();
}

TEST(PairRegistration, IcpRecoversSmallMotion) {
    const Eigen::Isometry3d T_b_a =
        lie::expSE3((Vector6d() << 0.02, -0.03, 0.01, 0.04, -0.03, 0.02).finished());
    auto p = makePair(T_b_a);
    const Eigen::Isometry3d truth = T_b_a.inverse();
    const PairResult r = multiScaleIcp(p->ia, p->ib, Eigen::Isometry3d::Identity(), IcpConfig{});
    ASSERT_TRUE(r.success) << r.reason;
    EXPECT_LT(translationError(r.T_source_target, truth), 0.002);
    EXPECT_LT(lie::rotationAngle(r.T_source_target.inverse() * truth), 0.1 * kDeg);
}

TEST(PairRegistration, RansacRecoversLargeMotionAndOverlapIsFull) {
    const Eigen::Isometry3d T_b_a =
        lie::expSE3((Vector6d() << 0.4, 1.2, -0.3, 1.5, -0.7, 2.0).finished());
    auto p = makePair(T_b_a);
    const Eigen::Isometry3d truth = T_b_a.inverse();
    const PairResult r = ransacFeatureMatching(p->ia, p->ib, RansacConfig{}, 42);
    ASSERT_TRUE(r.success) << r.reason;
    EXPECT_LT(translationError(r.T_source_target, truth), 0.05);
    EXPECT_LT(lie::rotationAngle(r.T_source_target.inverse() * truth), 3.0 * kDeg);
    // Same seed, same answer; evaluation at the truth: full overlap, Λ(5,5) = correspondences.
    const PairResult again = ransacFeatureMatching(p->ia, p->ib, RansacConfig{}, 42);
    EXPECT_TRUE(again.T_source_target.matrix() == r.T_source_target.matrix());
    // The feature matching's chunks (256 target points) merge to the serial scan's answer.
    ASSERT_GT(p->ib.features.cols(), 2 * 256);
    for (int threads : {1, 2}) {
        RansacConfig c;
        c.num_threads = threads;
        const PairResult t = ransacFeatureMatching(p->ia, p->ib, c, 42);
        EXPECT_TRUE(t.T_source_target.matrix() == r.T_source_target.matrix()) << threads;
        EXPECT_EQ(t.ransac_inliers, r.ransac_inliers);
    }
    const PairResult e = evaluateAlignment(p->ia, p->ib, truth, 0.07, 0);
    EXPECT_GT(e.overlap, 0.99);
    EXPECT_EQ(e.information(5, 5), e.num_correspondences);
    EXPECT_LT(e.inlier_rmse_m, 0.03);  // separate 5 cm voxel grids: about voxel / 3
    // Λ is symmetric positive definite.
    Eigen::SelfAdjointEigenSolver<Matrix6d> es(e.information);
    EXPECT_GT(es.eigenvalues().minCoeff(), 0.0);
    // Far off: no overlap.
    Eigen::Isometry3d far = truth;
    far.translation() += Eigen::Vector3d(10, 0, 0);
    EXPECT_LT(evaluateAlignment(p->ia, p->ib, far, 0.07, 0).overlap, 0.01);
}

TEST(GuidedSearch, FindsTheTranslationDriftUnderTheOdometryRotation) {
    // The odometry has the rotation to within a degree but the translation 34 cm off: the
    // strongest vote peak is the truth (to a bin), and ICP from it finishes the job.
    const Eigen::Isometry3d T_b_a =
        lie::expSE3((Vector6d() << 0.1, -0.3, 0.05, 0.5, 0.2, -0.3).finished());
    auto p = makePair(T_b_a);
    const Eigen::Isometry3d truth = T_b_a.inverse();
    const Eigen::Isometry3d T_odo =
        Eigen::Translation3d(0.25, -0.2, 0.1) * truth *
        Eigen::AngleAxisd(1.0 * kDeg, Eigen::Vector3d(1, 2, 3).normalized());
    const GuidedSearchConfig config;
    const std::vector<GuidedCandidate> c = guidedCandidates(p->ia, p->ib, T_odo, 0.3, config);
    ASSERT_FALSE(c.empty());
    ASSERT_LE(c.size(), static_cast<size_t>(config.max_peaks));
    for (size_t k = 1; k < c.size(); ++k) EXPECT_LE(c[k].votes, c[k - 1].votes);
    // The candidate moves the fragment's centroid to within two bins of where the truth puts it
    // (votes are binned at 5 cm, and the residual 1-degree turn moves points 2 m out by 3.5 cm).
    const PointCloud& pts = p->ib.coarse.cloud();
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3f& q : pts.points) centroid += q.cast<double>();
    centroid /= static_cast<double>(pts.size());
    const double before = (T_odo * centroid - truth * centroid).norm();
    const double after = (c.front().T_source_target * centroid - truth * centroid).norm();
    std::printf("guided search: centroid %.3f m off at the odometry, %.3f m at the best peak\n",
                before, after);
    EXPECT_GT(before, 0.3);
    EXPECT_LT(after, 0.1);
    const PairResult icp = multiScaleIcp(p->ia, p->ib, c.front().T_source_target, IcpConfig{});
    ASSERT_TRUE(icp.success) << icp.reason;
    EXPECT_LT(translationError(icp.T_source_target, truth), 0.01);
    EXPECT_LT(lie::rotationAngle(icp.T_source_target.inverse() * truth), 0.2 * kDeg);
    // Deterministic, and nothing to vote with without normals.
    const std::vector<GuidedCandidate> again = guidedCandidates(p->ia, p->ib, T_odo, 0.3, config);
    ASSERT_EQ(again.size(), c.size());
    for (size_t k = 0; k < c.size(); ++k) {
        EXPECT_TRUE(again[k].T_source_target.matrix() == c[k].T_source_target.matrix());
    }
    FragmentIndex bare;
    EXPECT_TRUE(guidedCandidates(p->ia, bare, T_odo, 0.3, config).empty());
}

TEST(GuidedSearch, AFloorAloneKeepsTheOdometryAlongItself) {
    // Two views of the same 3 m x 3 m floor: any slide along it fits, only the height is
    // observed. The odometry is 20 cm off along the floor and 8 cm in height: the search
    // corrects the height and keeps the odometry along the floor (the prior breaks the tie).
    Fragment floor;
    for (int i = 0; i < 150; ++i) {
        for (int j = 0; j < 150; ++j) {
            floor.points_F.points.emplace_back(0.02f * i - 1.5f, 0.02f * j - 1.5f, 0.0f);
            floor.points_F.normals.emplace_back(0.0f, 0.0f, 1.0f);
        }
    }
    Fragment other = floor;
    other.id = 1;
    const PreparedFragment pa = prepareFragment(floor, {}).value();
    const PreparedFragment pb = prepareFragment(other, {}).value();
    const FragmentIndex ia = buildFragmentIndex(floor, pa, IcpConfig{});
    const FragmentIndex ib = buildFragmentIndex(other, pb, IcpConfig{});
    const Eigen::Isometry3d T_odo(Eigen::Translation3d(0.2, 0.0, 0.08));
    const std::vector<GuidedCandidate> c =
        guidedCandidates(ia, ib, T_odo, 0.2, GuidedSearchConfig{});
    ASSERT_FALSE(c.empty());
    const Eigen::Vector3d t = c.front().T_source_target.translation();
    // Offsets are voted in 5 cm bins: the peak is right to half a bin (ICP refines it).
    EXPECT_NEAR(t.z(), 0.0, 0.026);
    EXPECT_NEAR(t.x(), 0.2, 0.026);
    EXPECT_NEAR(t.y(), 0.0, 0.026);
}

TEST(PairRegistration, RemappedIcpKeepsTheStartAlongWhatTheGeometryLeavesFree) {
    // A wall (x = 0) meeting the floor (z = 0) along the y axis, 2 mm of depth noise, normals
    // tilted by up to 3 degrees as estimated normals are: translation along y is observed only
    // through that noise. From a start 3 cm / 10 cm / -2 cm off, ICP with solution remapping
    // corrects x and z and keeps the start along y; plain Gauss-Newton follows the noise there.
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    PointCloud source_cloud, target;
    for (int i = 0; i < 100; ++i) {
        for (int j = 0; j < 60; ++j) {
            const float y = 0.03f * static_cast<float>(i) - 1.5f;
            const float s = 0.03f * static_cast<float>(j) + 0.015f;
            const Eigen::Vector3f wall(0.0f, y, s), floor(s, y, 0.0f);
            source_cloud.points.push_back(wall);
            source_cloud.normals.push_back(
                Eigen::Vector3f(1.0f, 0.05f * unit(rng), 0.0f).normalized());
            source_cloud.points.push_back(floor);
            source_cloud.normals.push_back(
                Eigen::Vector3f(0.0f, 0.05f * unit(rng), 1.0f).normalized());
            target.points.push_back(wall + Eigen::Vector3f(0.002f * unit(rng), 0.0f, 0.0f));
            target.points.push_back(floor + Eigen::Vector3f(0.0f, 0.0f, 0.002f * unit(rng)));
        }
    }
    const IndexedCloud source(source_cloud);
    const Eigen::Isometry3d start(Eigen::Translation3d(0.03, 0.10, -0.02));
    const PairResult remapped = icpPointToPlane(source, target, start, 0.07, 30, 1e-9,
                                                /*min_normal_spread=*/0.005, /*num_threads=*/1);
    ASSERT_TRUE(remapped.success) << remapped.reason;
    const Eigen::Vector3d t = remapped.T_source_target.translation();
    EXPECT_NEAR(t.x(), 0.0, 2e-3);
    EXPECT_NEAR(t.z(), 0.0, 2e-3);
    EXPECT_NEAR(t.y(), 0.10, 1e-3);
    const PairResult plain = icpPointToPlane(source, target, start, 0.07, 30, 1e-9,
                                             /*min_normal_spread=*/0.0, /*num_threads=*/1);
    std::printf("plain: success %d, t = %.4f %.4f %.4f; remapped t = %.4f %.4f %.4f\n",
                plain.success, plain.T_source_target.translation().x(),
                plain.T_source_target.translation().y(), plain.T_source_target.translation().z(),
                t.x(), t.y(), t.z());
    if (plain.success) {
        EXPECT_GT(std::abs(plain.T_source_target.translation().y() - 0.10), 0.005);
    }
}

TEST(PairRegistration, FitRigidIsExact) {
    const Eigen::Isometry3d T =
        lie::expSE3((Vector6d() << 0.5, -0.2, 1.0, 0.3, 0.1, -2.0).finished());
    std::vector<Eigen::Vector3d> p, q;
    for (int i = 0; i < 10; ++i) {
        q.emplace_back(std::sin(i), std::cos(2.0 * i), 0.1 * i);
        p.push_back(T * q.back());
    }
    EXPECT_LT((fitRigid(p, q).matrix() - T.matrix()).norm(), 1e-10);
}

TEST(PairRegistration, NearestWithinARadiusIsTheBruteForceNearest) {
    // Points on a coarse lattice (many equidistant neighbours) plus jitter, queries inside and
    // far outside the cloud: the bounded search must find the brute-force nearest whenever one
    // lies within the radius, and nothing otherwise.
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> jitter(-0.002f, 0.002f);
    PointCloud cloud;
    for (int x = 0; x < 20; ++x)
        for (int y = 0; y < 20; ++y)
            for (int z = 0; z < 3; ++z)
                cloud.points.emplace_back(0.05f * x + jitter(rng), 0.05f * y + jitter(rng),
                                          0.05f * z + jitter(rng));
    const IndexedCloud indexed{PointCloud(cloud)};
    std::uniform_real_distribution<float> where(-0.5f, 1.5f);
    int found = 0, missed = 0;
    for (int k = 0; k < 4000; ++k) {
        const Eigen::Vector3f q(where(rng), where(rng), 0.3f * where(rng));
        for (const float radius : {0.01f, 0.03f, 0.2f}) {
            const float r2 = radius * radius;
            float best = std::numeric_limits<float>::infinity();
            for (const Eigen::Vector3f& p : cloud.points)
                best = std::min(best, (p - q).squaredNorm());
            uint32_t index = 0;
            float d2 = -1.0f;
            const bool hit = indexed.nearest(q, r2, &index, &d2);
            ASSERT_EQ(hit, best <= r2) << "query " << q.transpose() << " radius " << radius;
            if (!hit) {
                ++missed;
                continue;
            }
            ++found;
            EXPECT_FLOAT_EQ(d2, best);
            EXPECT_FLOAT_EQ((cloud.points[index] - q).squaredNorm(), best);
        }
    }
    EXPECT_GT(found, 1000);
    EXPECT_GT(missed, 1000);
}

TEST(PairRegistration, ANearestSearchFromAHintFindsWhatTheSearchWithoutOneFinds) {
    // Points on an exact lattice (so that many queries have several equidistant nearest points)
    // and queries near it, each searched from hints near, far, beyond the radius and out of
    // range: the same point and distance every time, ties included.
    PointCloud cloud;
    for (int x = 0; x < 12; ++x)
        for (int y = 0; y < 12; ++y)
            for (int z = 0; z < 4; ++z) cloud.points.emplace_back(0.25f * x, 0.25f * y, 0.25f * z);
    const IndexedCloud indexed{PointCloud(cloud)};
    std::mt19937 rng(9);
    std::uniform_int_distribution<int> cell(0, 24);
    std::uniform_int_distribution<uint32_t> any(0, static_cast<uint32_t>(cloud.size()) + 5);
    int ties = 0;
    for (int k = 0; k < 3000; ++k) {
        // Half-cell positions are equidistant from two to eight lattice points.
        const Eigen::Vector3f q(0.125f * cell(rng), 0.125f * cell(rng), 0.125f * (cell(rng) % 8));
        uint32_t index = 0;
        float d2 = 0.0f;
        const float r2 = 0.04f;
        const bool hit = indexed.nearest(q, r2, &index, &d2);
        int equidistant = 0;
        for (const Eigen::Vector3f& p : cloud.points) equidistant += (p - q).squaredNorm() == d2;
        ties += hit && equidistant > 1;
        for (const uint32_t hint : {index, any(rng), any(rng), uint32_t{0}, uint32_t{1u << 31}}) {
            uint32_t hinted_index = 0;
            float hinted_d2 = 0.0f;
            ASSERT_EQ(indexed.nearest(q, r2, hint, &hinted_index, &hinted_d2), hit);
            if (!hit) continue;
            EXPECT_EQ(hinted_index, index) << q.transpose() << " hint " << hint;
            EXPECT_EQ(hinted_d2, d2);
        }
    }
    EXPECT_GT(ties, 300);

    // Random points and queries, each searched from its own nearest point: the hint's exact
    // distance must not let the search prune the branch that holds it.
    std::uniform_real_distribution<float> u(0.0f, 3.0f);
    PointCloud random;
    for (int k = 0; k < 20000; ++k) random.points.emplace_back(u(rng), u(rng), u(rng));
    const IndexedCloud random_indexed{PointCloud(random)};
    std::normal_distribution<float> offset(0.0f, 0.002f);
    for (int k = 0; k < 200000; ++k) {
        const Eigen::Vector3f q =
            random.points[static_cast<size_t>(k) % random.points.size()] +
            (k % 2 == 0 ? Eigen::Vector3f(offset(rng), offset(rng), offset(rng))
                        : Eigen::Vector3f(u(rng), u(rng), u(rng)) * 0.01f);
        uint32_t index = 0, hinted_index = 0;
        float d2 = 0.0f, hinted_d2 = 0.0f;
        if (!random_indexed.nearest(q, 0.01f, &index, &d2)) continue;
        ASSERT_TRUE(random_indexed.nearest(q, 0.01f, index, &hinted_index, &hinted_d2)) << k;
        ASSERT_EQ(hinted_index, index) << k;
        ASSERT_EQ(hinted_d2, d2) << k;
    }
}

}  // namespace
}  // namespace plumb::registration
