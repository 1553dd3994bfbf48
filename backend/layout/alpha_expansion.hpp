// SPDX-License-Identifier: Apache-2.0
#pragma once

// Multi-label energy minimisation with a Potts smoothness term by alpha-expansion (Boykov,
// Veksler, Zabih, PAMI 2001), the optimiser of the paper's graph-cut multi-model fitting
// (§3.2, Eq. 4-5; reference §4.5):
//
//   E(f) = sum_p D_p(f_p) + sum_{(p,q) in N} w_pq [f_p != f_q].
//
// Each expansion move "every node keeps its label or switches to alpha" is a binary submodular
// problem solved exactly by one s-t minimum cut (Kolmogorov-Zabih construction, reference §4.5);
// moves are applied in label order until a full cycle lowers E no more. For Potts the result is
// within a factor 2 of the global optimum (Boykov et al., Theorem 6.1).
//
// No randomness; the result depends only on the problem and the initial labelling.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <cstdint>
#include <vector>

#include "common/core/status.hpp"

namespace plumb::layout {

struct PottsEdge {
    int p = 0;
    int q = 0;
    double weight = 0.0;  ///< w_pq >= 0, paid when f_p != f_q
};

/// A Potts labelling problem. unary[p * num_labels + l] = D_p(l) (finite, any sign).
struct PottsProblem {
    int num_nodes = 0;
    int num_labels = 0;
    std::vector<double> unary;
    std::vector<PottsEdge> edges;

    double cost(int p, int l) const { return unary[static_cast<size_t>(p) * num_labels + l]; }
};

struct ExpansionConfig {
    /// Upper bound on full cycles over the labels (the paper's fits converge in 2-5).
    int max_cycles = 10;
    /// A move is accepted when it lowers E by more than this (guards against float noise).
    double min_improvement = 1e-12;
};

struct ExpansionResult {
    std::vector<int> labels;      ///< one per node, in [0, num_labels)
    double initial_energy = 0.0;  ///< E of the initial labelling
    double energy = 0.0;          ///< E of `labels`
    int cycles = 0;               ///< full cycles run (the last one changed nothing or hit max)
    int moves_accepted = 0;       ///< expansion moves that lowered E
    int max_flow_calls = 0;       ///< s-t cuts solved
};

/// E(labels) for `problem`.
double pottsEnergy(const PottsProblem& problem, const std::vector<int>& labels);

/// Checks sizes, finiteness, non-negative edge weights and node indices.
Status validatePottsProblem(const PottsProblem& problem);

/// Minimises E from `initial` (empty: every node starts at its cheapest unary label).
/// kInvalidArgument for a malformed problem or initial labelling.
Result<ExpansionResult> alphaExpansion(const PottsProblem& problem, std::vector<int> initial = {},
                                       const ExpansionConfig& config = {});

/// The exact minimum by enumeration, for tests on tiny problems (num_labels^num_nodes states;
/// kInvalidArgument beyond 2^24 states).
Result<ExpansionResult> bruteForcePotts(const PottsProblem& problem);

}  // namespace plumb::layout
