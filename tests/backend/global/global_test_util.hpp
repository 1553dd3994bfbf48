// SPDX-License-Identifier: Apache-2.0
#pragma once

// Shared pieces of the global-registration tests: pair priors from ground truth and the
// perturbed starting poses.

#include <vector>

#include "backend/global/global_registration.hpp"
#include "tests/backend/global/overlap_information.hpp"
#include "tests/backend/global/sim_fragments.hpp"

namespace plumb::testing {

/// Priors for consecutive fragments (k, k+1) (plus `extra` pairs) with the ground-truth relative
/// pose times a perturbation of `noise_deg` / `noise_m`, and Choi's information Σ G^T G over
/// the points of fragment j with a neighbour in fragment i within 3 cm at ground truth.
inline std::vector<global::PairPrior> makePriors(
    const SimFragments& sim, const std::vector<global::GlobalCloud>& clouds, double noise_deg,
    double noise_m, const std::vector<std::pair<uint32_t, uint32_t>>& extra = {}) {
    std::vector<std::pair<uint32_t, uint32_t>> pairs;
    for (uint32_t k = 0; k + 1 < sim.fragments.size(); ++k) pairs.emplace_back(k, k + 1);
    pairs.insert(pairs.end(), extra.begin(), extra.end());
    std::vector<global::PairPrior> priors;
    uint64_t seed = 100;
    for (const auto& [i, j] : pairs) {
        global::PairPrior p;
        p.i = i;
        p.j = j;
        p.T_i_j = sim.T_W_F_gt[i].inverse() * sim.T_W_F_gt[j] *
                  randomPerturbation(noise_deg, noise_m, seed++);
        p.information = overlapInformation(clouds[i], clouds[j],
                                           sim.T_W_F_gt[i].inverse() * sim.T_W_F_gt[j], 0.03);
        priors.push_back(p);
    }
    return priors;
}

/// Ground truth with fragments 1.. perturbed by `angle_deg` / `dist_m` (random directions).
inline std::vector<Eigen::Isometry3d> perturbedPoses(const SimFragments& sim, double angle_deg,
                                                     double dist_m, uint64_t seed) {
    std::vector<Eigen::Isometry3d> T = sim.T_W_F_gt;
    for (size_t k = 1; k < T.size(); ++k) {
        T[k] = T[k] * randomPerturbation(angle_deg, dist_m, seed + k);
    }
    return T;
}

}  // namespace plumb::testing
