// SPDX-License-Identifier: Apache-2.0
#include "backend/posegraph/pose_graph.hpp"

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <optional>

namespace plumb::posegraph {

const char* toString(PoseGraphEdge::Kind kind) {
    return kind == PoseGraphEdge::Kind::kOdometry ? "odometry" : "loop";
}

const char* toString(PoseGraphEdge::Information information) {
    switch (information) {
        case PoseGraphEdge::Information::kChoi:
            return "choi";
        case PoseGraphEdge::Information::kPlane:
            return "point_to_plane";
        case PoseGraphEdge::Information::kTracker:
            return "tracker";
    }
    return "?";
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
    s.field("cg_relative_tolerance", c.cg_relative_tolerance,
            "forcing term of the inexact LM steps: conjugate gradients stop at this relative "
            "residual")
        .range(1e-12, 0.5);
    s.field("chain_max_cg_iterations", c.chain_max_cg_iterations,
            "conjugate-gradient iterations with the odometry-chain preconditioner before the "
            "step is factorised (0: factorise from the first step)")
        .min(0);
    s.field("factor_max_cg_iterations", c.factor_max_cg_iterations,
            "conjugate-gradient iterations with an earlier factorisation as preconditioner "
            "before the step is factorised afresh")
        .min(0);
    s.field("reference_node", c.reference_node, "node held fixed (the gauge)").min(0);
}

namespace {

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

/// The Gauss-Newton system of one linearisation, kept per edge: H_e = J^T w Λ J and g_e = J^T w Λ e
/// with J_source = -J, J_target = +J. It is applied matrix-free by the conjugate-gradient solve and
/// assembled into a sparse matrix only when it is factorised.
struct LinearSystem {
    std::vector<Matrix6d> H;  ///< per active edge
    Eigen::VectorXd b;        ///< right-hand side -Σ J^T w Λ e
    Eigen::VectorXd diag;     ///< diagonal of the assembled matrix (the LM damping scale)
};

LinearSystem linearise(const Problem& p, const std::vector<Eigen::Isometry3d>& T,
                       const std::vector<double>& f) {
    const int n = 6 * p.num_vars;
    LinearSystem s;
    s.H.resize(p.active.size());
    s.b = Eigen::VectorXd::Zero(n);
    s.diag = Eigen::VectorXd::Zero(n);
    for (size_t k = 0; k < p.active.size(); ++k) {
        const PoseGraphEdge& e = p.graph->edges[p.active[k]];
        const double w = e.kind == PoseGraphEdge::Kind::kLoop ? lineProcess(p.mu, f[k]) : 1.0;
        if (w <= 0.0) {
            s.H[k].setZero();
            continue;
        }
        // e ≈ e0 + J_l^-1(e0) Ad(A) (δ_t - δ_s), A = T_st^-1 T_W_s^-1 (left perturbations).
        const Eigen::Isometry3d A = e.T_source_target.inverse() * T[e.source].inverse();
        const Vector6d r = edgeResidual(e, T[e.source], T[e.target]);
        const Matrix6d J = (Matrix6d::Identity() - 0.5 * lie::adSE3(r)) * lie::adjointSE3(A);
        const Matrix6d JtL = J.transpose() * (w * e.information);
        s.H[k] = JtL * J;
        const Vector6d g = JtL * r;
        const int vs = p.var[e.source], vt = p.var[e.target];
        if (vs >= 0) {
            s.b.segment<6>(6 * vs) += g;
            s.diag.segment<6>(6 * vs) += s.H[k].diagonal();
        }
        if (vt >= 0) {
            s.b.segment<6>(6 * vt) -= g;
            s.diag.segment<6>(6 * vt) += s.H[k].diagonal();
        }
    }
    return s;
}

/// y = (H + λ D) x without assembling H.
Eigen::VectorXd applyDamped(const Problem& p, const LinearSystem& s, const Eigen::VectorXd& damping,
                            const Eigen::VectorXd& x) {
    Eigen::VectorXd y = damping.cwiseProduct(x);
    for (size_t k = 0; k < p.active.size(); ++k) {
        const PoseGraphEdge& e = p.graph->edges[p.active[k]];
        const int vs = p.var[e.source], vt = p.var[e.target];
        // H_e acts on (x_t - x_s): rows of the source get -H_e d, rows of the target +H_e d.
        Vector6d d = Vector6d::Zero();
        if (vt >= 0) d += x.segment<6>(6 * vt);
        if (vs >= 0) d -= x.segment<6>(6 * vs);
        const Vector6d hd = s.H[k] * d;
        if (vt >= 0) y.segment<6>(6 * vt) += hd;
        if (vs >= 0) y.segment<6>(6 * vs) -= hd;
    }
    return y;
}

/// The sparsity pattern of a round's normal equations (lower triangle, column-major) and, per
/// active edge, where each of its three 6x6 blocks (ss, tt, ts) starts in every column, so that a
/// linearisation is assembled by adding into the value array without sorting triplets.
struct Assembly {
    Eigen::SparseMatrix<double> matrix;
    /// Per active edge and block (0: ss, 1: tt, 2: lower off-diagonal), the value index of the
    /// block's first row in each of its 6 columns; -1 when the block does not exist.
    std::vector<std::array<std::array<int, 6>, 3>> offsets;
    std::vector<std::array<int, 6>> diagonal;  ///< per variable block: its diagonal block
};

Assembly buildAssembly(const Problem& p) {
    const int n = 6 * p.num_vars;
    std::vector<Eigen::Triplet<double>> pattern;
    auto block = [&](int vi, int vj) {  // lower triangle: vi >= vj
        for (int c = 0; c < 6; ++c) {
            for (int r = vi == vj ? c : 0; r < 6; ++r) pattern.emplace_back(6 * vi + r, 6 * vj + c);
        }
    };
    for (int v = 0; v < p.num_vars; ++v) block(v, v);
    for (int k : p.active) {
        const PoseGraphEdge& e = p.graph->edges[k];
        const int vs = p.var[e.source], vt = p.var[e.target];
        if (vs >= 0 && vt >= 0) block(std::max(vs, vt), std::min(vs, vt));
    }
    Assembly a;
    a.matrix.resize(n, n);
    a.matrix.setFromTriplets(pattern.begin(), pattern.end());
    a.matrix.makeCompressed();
    // Row indices within a column are sorted, so a block's 6 rows are contiguous from its first.
    auto first = [&](int vi, int vj, int c) {
        const int col = 6 * vj + c;
        const int* rows = a.matrix.innerIndexPtr();
        const int* begin = rows + a.matrix.outerIndexPtr()[col];
        const int* end = rows + a.matrix.outerIndexPtr()[col + 1];
        return static_cast<int>(std::lower_bound(begin, end, 6 * vi) - rows);
    };
    a.diagonal.resize(p.num_vars);
    for (int v = 0; v < p.num_vars; ++v) {
        for (int c = 0; c < 6; ++c) a.diagonal[v][c] = first(v, v, c);
    }
    a.offsets.resize(p.active.size());
    for (size_t k = 0; k < p.active.size(); ++k) {
        const PoseGraphEdge& e = p.graph->edges[p.active[k]];
        const int vs = p.var[e.source], vt = p.var[e.target];
        for (int c = 0; c < 6; ++c) {
            a.offsets[k][0][c] = vs >= 0 ? first(vs, vs, c) : -1;
            a.offsets[k][1][c] = vt >= 0 ? first(vt, vt, c) : -1;
            a.offsets[k][2][c] =
                vs >= 0 && vt >= 0 ? first(std::max(vs, vt), std::min(vs, vt), c) : -1;
        }
    }
    return a;
}

/// Writes H + λ D into the assembly's value array (lower triangle).
void assemble(const Problem& p, const LinearSystem& s, const Eigen::VectorXd& damping,
              Assembly& a) {
    double* values = a.matrix.valuePtr();
    std::fill(values, values + a.matrix.nonZeros(), 0.0);
    // A diagonal block stores rows c..5 of column c from its first index; an off-diagonal block
    // all 6 rows.
    auto addDiagonal = [&](const std::array<int, 6>& at, const Matrix6d& M) {
        for (int c = 0; c < 6; ++c) {
            for (int r = c; r < 6; ++r) values[at[c] + r - c] += M(r, c);
        }
    };
    for (size_t k = 0; k < p.active.size(); ++k) {
        const Matrix6d& H = s.H[k];
        const auto& at = a.offsets[k];
        if (at[0][0] >= 0) addDiagonal(at[0], H);
        if (at[1][0] >= 0) addDiagonal(at[1], H);
        if (at[2][0] >= 0) {
            // Block (row var, column var) = -H_e for (s, t) or (t, s); H_e is symmetric.
            for (int c = 0; c < 6; ++c) {
                for (int r = 0; r < 6; ++r) values[at[2][c] + r] -= H(r, c);
            }
        }
    }
    for (int v = 0; v < p.num_vars; ++v) {
        for (int c = 0; c < 6; ++c) values[a.diagonal[v][c]] += damping[6 * v + c];
    }
}

/// The chain preconditioner: H + λD restricted to its block diagonal and the blocks between
/// consecutive variables (the odometry chain), factorised by block Gaussian elimination in O(n).
/// Loop edges keep only their diagonal blocks. It is positive definite whenever H + λD is.
class ChainPreconditioner {
  public:
    ChainPreconditioner(const Problem& p, const LinearSystem& s, const Eigen::VectorXd& damping) {
        const int m = p.num_vars;
        std::vector<Matrix6d> D(m, Matrix6d::Zero());
        lower_.assign(m, Matrix6d::Zero());
        for (int v = 0; v < m; ++v) D[v].diagonal() = damping.segment<6>(6 * v);
        for (size_t k = 0; k < p.active.size(); ++k) {
            const PoseGraphEdge& e = p.graph->edges[p.active[k]];
            const int vs = p.var[e.source], vt = p.var[e.target];
            if (vs >= 0) D[vs] += s.H[k];
            if (vt >= 0) D[vt] += s.H[k];
            if (vs >= 0 && vt >= 0 && std::abs(vs - vt) == 1) lower_[std::min(vs, vt)] -= s.H[k];
        }
        // Pivots U_0 = D_0, U_v = D_v - L_{v-1} U_{v-1}^-1 L_{v-1}^T (L_v: block (v+1, v)).
        pivot_inverse_.resize(m);
        for (int v = 0; v < m; ++v) {
            if (v > 0) D[v] -= lower_[v - 1] * pivot_inverse_[v - 1] * lower_[v - 1].transpose();
            Eigen::LLT<Matrix6d> llt(D[v]);
            valid_ = valid_ && llt.info() == Eigen::Success;
            pivot_inverse_[v] = llt.solve(Matrix6d::Identity());
        }
    }
    bool valid() const { return valid_; }
    Eigen::VectorXd solve(const Eigen::VectorXd& r) const {
        const int m = static_cast<int>(pivot_inverse_.size());
        Eigen::VectorXd y = r;
        for (int v = 1; v < m; ++v) {
            y.segment<6>(6 * v) -=
                lower_[v - 1] * (pivot_inverse_[v - 1] * y.segment<6>(6 * v - 6));
        }
        Eigen::VectorXd x(r.size());
        for (int v = m - 1; v >= 0; --v) {
            Vector6d rhs = y.segment<6>(6 * v);
            if (v + 1 < m) rhs -= lower_[v].transpose() * x.segment<6>(6 * v + 6);
            x.segment<6>(6 * v) = pivot_inverse_[v] * rhs;
        }
        return x;
    }

  private:
    std::vector<Matrix6d> lower_;
    std::vector<Matrix6d> pivot_inverse_;
    bool valid_ = true;
};

/// Preconditioned conjugate gradients on (H + λ D) δ = b, stopping at |r| <= tolerance |b|.
/// Returns false when `max_iterations` are not enough. Every iterate lowers the quadratic model,
/// so a step cut short is still a descent step.
template <typename Preconditioner>
bool solvePreconditioned(const Problem& p, const LinearSystem& s, const Eigen::VectorXd& damping,
                         const Preconditioner& preconditioner, double tolerance, int max_iterations,
                         Eigen::VectorXd* delta, int* iterations) {
    const double b_norm = s.b.norm();
    Eigen::VectorXd x = Eigen::VectorXd::Zero(s.b.size());
    if (b_norm == 0.0) {
        *delta = x;
        return true;
    }
    Eigen::VectorXd r = s.b;
    Eigen::VectorXd z = preconditioner.solve(r);
    Eigen::VectorXd d = z;
    double rz = r.dot(z);
    for (int it = 0; it < max_iterations; ++it) {
        ++*iterations;
        const Eigen::VectorXd Ad = applyDamped(p, s, damping, d);
        const double dAd = d.dot(Ad);
        if (!(dAd > 0.0)) return false;
        const double alpha = rz / dAd;
        x += alpha * d;
        r -= alpha * Ad;
        if (r.norm() <= tolerance * b_norm) {
            *delta = x;
            return x.allFinite();
        }
        z = preconditioner.solve(r);
        const double rz_next = r.dot(z);
        d = z + (rz_next / rz) * d;
        rz = rz_next;
    }
    return false;
}

/// The LM solver state that outlives one iteration: the latest factorisation, reused as the
/// preconditioner of later iterations (and rounds).
struct Factorisation {
    /// Sparse LDL^T of the lower triangle (AMD ordering).
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;
    bool valid = false;
    int count = 0;          ///< factorisations computed
    int cg_iterations = 0;  ///< conjugate-gradient iterations run
};

/// One round of iteratively re-weighted LM. Returns iterations; sets *converged.
int optimiseRound(const Problem& p, std::vector<Eigen::Isometry3d>& T,
                  const PoseGraphConfig& config, Factorisation& factor, bool* converged) {
    *converged = false;
    if (p.num_vars == 0) {
        *converged = true;
        return 0;
    }
    double lambda = config.initial_lambda;
    std::vector<double> f = edgeCosts(p, T);
    double cost = robustCost(p, f);
    // The round's sparsity pattern, built (and its ordering analysed) at its first factorisation:
    // most rounds never factorise.
    std::optional<Assembly> assembly;
    int it = 0;
    for (; it < config.max_iterations; ++it) {
        const LinearSystem system = linearise(p, T, f);
        bool accepted = false;
        double new_cost = cost;
        double step_norm = 0.0;
        for (int attempt = 0; attempt < 12 && !accepted; ++attempt) {
            const Eigen::VectorXd damping = lambda * system.diag.cwiseMax(1e-9);
            Eigen::VectorXd delta;
            // An inexact Newton step: conjugate gradients to the forcing tolerance, preconditioned
            // by the latest factorisation or, before there is one, by the odometry chain. Only
            // when that does not converge is this step's system factorised.
            bool solved = false;
            if (factor.valid) {
                solved = solvePreconditioned(
                    p, system, damping, factor.ldlt, config.cg_relative_tolerance,
                    config.factor_max_cg_iterations, &delta, &factor.cg_iterations);
            } else {
                const ChainPreconditioner chain(p, system, damping);
                solved = chain.valid() && solvePreconditioned(p, system, damping, chain,
                                                              config.cg_relative_tolerance,
                                                              config.chain_max_cg_iterations,
                                                              &delta, &factor.cg_iterations);
            }
            if (!solved) {
                if (!assembly) {
                    assembly = buildAssembly(p);
                    factor.ldlt.analyzePattern(assembly->matrix);
                }
                assemble(p, system, damping, *assembly);
                factor.ldlt.factorize(assembly->matrix);
                ++factor.count;
                factor.valid = factor.ldlt.info() == Eigen::Success;
                if (factor.valid) delta = factor.ldlt.solve(system.b);
                solved = factor.valid && delta.allFinite();
            }
            if (!solved) {
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
        sum += e.information_source == PoseGraphEdge::Information::kTracker ? e.num_correspondences
                                                                            : e.information(5, 5);
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
    Factorisation factor;
    // Optimise, prune, and optimise again while pruning changes the graph (at most 3 rounds).
    for (int round = 0; round < 3; ++round) {
        bool converged = false;
        report.iterations += optimiseRound(p, T, config, factor, &converged);
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
    report.factorisations = factor.count;
    report.cg_iterations = factor.cg_iterations;
    return report;
}

}  // namespace plumb::posegraph
