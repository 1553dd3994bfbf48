// SPDX-License-Identifier: Apache-2.0
#include "backend/layout/alpha_expansion.hpp"

#include <fmt/format.h>

#include <opencv2/core.hpp>
// GCGraph needs <opencv2/core.hpp> first (reference §4.5).
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc/detail/gcgraph.hpp>

namespace plumb::layout {

double pottsEnergy(const PottsProblem& problem, const std::vector<int>& labels) {
    double e = 0.0;
    for (int p = 0; p < problem.num_nodes; ++p) e += problem.cost(p, labels[p]);
    for (const PottsEdge& edge : problem.edges) {
        if (labels[edge.p] != labels[edge.q]) e += edge.weight;
    }
    return e;
}

Status validatePottsProblem(const PottsProblem& problem) {
    if (problem.num_nodes < 0 || problem.num_labels < 1) {
        return invalidArgument(
            fmt::format("Potts problem: {} nodes and {} labels (need >= 0, >= 1)",
                        problem.num_nodes, problem.num_labels));
    }
    const size_t expected = static_cast<size_t>(problem.num_nodes) * problem.num_labels;
    if (problem.unary.size() != expected) {
        return invalidArgument(fmt::format("Potts problem: {} unary costs for {} nodes x {} labels",
                                           problem.unary.size(), problem.num_nodes,
                                           problem.num_labels));
    }
    for (size_t i = 0; i < expected; ++i) {
        if (!std::isfinite(problem.unary[i])) {
            return invalidArgument(fmt::format("Potts problem: unary cost {} is not finite", i));
        }
    }
    for (size_t i = 0; i < problem.edges.size(); ++i) {
        const PottsEdge& e = problem.edges[i];
        if (e.p < 0 || e.q < 0 || e.p >= problem.num_nodes || e.q >= problem.num_nodes ||
            e.p == e.q) {
            return invalidArgument(
                fmt::format("Potts problem: edge {} joins invalid nodes ({}, {})", i, e.p, e.q));
        }
        if (!std::isfinite(e.weight) || e.weight < 0.0) {
            return invalidArgument(fmt::format(
                "Potts problem: edge {} has weight {} (need finite >= 0)", i, e.weight));
        }
    }
    return Status::ok();
}

namespace {

enum class NodeState : uint8_t { kAlpha, kKept, kFree };

/// One expansion move for `alpha`: the labelling that minimises E among all labellings in which
/// every node keeps its label or takes alpha (exact, by a minimum cut). Returns false when the
/// cut could not be computed (should not happen; GCGraph asserts on malformed graphs).
bool expansionMove(const PottsProblem& problem, const std::vector<double>& incident_weight,
                   const std::vector<int>& labels, int alpha, std::vector<int>* proposal,
                   int* max_flow_calls) {
    const int n = problem.num_nodes;
    std::vector<NodeState> state(n, NodeState::kKept);
    std::vector<int> vertex(n, -1);
    int num_free = 0;
    for (int p = 0; p < n; ++p) {
        if (labels[p] == alpha) {
            state[p] = NodeState::kAlpha;
            continue;
        }
        // Exact pruning: switching p alone changes the pairwise part by at most the sum of its
        // incident weights, so when the unary increase exceeds that sum, x_p = 0 is optimal.
        if (problem.cost(p, alpha) - problem.cost(p, labels[p]) > incident_weight[p]) continue;
        state[p] = NodeState::kFree;
        vertex[p] = num_free++;
    }
    *proposal = labels;
    if (num_free == 0) return true;

    std::vector<double> e0(num_free, 0.0), e1(num_free, 0.0);
    for (int p = 0; p < n; ++p) {
        if (state[p] != NodeState::kFree) continue;
        e0[vertex[p]] = problem.cost(p, labels[p]);
        e1[vertex[p]] = problem.cost(p, alpha);
    }
    struct BinaryEdge {
        int i, j;
        double w;     // paid when i keeps (x=0) and j switches (x=1)
        double revw;  // paid when i switches and j keeps
    };
    std::vector<BinaryEdge> binary_edges;
    for (const PottsEdge& edge : problem.edges) {
        if (edge.weight <= 0.0) continue;
        const NodeState sp = state[edge.p], sq = state[edge.q];
        if (sp != NodeState::kFree && sq != NodeState::kFree) continue;  // constant
        if (sp == NodeState::kFree && sq == NodeState::kFree) {
            const int i = vertex[edge.p], j = vertex[edge.q];
            if (labels[edge.p] == labels[edge.q]) {
                // A = D = 0, B = C = w: a symmetric edge.
                binary_edges.push_back({i, j, edge.weight, edge.weight});
            } else {
                // A = B = C = w, D = 0: E = w - w x_q + w (1 - x_p) x_q (Kolmogorov-Zabih).
                e1[j] -= edge.weight;
                e0[j] += 0.0;
                binary_edges.push_back({i, j, edge.weight, 0.0});
                // The constant w is irrelevant to the minimiser.
            }
            continue;
        }
        // One endpoint free (p), the other fixed with final label g.
        const int p = sp == NodeState::kFree ? edge.p : edge.q;
        const int q = sp == NodeState::kFree ? edge.q : edge.p;
        const int g = state[q] == NodeState::kAlpha ? alpha : labels[q];
        if (labels[p] != g) e0[vertex[p]] += edge.weight;
        if (alpha != g) e1[vertex[p]] += edge.weight;
    }

    std::vector<uint8_t> switch_to_alpha(num_free, 0);
    if (binary_edges.empty()) {
        for (int i = 0; i < num_free; ++i) switch_to_alpha[i] = e1[i] < e0[i] ? 1 : 0;
    } else {
        cv::detail::GCGraph<double> graph(static_cast<unsigned>(num_free),
                                          static_cast<unsigned>(binary_edges.size()));
        for (int i = 0; i < num_free; ++i) {
            graph.addVtx();
            const double m = std::min(e0[i], e1[i]);
            // Label 0 (keep) = source side, label 1 (alpha) = sink side: the first weight is paid
            // on the sink side, the second on the source side (reference §4.5, checked).
            graph.addTermWeights(i, e1[i] - m, e0[i] - m);
        }
        for (const BinaryEdge& e : binary_edges) graph.addEdges(e.i, e.j, e.w, e.revw);
        try {
            graph.maxFlow();
        } catch (const cv::Exception&) {
            return false;
        }
        ++*max_flow_calls;
        for (int i = 0; i < num_free; ++i) switch_to_alpha[i] = graph.inSourceSegment(i) ? 0 : 1;
    }
    for (int p = 0; p < n; ++p) {
        if (state[p] == NodeState::kFree && switch_to_alpha[vertex[p]]) (*proposal)[p] = alpha;
    }
    return true;
}

}  // namespace

Result<ExpansionResult> alphaExpansion(const PottsProblem& problem, std::vector<int> initial,
                                       const ExpansionConfig& config) {
    PLUMB_RETURN_IF_ERROR(validatePottsProblem(problem));
    const int n = problem.num_nodes;
    if (initial.empty()) {
        initial.resize(n);
        for (int p = 0; p < n; ++p) {
            int best = 0;
            for (int l = 1; l < problem.num_labels; ++l) {
                if (problem.cost(p, l) < problem.cost(p, best)) best = l;
            }
            initial[p] = best;
        }
    }
    if (static_cast<int>(initial.size()) != n) {
        return invalidArgument(
            fmt::format("alpha-expansion: initial labelling has {} entries for "
                        "{} nodes",
                        initial.size(), n));
    }
    for (int p = 0; p < n; ++p) {
        if (initial[p] < 0 || initial[p] >= problem.num_labels) {
            return invalidArgument(
                fmt::format("alpha-expansion: initial label {} of node {} is outside [0, {})",
                            initial[p], p, problem.num_labels));
        }
    }
    std::vector<double> incident_weight(n, 0.0);
    for (const PottsEdge& e : problem.edges) {
        incident_weight[e.p] += e.weight;
        incident_weight[e.q] += e.weight;
    }

    ExpansionResult result;
    result.labels = std::move(initial);
    result.initial_energy = pottsEnergy(problem, result.labels);
    result.energy = result.initial_energy;
    std::vector<int> proposal;
    for (int cycle = 0; cycle < config.max_cycles; ++cycle) {
        ++result.cycles;
        bool improved = false;
        for (int alpha = 0; alpha < problem.num_labels; ++alpha) {
            if (!expansionMove(problem, incident_weight, result.labels, alpha, &proposal,
                               &result.max_flow_calls)) {
                return Status(StatusCode::kInternal,
                              fmt::format("alpha-expansion: max-flow failed for label {}", alpha));
            }
            const double e = pottsEnergy(problem, proposal);
            if (e < result.energy - config.min_improvement) {
                result.labels.swap(proposal);
                result.energy = e;
                ++result.moves_accepted;
                improved = true;
            }
        }
        if (!improved) break;
    }
    return result;
}

Result<ExpansionResult> bruteForcePotts(const PottsProblem& problem) {
    PLUMB_RETURN_IF_ERROR(validatePottsProblem(problem));
    const double states = std::pow(static_cast<double>(problem.num_labels), problem.num_nodes);
    if (states > static_cast<double>(1 << 24)) {
        return invalidArgument(
            fmt::format("brute force over {} states is too large (limit 2^24)", states));
    }
    std::vector<int> labels(problem.num_nodes, 0);
    ExpansionResult best;
    best.labels = labels;
    best.energy = pottsEnergy(problem, labels);
    best.initial_energy = best.energy;
    const int64_t total = static_cast<int64_t>(states);
    for (int64_t s = 1; s < total; ++s) {
        // Increment the mixed-radix counter.
        for (int p = 0; p < problem.num_nodes; ++p) {
            if (++labels[p] < problem.num_labels) break;
            labels[p] = 0;
        }
        const double e = pottsEnergy(problem, labels);
        if (e < best.energy) {
            best.energy = e;
            best.labels = labels;
        }
    }
    return best;
}

}  // namespace plumb::layout
