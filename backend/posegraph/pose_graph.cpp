// SPDX-License-Identifier: Apache-2.0
#include "backend/posegraph/pose_graph.hpp"

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>

namespace plumb::posegraph {

const char* toString(PoseGraphEdge::Kind kind) {
    return kind == PoseGraphEdge::Kind::kOdometry ? "odometry" : "loop";
}

void describe(config::Schema& s, PoseGraphConfig& c) {
    s.field("preference_loop_closure", c.preference_loop_closure,
            "line-process preference (Open3D preference_loop_closure)")
        .positive();
    s.field("max_correspondence_distance_m", c.max_correspondence_distance_m,
            "correspondence distance the information matrices were built with", "m")
        .positive();
    s.field("edge_prune_threshold", c.edge_prune_threshold,
            "loop edges whose line-process weight falls below this are pruned")
        .range(0.0, 1.0);
    s.field("max_iterations", c.max_iterations, "maximum LM iterations per round").min(1);
    s.field("relative_cost_tolerance", c.relative_cost_tolerance,
            "stop when the relative cost decrease falls below this")
        .min(0.0);
    s.field("step_tolerance", c.step_tolerance, "stop when the step norm falls below this")
        .min(0.0);
    s.field("initial_lambda", c.initial_lambda, "initial LM damping (relative to the diagonal)")
        .positive();
    s.field("reference_node", c.reference_node, "node held fixed (the gauge)").min(0);
}

namespace {

Matrix6d adjoint(const Eigen::Isometry3d& T) {
    Matrix6d ad = Matrix6d::Zero();
    const Eigen::Matrix3d R = T.rotation();
    ad.topLeftCorner<3, 3>() = R;
    ad.bottomRightCorner<3, 3>() = R;
    ad.bottomLeftCorner<3, 3>() = lie::skew(T.translation()) * R;
    return ad;
}

/// ad(xi) for xi = (omega, upsilon): [[ω^, 0], [υ^, ω^]].
Matrix6d smallAdjoint(const Vector6d& xi) {
    Matrix6d ad = Matrix6d::Zero();
    const Eigen::Matrix3d w = lie::skew(xi.head<3>());
    ad.topLeftCorner<3, 3>() = w;
    ad.bottomRightCorner<3, 3>() = w;
    ad.bottomLeftCorner<3, 3>() = lie::skew(xi.tail<3>());
    return ad;
}

bool finitePose(const Eigen::Isometry3d& T) { return T.matrix().allFinite(); }

struct Problem {
    const PoseGraph* graph;
    std::vector<int> active;  ///< indices of the edges taking part
    std::vector<int> var;     ///< node -> variable block, -1 for the reference node
    int num_vars = 0;
    double mu = 0.0;
};

/// f = e^T Λ e of every active edge.
std::vector<double> edgeCosts(const Problem& p, const std::vector<Eigen::Isometry3d>& T) {
    std::vector<double> f(p.active.size());
    for (size_t k = 0; k < p.active.size(); ++k) {
        const PoseGraphEdge& e = p.graph->edges[p.active[k]];
        const Vector6d r = edgeResidual(e, T[e.source], T[e.target]);
        f[k] = std::max(0.0, r.dot(e.information * r));
    }
    return f;
}

/// Robust total: Σ_odometry f + Σ_loop ρ(f), ρ(f) = μ f / (μ + f) = min_l [l f + μ(√l - 1)^2].
double robustCost(const Problem& p, const std::vector<double>& f) {
    double c = 0.0;
    for (size_t k = 0; k < p.active.size(); ++k) {
        const PoseGraphEdge& e = p.graph->edges[p.active[k]];
        if (e.kind == PoseGraphEdge::Kind::kLoop) {
            c += p.mu > 0.0 ? p.mu * f[k] / (p.mu + f[k]) : 0.0;
        } else {
            c += f[k];
        }
    }
    return c;
}

/// Closed-form line process (Choi Eq. (5)): l = (μ / (μ + f))^2.
double lineProcess(double mu, double f) {
    if (!(mu > 0.0)) return 0.0;
    const double s = mu / (mu + f);
    return s * s;
}

/// One round of iteratively re-weighted LM. Returns iterations; sets *converged.
int optimiseRound(const Problem& p, std::vector<Eigen::Isometry3d>& T,
                  const PoseGraphConfig& config, bool* converged) {
    *converged = false;
    if (p.num_vars == 0) {
        *converged = true;
        return 0;
    }
    const int n = 6 * p.num_vars;
    double lambda = config.initial_lambda;
    std::vector<double> f = edgeCosts(p, T);
    double cost = robustCost(p, f);
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver;
    bool analysed = false;
    int it = 0;
    for (; it < config.max_iterations; ++it) {
        // Normal equations of Σ w e^T Λ e with w = l (loop) or 1 (odometry), e linearised as
        // e ≈ e0 + J_l^-1(e0) Ad(A) (δ_t - δ_s), A = T_st^-1 T_W_s^-1 (left perturbations).
        std::vector<Eigen::Triplet<double>> triplets;
        triplets.reserve(p.active.size() * 4 * 36 + static_cast<size_t>(n));
        Eigen::VectorXd b = Eigen::VectorXd::Zero(n);
        for (size_t k = 0; k < p.active.size(); ++k) {
            const PoseGraphEdge& e = p.graph->edges[p.active[k]];
            const double w = e.kind == PoseGraphEdge::Kind::kLoop ? lineProcess(p.mu, f[k]) : 1.0;
            if (w <= 0.0) continue;
            const Eigen::Isometry3d A = e.T_source_target.inverse() * T[e.source].inverse();
            const Vector6d r = edgeResidual(e, T[e.source], T[e.target]);
            const Matrix6d J = (Matrix6d::Identity() - 0.5 * smallAdjoint(r)) * adjoint(A);
            const Matrix6d JtL = J.transpose() * (w * e.information);
            const Matrix6d H = JtL * J;
            const Vector6d g = JtL * r;
            const int vs = p.var[e.source], vt = p.var[e.target];
            // J_s = -J, J_t = +J.
            auto add = [&](int vi, int vj, const Matrix6d& M) {
                for (int c = 0; c < 6; ++c) {
                    for (int rr = 0; rr < 6; ++rr) {
                        triplets.emplace_back(6 * vi + rr, 6 * vj + c, M(rr, c));
                    }
                }
            };
            if (vs >= 0) {
                add(vs, vs, H);
                b.segment<6>(6 * vs) -= g;
            }
            if (vt >= 0) {
                add(vt, vt, H);
                b.segment<6>(6 * vt) += g;
            }
            if (vs >= 0 && vt >= 0) {
                add(vs, vt, -H);
                add(vt, vs, -H);
            }
        }
        for (int i = 0; i < n; ++i) triplets.emplace_back(i, i, 0.0);  // keep the diagonal
        Eigen::SparseMatrix<double> H(n, n);
        H.setFromTriplets(triplets.begin(), triplets.end());
        const Eigen::VectorXd diag = H.diagonal();
        if (!analysed) {
            solver.analyzePattern(H);
            analysed = true;
        }
        bool accepted = false;
        double new_cost = cost;
        double step_norm = 0.0;
        for (int attempt = 0; attempt < 12 && !accepted; ++attempt) {
            Eigen::SparseMatrix<double> A = H;
            for (int i = 0; i < n; ++i) {
                A.coeffRef(i, i) += lambda * std::max(diag[i], 1e-9);
            }
            solver.factorize(A);
            if (solver.info() != Eigen::Success) {
                lambda *= 10.0;
                continue;
            }
            const Eigen::VectorXd delta = -solver.solve(b);
            if (!delta.allFinite()) {
                lambda *= 10.0;
                continue;
            }
            std::vector<Eigen::Isometry3d> T_new = T;
            for (size_t i = 0; i < T.size(); ++i) {
                if (p.var[i] < 0) continue;
                T_new[i] = lie::orthonormalized(
                    lie::expSE3(Vector6d(delta.segment<6>(6 * p.var[i]))) * T[i]);
            }
            const std::vector<double> f_new = edgeCosts(p, T_new);
            new_cost = robustCost(p, f_new);
            step_norm = delta.norm();
            if (new_cost <= cost) {
                T.swap(T_new);
                f = f_new;
                accepted = true;
                lambda = std::max(lambda * 0.1, 1e-12);
            } else {
                lambda *= 10.0;
            }
        }
        if (!accepted) {
            *converged = true;  // no step decreases the cost: a (numerical) minimum
            break;
        }
        const double decrease = cost - new_cost;
        cost = new_cost;
        if (decrease <= config.relative_cost_tolerance * std::max(cost, 1e-300) ||
            step_norm < config.step_tolerance) {
            *converged = true;
            ++it;
            break;
        }
    }
    return it;
}

}  // namespace

Vector6d edgeResidual(const PoseGraphEdge& edge, const Eigen::Isometry3d& T_W_source,
                      const Eigen::Isometry3d& T_W_target) {
    const Eigen::Isometry3d E = edge.T_source_target.inverse() * T_W_source.inverse() * T_W_target;
    return lie::logSE3(E);
}

double lineProcessMu(const PoseGraph& graph, const PoseGraphConfig& config) {
    double sum = 0.0;
    int count = 0;
    for (const PoseGraphEdge& e : graph.edges) {
        if (!e.kept) continue;
        sum += e.information(5, 5);
        ++count;
    }
    if (count == 0) return 0.0;
    const double tau = config.max_correspondence_distance_m;
    return config.preference_loop_closure * tau * tau * (sum / count);
}

Result<PoseGraphReport> optimisePoseGraph(PoseGraph& graph, const PoseGraphConfig& config) {
    const size_t num_nodes = graph.T_W_F.size();
    if (num_nodes == 0) return invalidArgument("pose graph: no nodes");
    if (config.reference_node < 0 || static_cast<size_t>(config.reference_node) >= num_nodes) {
        return invalidArgument("pose graph: reference node " +
                               std::to_string(config.reference_node) + " out of range (" +
                               std::to_string(num_nodes) + " nodes)");
    }
    for (size_t i = 0; i < num_nodes; ++i) {
        if (!finitePose(graph.T_W_F[i])) {
            return invalidArgument("pose graph: node " + std::to_string(i) +
                                   " has a non-finite pose");
        }
    }
    std::vector<int> parent(num_nodes);
    std::iota(parent.begin(), parent.end(), 0);
    auto find = [&](int x) {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
    };
    for (size_t k = 0; k < graph.edges.size(); ++k) {
        const PoseGraphEdge& e = graph.edges[k];
        if (e.source >= num_nodes || e.target >= num_nodes || e.source == e.target) {
            return invalidArgument("pose graph: edge " + std::to_string(k) + " (" +
                                   std::to_string(e.source) + " -> " + std::to_string(e.target) +
                                   ") names a missing node or a self loop");
        }
        if (!e.kept) continue;
        if (!finitePose(e.T_source_target) || !e.information.allFinite()) {
            return invalidArgument("pose graph: edge " + std::to_string(e.source) + " -> " +
                                   std::to_string(e.target) +
                                   " has a non-finite transform or information matrix");
        }
        if (e.kind == PoseGraphEdge::Kind::kOdometry) {
            parent[find(static_cast<int>(e.source))] = find(static_cast<int>(e.target));
        }
    }
    // Connectivity through odometry edges only, since loops may be pruned.
    for (size_t i = 0; i < num_nodes; ++i) {
        if (find(static_cast<int>(i)) != find(config.reference_node)) {
            return failedPrecondition("pose graph: node " + std::to_string(i) +
                                      " is not connected to the reference node by odometry edges");
        }
    }

    PoseGraphReport report;
    Problem p;
    p.graph = &graph;
    p.mu = lineProcessMu(graph, config);
    report.mu = p.mu;
    p.var.assign(num_nodes, -1);
    for (size_t i = 0; i < num_nodes; ++i) {
        if (static_cast<int>(i) != config.reference_node) p.var[i] = p.num_vars++;
    }
    auto collectActive = [&] {
        p.active.clear();
        for (size_t k = 0; k < graph.edges.size(); ++k) {
            if (graph.edges[k].kept) p.active.push_back(static_cast<int>(k));
        }
    };
    collectActive();
    for (int k : p.active) {
        if (graph.edges[k].kind == PoseGraphEdge::Kind::kLoop) ++report.num_loop_edges;
    }
    report.initial_cost = robustCost(p, edgeCosts(p, graph.T_W_F));

    std::vector<Eigen::Isometry3d> T = graph.T_W_F;
    // Optimise, prune, and optimise again while pruning changes the graph (at most 3 rounds).
    for (int round = 0; round < 3; ++round) {
        bool converged = false;
        report.iterations += optimiseRound(p, T, config, &converged);
        report.converged = converged;
        ++report.rounds;
        const std::vector<double> f = edgeCosts(p, T);
        report.final_cost = robustCost(p, f);
        bool pruned = false;
        for (size_t k = 0; k < p.active.size(); ++k) {
            PoseGraphEdge& e = graph.edges[p.active[k]];
            if (e.kind != PoseGraphEdge::Kind::kLoop) {
                e.line_process = 1.0;
                continue;
            }
            e.line_process = lineProcess(p.mu, f[k]);
            if (e.line_process < config.edge_prune_threshold) {
                e.kept = false;
                char buf[160];
                std::snprintf(buf, sizeof(buf),
                              "pruned: line-process weight %.4f < %.2f after round %d",
                              e.line_process, config.edge_prune_threshold, round + 1);
                e.reason = buf;
                ++report.num_pruned;
                pruned = true;
            }
        }
        if (!pruned) break;
        collectActive();
    }
    graph.T_W_F = T;
    return report;
}

}  // namespace plumb::posegraph
