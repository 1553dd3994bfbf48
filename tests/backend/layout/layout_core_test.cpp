// SPDX-License-Identifier: Apache-2.0
// alpha-expansion against brute force (reference §4.11 d) and T-linkage on toy line sets (e).

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <random>

#include "backend/layout/alpha_expansion.hpp"
#include "backend/layout/tlinkage.hpp"

namespace plumb::layout {
namespace {

PottsProblem randomProblem(std::mt19937& rng, int nodes, int labels, double edge_prob) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    PottsProblem p;
    p.num_nodes = nodes;
    p.num_labels = labels;
    for (int i = 0; i < nodes * labels; ++i) p.unary.push_back(u(rng));
    for (int a = 0; a < nodes; ++a) {
        for (int b = a + 1; b < nodes; ++b) {
            if (u(rng) < edge_prob) p.edges.push_back({a, b, 0.6 * u(rng)});
        }
    }
    return p;
}

TEST(AlphaExpansion, MatchesBruteForceOnSmallGraphs) {
    std::mt19937 rng(7);
    int equal = 0;
    const int trials = 60;
    for (int t = 0; t < trials; ++t) {
        const PottsProblem p = randomProblem(rng, 8, 3, 0.4);
        auto exp = alphaExpansion(p);
        auto opt = bruteForcePotts(p);
        ASSERT_TRUE(exp.isOk()) << exp.status().toString();
        ASSERT_TRUE(opt.isOk());
        EXPECT_NEAR(exp->energy, pottsEnergy(p, exp->labels), 1e-9);
        EXPECT_LE(exp->energy, exp->initial_energy + 1e-12);
        // Boykov-Veksler-Zabih: within 2x of the optimum for Potts.
        EXPECT_LE(exp->energy, 2.0 * opt->energy + 1e-9) << "trial " << t;
        EXPECT_GE(exp->energy, opt->energy - 1e-9);
        if (exp->energy <= opt->energy + 1e-9) ++equal;
    }
    EXPECT_GE(equal, trials * 8 / 10) << equal << " of " << trials << " reached the optimum";
}

TEST(AlphaExpansion, StrongSmoothnessGivesOneLabelAndChainsAreExact) {
    // A chain with two labels is solved exactly by a single cut: compare with brute force.
    std::mt19937 rng(3);
    for (int t = 0; t < 20; ++t) {
        PottsProblem p = randomProblem(rng, 10, 2, 0.0);
        for (int i = 0; i + 1 < 10; ++i) p.edges.push_back({i, i + 1, 0.3});
        auto exp = alphaExpansion(p);
        auto opt = bruteForcePotts(p);
        ASSERT_TRUE(exp.isOk());
        EXPECT_NEAR(exp->energy, opt->energy, 1e-9);  // binary submodular: exact
    }
    PottsProblem p = randomProblem(rng, 8, 3, 1.0);
    for (auto& e : p.edges) e.weight = 10.0;
    auto exp = alphaExpansion(p);
    ASSERT_TRUE(exp.isOk());
    for (int l : exp->labels) EXPECT_EQ(l, exp->labels[0]);
}

TEST(AlphaExpansion, RejectsMalformedProblems) {
    PottsProblem p;
    p.num_nodes = 2;
    p.num_labels = 2;
    p.unary = {0, 1, 1};
    EXPECT_EQ(alphaExpansion(p).status().code(), StatusCode::kInvalidArgument);
    p.unary = {0, 1, 1, 0};
    p.edges = {{0, 0, 1.0}};
    EXPECT_EQ(alphaExpansion(p).status().code(), StatusCode::kInvalidArgument);
    p.edges = {{0, 1, -1.0}};
    EXPECT_EQ(alphaExpansion(p).status().code(), StatusCode::kInvalidArgument);
    p.edges = {{0, 1, 1.0}};
    EXPECT_EQ(alphaExpansion(p, {0, 5}).status().code(), StatusCode::kInvalidArgument);
    p.unary[0] = std::nan("");
    EXPECT_EQ(alphaExpansion(p).status().code(), StatusCode::kInvalidArgument);
}

/// Points on `lines` (2-D, n.x + d = 0) with Gaussian noise, hypotheses from random point pairs,
/// T-linkage over the points: the clusters with >= min_size points must be one per line.
int clustersOnToyLines(const std::vector<Eigen::Vector3d>& lines, int outliers, uint32_t seed,
                       int* pure) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> noise(0.0, 0.003);
    std::uniform_real_distribution<double> t(-1.0, 1.0), box(-1.5, 1.5);
    std::vector<Eigen::Vector2d> pts;
    std::vector<int> truth;
    for (size_t l = 0; l < lines.size(); ++l) {
        const Eigen::Vector2d n = lines[l].head<2>().normalized();
        const Eigen::Vector2d dir(-n.y(), n.x());
        const Eigen::Vector2d p0 = -lines[l].z() * n;
        for (int i = 0; i < 60; ++i) {
            pts.push_back(p0 + t(rng) * dir + noise(rng) * n);
            truth.push_back(static_cast<int>(l));
        }
    }
    for (int i = 0; i < outliers; ++i) {
        pts.emplace_back(box(rng), box(rng));
        truth.push_back(-1);
    }
    std::vector<Eigen::Vector3d> hyps;
    std::uniform_int_distribution<size_t> pick(0, pts.size() - 1);
    for (int h = 0; h < 600; ++h) {
        const Eigen::Vector2d a = pts[pick(rng)], b = pts[pick(rng)];
        if ((b - a).norm() < 1e-3) continue;
        const Eigen::Vector2d dir = (b - a).normalized();
        const Eigen::Vector2d n(-dir.y(), dir.x());
        hyps.emplace_back(n.x(), n.y(), -n.dot(a));
    }
    std::vector<PreferenceVector> prefs;
    for (const Eigen::Vector2d& p : pts) {
        prefs.push_back(preferencesFromResiduals(
            static_cast<int>(hyps.size()),
            [&](int h) { return std::abs(hyps[h].head<2>().dot(p) + hyps[h].z()); }, 0.01, 5.0));
    }
    const TLinkageResult r = tLinkage(prefs);
    int big = 0;
    *pure = 0;
    for (const auto& members : r.members) {
        if (members.size() < 20) continue;
        ++big;
        std::vector<int> count(lines.size(), 0);
        for (int i : members) {
            if (truth[i] >= 0) ++count[truth[i]];
        }
        const int best = *std::max_element(count.begin(), count.end());
        if (best >= static_cast<int>(members.size()) * 9 / 10) ++*pure;
    }
    return big;
}

TEST(TLinkage, RecoversTheNumberOfLines) {
    const std::vector<std::vector<Eigen::Vector3d>> cases = {
        {{1, 0, 0.5}, {0, 1, -0.3}, {1, 1, 0.2}},
        {{1, 0, 0.0}, {1, 0, -1.0}},
        {{0.3, 1, 0.0}, {1, -0.2, 0.4}, {1, 0.9, -0.8}, {0, 1, 1.0}},
    };
    for (size_t c = 0; c < cases.size(); ++c) {
        int pure = 0;
        const int found = clustersOnToyLines(cases[c], 30, 11 + static_cast<uint32_t>(c), &pure);
        EXPECT_EQ(found, static_cast<int>(cases[c].size())) << "case " << c;
        EXPECT_EQ(pure, found) << "case " << c;
    }
}

TEST(TLinkage, TanimotoAndAdjacency) {
    const PreferenceVector a = {{0, 1.0f}, {2, 0.5f}};
    const PreferenceVector b = {{0, 1.0f}, {2, 0.5f}};
    const PreferenceVector c = {{1, 1.0f}};
    EXPECT_NEAR(tanimotoDistance(a, b), 0.0, 1e-12);
    EXPECT_NEAR(tanimotoDistance(a, c), 1.0, 1e-12);
    EXPECT_NEAR(tanimotoDistance(a, {}), 1.0, 1e-12);
    // Four identical items, but 0-1 and 2-3 are not adjacent to each other: two clusters.
    const std::vector<PreferenceVector> prefs = {a, a, a, a};
    EXPECT_EQ(tLinkage(prefs).num_clusters, 1);
    const std::vector<std::vector<int>> adj = {{1}, {0}, {3}, {2}};
    const TLinkageResult r = tLinkage(prefs, adj);
    EXPECT_EQ(r.num_clusters, 2);
    EXPECT_EQ(r.cluster_of_item[0], r.cluster_of_item[1]);
    EXPECT_NE(r.cluster_of_item[1], r.cluster_of_item[2]);
}

}  // namespace
}  // namespace plumb::layout
