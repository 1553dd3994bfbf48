// SPDX-License-Identifier: Apache-2.0
#include "backend/calibration/planar_distortion.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "backend/calibration/self_calibration.hpp"
#include "common/core/parallel.hpp"

namespace plumb::calibration {
namespace {

constexpr int kTerms = PlanarDistortion::kTerms;
constexpr int kBins = PlanarDistortion::kBins;
constexpr int kParams = kTerms * kBins;
using ParamMatrix = Eigen::Matrix<double, kParams, kParams>;
using ParamVector = Eigen::Matrix<double, kParams, 1>;
using Block = PlanarDistortionEstimator::Block;

double degrees(double rad) { return rad * 180.0 / std::numbers::pi; }

/// One frame's blocks corrected by the current model, with their normals.
struct CorrectedFrame {
    std::vector<Eigen::Vector3d> q;       ///< f * P (z = 0: not used)
    std::vector<Eigen::Vector3d> normal;  ///< unit, towards the camera (zero: none)
    std::vector<double> factor;
};

/// The normal equations of one frame's segments with their planes eliminated.
struct FrameSystem {
    ParamMatrix h = ParamMatrix::Zero();
    ParamVector g = ParamVector::Zero();
    Eigen::Matrix<double, kBins, 1> bin_weight = Eigen::Matrix<double, kBins, 1>::Zero();
    double cost = 0.0;    ///< sum of squared normalised weighted residuals
    double weight = 0.0;  ///< sum of the robust weights
    size_t segments = 0, blocks = 0;
};

class Fitter {
  public:
    Fitter(const PlanarDistortionConfig& config, int columns, int rows)
        : config_(config), columns_(columns), rows_(rows) {}

    CorrectedFrame correct(const std::vector<Block>& blocks, const PlanarDistortion& model) const {
        CorrectedFrame out;
        const size_t n = blocks.size();
        out.q.assign(n, Eigen::Vector3d::Zero());
        out.normal.assign(n, Eigen::Vector3d::Zero());
        out.factor.assign(n, 1.0);
        for (size_t i = 0; i < n; ++i) {
            const Block& b = blocks[i];
            if (b.z <= 0.0F) continue;
            const double f = model.factor(b.u, b.v, b.z);
            out.factor[i] = f;
            out.q[i] = f * Eigen::Vector3d(b.x, b.y, b.z);
        }
        const int s = config_.normal_stencil;
        for (int y = s; y + s < rows_; ++y) {
            for (int x = s; x + s < columns_; ++x) {
                const size_t i = index(x, y);
                if (out.q[i].z() <= 0.0) continue;
                const Eigen::Vector3d& l = out.q[index(x - s, y)];
                const Eigen::Vector3d& r = out.q[index(x + s, y)];
                const Eigen::Vector3d& u = out.q[index(x, y - s)];
                const Eigen::Vector3d& d = out.q[index(x, y + s)];
                const double z = out.q[i].z();
                const double step = config_.max_depth_step * z * s;
                bool ok = true;
                for (const Eigen::Vector3d* p : {&l, &r, &u, &d}) {
                    ok = ok && p->z() > 0.0 && std::abs(p->z() - z) <= step;
                }
                if (!ok) continue;
                Eigen::Vector3d n = (r - l).cross(d - u);
                if (n.norm() <= 0.0) continue;
                n.normalize();
                if (n.dot(out.q[i]) > 0.0) n = -n;
                out.normal[i] = n;
            }
        }
        return out;
    }

    /// Planar segments of one frame: region growing over the 4-neighbourhood.
    std::vector<std::vector<size_t>> segment(const CorrectedFrame& f) const {
        const double cos_neighbour =
            std::cos(config_.max_neighbour_angle_deg * std::numbers::pi / 180.0);
        const double cos_spread =
            std::cos(config_.max_segment_spread_deg * std::numbers::pi / 180.0);
        std::vector<int> label(f.q.size(), -1);
        std::vector<std::vector<size_t>> segments;
        std::vector<size_t> stack;
        for (size_t seed = 0; seed < f.q.size(); ++seed) {
            if (label[seed] >= 0 || f.normal[seed].isZero()) continue;
            const int id = static_cast<int>(segments.size());
            std::vector<size_t> members;
            label[seed] = id;
            stack.assign(1, seed);
            while (!stack.empty()) {
                const size_t a = stack.back();
                stack.pop_back();
                members.push_back(a);
                const int ax = static_cast<int>(a % static_cast<size_t>(columns_));
                const int ay = static_cast<int>(a / static_cast<size_t>(columns_));
                const int nx[4] = {ax - 1, ax + 1, ax, ax};
                const int ny[4] = {ay, ay, ay - 1, ay + 1};
                for (int k = 0; k < 4; ++k) {
                    if (nx[k] < 0 || ny[k] < 0 || nx[k] >= columns_ || ny[k] >= rows_) continue;
                    const size_t b = index(nx[k], ny[k]);
                    if (label[b] >= 0 || f.normal[b].isZero()) continue;
                    if (f.normal[a].dot(f.normal[b]) < cos_neighbour) continue;
                    if (f.normal[seed].dot(f.normal[b]) < cos_spread) continue;
                    if (std::abs(f.q[a].z() - f.q[b].z()) > config_.max_depth_step * f.q[a].z()) {
                        continue;
                    }
                    label[b] = id;
                    stack.push_back(b);
                }
            }
            std::sort(members.begin(), members.end());
            segments.push_back(std::move(members));
        }
        std::erase_if(segments, [&](const std::vector<size_t>& m) {
            return static_cast<int>(m.size()) < config_.min_segment_blocks;
        });
        return segments;
    }

    /// The robust plane of one segment: the weighted PCA plane, Huber weights at huber_sigmas
    /// robust sigmas, the plane again (three passes). `ok` false when the block normals spread
    /// too far from it (a curved surface, not a bent plane).
    struct SegmentFit {
        Eigen::Vector3d n = Eigen::Vector3d::Zero();  ///< unit, towards the camera
        double d = 0.0;                               ///< n . q = d on the plane
        std::vector<double> sigma, residual, weight;  ///< per block, residuals in sigmas
        double cost = 0.0, wsum = 0.0;  ///< sum of weighted squared residuals, of weights
        bool ok = false;
    };
    SegmentFit fitSegment(const CorrectedFrame& f, const std::vector<size_t>& seg) const {
        SegmentFit s;
        const size_t m = seg.size();
        s.sigma.resize(m);
        s.weight.assign(m, 1.0);
        s.residual.resize(m);
        for (size_t j = 0; j < m; ++j) {
            const double z = f.q[seg[j]].z();
            s.sigma[j] = config_.noise_per_m2 * z * z;
        }
        for (int pass = 0; pass < 3; ++pass) {
            fitPlane(f, seg, s.sigma, s.weight, &s.n, &s.d);
            for (size_t j = 0; j < m; ++j) {
                s.residual[j] = (s.n.dot(f.q[seg[j]]) - s.d) / s.sigma[j];
            }
            std::vector<double> a(m);
            for (size_t j = 0; j < m; ++j) a[j] = std::abs(s.residual[j]);
            std::nth_element(a.begin(), a.begin() + static_cast<long>(m / 2), a.end());
            const double scale = std::max(1.4826 * a[m / 2], 1e-3);
            const double k = config_.huber_sigmas * scale;
            for (size_t j = 0; j < m; ++j) {
                const double e = std::abs(s.residual[j]);
                s.weight[j] = e <= k ? 1.0 : k / e;
            }
        }
        double min_cos = 1.0;
        for (size_t j : seg) min_cos = std::min(min_cos, std::abs(f.normal[j].dot(s.n)));
        if (degrees(std::acos(std::clamp(min_cos, -1.0, 1.0))) > config_.max_segment_spread_deg) {
            return s;
        }
        for (size_t j = 0; j < m; ++j) {
            s.cost += s.weight[j] * s.residual[j] * s.residual[j];
            s.wsum += s.weight[j];
        }
        s.ok = true;
        return s;
    }

    /// Adds the segments of one frame to its system (Eq. 2, the planes eliminated).
    void accumulate(const std::vector<Block>& blocks, const CorrectedFrame& f,
                    const std::vector<std::vector<size_t>>& segments, bool gate_rms,
                    FrameSystem* sys) const {
        for (const std::vector<size_t>& seg : segments) {
            const size_t m = seg.size();
            const SegmentFit fit = fitSegment(f, seg);
            if (!fit.ok) continue;
            const Eigen::Vector3d& n = fit.n;
            const double d = fit.d;
            const std::vector<double>& sigma = fit.sigma;
            const std::vector<double>& weight = fit.weight;
            const double cost = fit.cost, wsum = fit.wsum;
            if (gate_rms && std::sqrt(cost / wsum) > config_.max_segment_rms_sigmas) continue;
            sys->cost += cost;
            sys->weight += wsum;
            ++sys->segments;
            sys->blocks += m;

            // Plane parameters: n + a t1 + b t2 (first order), d + e.
            Eigen::Vector3d t1 = n.unitOrthogonal();
            Eigen::Vector3d t2 = n.cross(t1);
            Eigen::Matrix3d hpp = Eigen::Matrix3d::Zero();
            Eigen::Matrix<double, 3, kParams> hpt = Eigen::Matrix<double, 3, kParams>::Zero();
            Eigen::Vector3d gp = Eigen::Vector3d::Zero();
            for (size_t j = 0; j < m; ++j) {
                const size_t i = seg[j];
                const Block& b = blocks[i];
                const Eigen::Vector3d& q = f.q[i];
                const double w = weight[j] / (sigma[j] * sigma[j]);
                const double r = n.dot(q) - d;
                const Eigen::Vector3d jp(t1.dot(q), t2.dot(q), -1.0);
                // dr/dc[b][k] = n . P w_b(z) phi_k(u, v)
                const double np = n.dot(Eigen::Vector3d(b.x, b.y, b.z));
                const std::array<double, kTerms> terms = PlanarDistortion::terms(b.u, b.v);
                const Eigen::Map<const Eigen::Matrix<double, kTerms, 1>> phi(terms.data());
                const DistortionTable::BinWeights bw = DistortionTable::binWeights(q.z());
                sys->bin_weight[bw.lo] += weight[j] * (1.0 - bw.a);
                sys->bin_weight[bw.hi] += weight[j] * bw.a;
                hpp.noalias() += w * jp * jp.transpose();
                gp += w * r * jp;
                // The Jacobian is (1 - a) np phi in bin lo and a np phi in bin hi, zero
                // elsewhere: only those blocks of the system change.
                const int lo = bw.lo * kTerms, hi = bw.hi * kTerms;
                const double jl = (1.0 - bw.a) * np, jh = bw.a * np;
                hpt.middleCols<kTerms>(lo).noalias() += (w * jl) * jp * phi.transpose();
                hpt.middleCols<kTerms>(hi).noalias() += (w * jh) * jp * phi.transpose();
                sys->g.segment<kTerms>(lo) += (w * r * jl) * phi;
                sys->g.segment<kTerms>(hi) += (w * r * jh) * phi;
                if (lo == hi) {
                    sys->h.block<kTerms, kTerms>(lo, lo).selfadjointView<Eigen::Lower>().rankUpdate(
                        phi, w * (jl + jh) * (jl + jh));
                } else {
                    sys->h.block<kTerms, kTerms>(lo, lo).selfadjointView<Eigen::Lower>().rankUpdate(
                        phi, w * jl * jl);
                    sys->h.block<kTerms, kTerms>(hi, hi).selfadjointView<Eigen::Lower>().rankUpdate(
                        phi, w * jh * jh);
                    sys->h.block<kTerms, kTerms>(hi, lo).noalias() +=
                        (w * jh * jl) * phi * phi.transpose();
                }
            }
            // Schur complement of the plane's block.
            const Eigen::Matrix3d hpp_inv = (hpp + 1e-9 * Eigen::Matrix3d::Identity()).inverse();
            const Eigen::Matrix<double, kParams, 3> htp_hinv = hpt.transpose() * hpp_inv;
            sys->h.triangularView<Eigen::Lower>() -= htp_hinv * hpt;
            sys->g -= htp_hinv * gp;
        }
    }

  private:
    size_t index(int x, int y) const {
        return static_cast<size_t>(y) * static_cast<size_t>(columns_) + static_cast<size_t>(x);
    }

    static void fitPlane(const CorrectedFrame& f, const std::vector<size_t>& seg,
                         const std::vector<double>& sigma, const std::vector<double>& weight,
                         Eigen::Vector3d* n, double* d) {
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        double wsum = 0.0;
        for (size_t j = 0; j < seg.size(); ++j) {
            const double w = weight[j] / (sigma[j] * sigma[j]);
            mean += w * f.q[seg[j]];
            wsum += w;
        }
        mean /= wsum;
        Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
        for (size_t j = 0; j < seg.size(); ++j) {
            const double w = weight[j] / (sigma[j] * sigma[j]);
            const Eigen::Vector3d e = f.q[seg[j]] - mean;
            cov.noalias() += w * e * e.transpose();
        }
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
        *n = es.eigenvectors().col(0);
        if (n->dot(mean) > 0.0) *n = -*n;
        *d = n->dot(mean);
    }

    const PlanarDistortionConfig& config_;
    int columns_, rows_;
};

}  // namespace

namespace {

constexpr int kCurvedTerms = PlanarDistortion::kCurvedTerms;

std::array<double, kCurvedTerms> monomials(double u, double v) {
    constexpr int kDegree = PlanarDistortion::kDegree;
    std::array<double, kDegree + 1> pu{}, pv{};  // u^i, v^i
    pu[0] = pv[0] = 1.0;
    for (int i = 1; i <= kDegree; ++i) {
        pu[static_cast<size_t>(i)] = pu[static_cast<size_t>(i - 1)] * u;
        pv[static_cast<size_t>(i)] = pv[static_cast<size_t>(i - 1)] * v;
    }
    std::array<double, kCurvedTerms> m{};
    size_t k = 0;
    for (int degree = 2; degree <= kDegree; ++degree) {
        for (int i = degree; i >= 0; --i) {
            m[k++] = pu[static_cast<size_t>(i)] * pv[static_cast<size_t>(degree - i)];
        }
    }
    return m;
}

/// Per monomial, its least-squares affine part a + b u + c v over the table's cell centres.
std::array<Eigen::Vector3d, kCurvedTerms> affineParts() {
    constexpr int n = DistortionTable::kCellsPerSide;
    Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
    Eigen::Matrix<double, 3, kCurvedTerms> atb = Eigen::Matrix<double, 3, kCurvedTerms>::Zero();
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) {
            const double u = (x + 0.5) / (n / 2.0) - 1.0, v = (y + 0.5) / (n / 2.0) - 1.0;
            const Eigen::Vector3d a(1.0, u, v);
            ata += a * a.transpose();
            const std::array<double, kCurvedTerms> m = monomials(u, v);
            for (int k = 0; k < kCurvedTerms; ++k) atb.col(k) += a * m[static_cast<size_t>(k)];
        }
    }
    std::array<Eigen::Vector3d, kCurvedTerms> out;
    for (int k = 0; k < kCurvedTerms; ++k) {
        out[static_cast<size_t>(k)] = ata.ldlt().solve(atb.col(k));
    }
    return out;
}

/// Eq. 3's gauge: removes from the affine coefficients of the estimated bins their
/// least-squares fit by a + b z (the constant term) and c z, d z (the u and v terms) over the
/// bins' centres z.
void removeDisparityAffine(const std::vector<int>& estimated, PlanarDistortion* model) {
    if (estimated.empty()) return;
    Eigen::MatrixXd a(static_cast<Eigen::Index>(estimated.size()), 2);
    Eigen::VectorXd z(static_cast<Eigen::Index>(estimated.size()));
    for (size_t e = 0; e < estimated.size(); ++e) {
        z[static_cast<Eigen::Index>(e)] = DistortionTable::binCentreM(estimated[e]);
        a.row(static_cast<Eigen::Index>(e)) << 1.0, z[static_cast<Eigen::Index>(e)];
    }
    auto coefficients = [&](int k) {
        Eigen::VectorXd y(static_cast<Eigen::Index>(estimated.size()));
        for (size_t e = 0; e < estimated.size(); ++e) {
            y[static_cast<Eigen::Index>(e)] =
                model->c[static_cast<size_t>(estimated[e])][static_cast<size_t>(k)];
        }
        return y;
    };
    auto subtract = [&](int k, const Eigen::VectorXd& fit) {
        for (size_t e = 0; e < estimated.size(); ++e) {
            model->c[static_cast<size_t>(estimated[e])][static_cast<size_t>(k)] -=
                fit[static_cast<Eigen::Index>(e)];
        }
    };
    const Eigen::VectorXd constant = coefficients(kCurvedTerms);
    const Eigen::Matrix2d ata = a.transpose() * a + 1e-12 * Eigen::Matrix2d::Identity();
    subtract(kCurvedTerms, a * ata.ldlt().solve(a.transpose() * constant));
    for (int k = kCurvedTerms + 1; k < kTerms; ++k) {
        const Eigen::VectorXd y = coefficients(k);
        subtract(k, z * (z.dot(y) / z.squaredNorm()));
    }
}

/// The bins not estimated copy the nearest estimated one (flat in depth beyond the data).
void copyToUnestimatedBins(const std::vector<int>& estimated, PlanarDistortion* model) {
    for (int b = 0; b < kBins; ++b) {
        if (std::find(estimated.begin(), estimated.end(), b) != estimated.end()) continue;
        int nearest = estimated.front();
        for (int e : estimated) {
            if (std::abs(e - b) < std::abs(nearest - b)) nearest = e;
        }
        model->c[static_cast<size_t>(b)] = model->c[static_cast<size_t>(nearest)];
    }
}

/// The depth-proportional scale b of the least-squares fit f - 1 = a + z (b + c u + d v) of the
/// model's factors at the estimated bins' centres z over the cells with data (Eq. 3), removed
/// as (z - z_first) b from each estimated bin's constant term. Returns b; 0 when fewer than two
/// bins were estimated or too few cells have data.
double removeDepthScaleOverData(const std::vector<int>& estimated, const std::vector<bool>& data,
                                PlanarDistortion* model) {
    constexpr int n = DistortionTable::kCellsPerSide;
    if (estimated.size() < 2) return 0.0;
    Eigen::Matrix4d ata = Eigen::Matrix4d::Zero();
    Eigen::Vector4d atb = Eigen::Vector4d::Zero();
    size_t rows = 0;
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) {
            if (!data[static_cast<size_t>(y) * n + x]) continue;
            const double u = (x + 0.5) / (n / 2.0) - 1.0, v = (y + 0.5) / (n / 2.0) - 1.0;
            for (int e : estimated) {
                const double z = DistortionTable::binCentreM(e);
                const Eigen::Vector4d a(1.0, z, z * u, z * v);
                ata += a * a.transpose();
                atb += a * (model->factor(u, v, z) - 1.0);
                ++rows;
            }
        }
    }
    if (rows < 8 * estimated.size()) return 0.0;
    const double b = ata.ldlt().solve(atb)[1];
    const double z_first = DistortionTable::binCentreM(estimated.front());
    for (int e : estimated) {
        model->c[static_cast<size_t>(e)][kCurvedTerms] -=
            (DistortionTable::binCentreM(e) - z_first) * b;
    }
    copyToUnestimatedBins(estimated, model);
    return b;
}

std::vector<int> binsOf(unsigned mask) {
    std::vector<int> bins;
    for (int b = 0; b < kBins; ++b) {
        if ((mask >> b) & 1U) bins.push_back(b);
    }
    return bins;
}

}  // namespace

std::array<double, PlanarDistortion::kTerms> PlanarDistortion::terms(double u, double v) {
    static const std::array<Eigen::Vector3d, kCurvedTerms> affine = affineParts();
    const std::array<double, kCurvedTerms> m = monomials(u, v);
    std::array<double, kTerms> t{};
    for (size_t k = 0; k < m.size(); ++k) t[k] = m[k] - affine[k].dot(Eigen::Vector3d(1.0, u, v));
    t[kCurvedTerms] = 1.0;
    t[kCurvedTerms + 1] = u;
    t[kCurvedTerms + 2] = v;
    return t;
}

double PlanarDistortion::factor(double u, double v, double z) const {
    const std::array<double, kTerms> phi = terms(u, v);
    const DistortionTable::BinWeights bw = DistortionTable::binWeights(z);
    double lo = 0.0, hi = 0.0;
    for (int k = 0; k < kTerms; ++k) {
        lo += c[static_cast<size_t>(bw.lo)][static_cast<size_t>(k)] * phi[static_cast<size_t>(k)];
        hi += c[static_cast<size_t>(bw.hi)][static_cast<size_t>(k)] * phi[static_cast<size_t>(k)];
    }
    return 1.0 + (1.0 - bw.a) * lo + bw.a * hi;
}

DistortionTable PlanarDistortion::toTable() const {
    constexpr int n = DistortionTable::kCellsPerSide;
    std::vector<std::array<float, 5>> cells(static_cast<size_t>(n) * n);
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) {
            const double u = (x + 0.5) / (n / 2.0) - 1.0, v = (y + 0.5) / (n / 2.0) - 1.0;
            for (int b = 0; b < kBins; ++b) {
                cells[static_cast<size_t>(y) * n + x][static_cast<size_t>(b)] =
                    static_cast<float>(factor(u, v, DistortionTable::binCentreM(b)));
            }
        }
    }
    return DistortionTable::fromCells(std::move(cells));
}

void describe(config::Schema& s, PlanarDistortionConfig& c) {
    s.field("grid_columns", c.grid_columns,
            "blocks per frame along x (fewer when a block would be narrower than 4 pixels)")
        .min(8);
    s.field("grid_rows", c.grid_rows,
            "blocks per frame along y (fewer when a block would be lower than 4 pixels)")
        .min(8);
    s.field("min_block_valid", c.min_block_valid,
            "a block is used when at least this share of its pixels hold depth")
        .range(0.0, 1.0);
    s.field("max_block_spread", c.max_block_spread,
            "... and their depths spread by at most this fraction of their mean")
        .positive();
    s.field("min_depth_m", c.min_depth_m, "blocks nearer than this are not used", "m").min(0.0);
    s.field("max_depth_m", c.max_depth_m, "blocks further than this are not used", "m").positive();
    s.field("at_block_origin", c.at_block_origin,
            "each raw depth belongs to the origin of its 2x2 disparity block");
    s.field("normal_stencil", c.normal_stencil, "normals from the blocks this far on either side")
        .min(1);
    s.field("max_neighbour_angle_deg", c.max_neighbour_angle_deg,
            "neighbouring blocks join a segment when their normals differ by at most this", "deg")
        .positive();
    s.field("max_depth_step", c.max_depth_step,
            "... and their depths by at most this fraction of the depth")
        .positive();
    s.field("max_segment_spread_deg", c.max_segment_spread_deg,
            "... and the block's normal is within this of the segment's", "deg")
        .positive();
    s.field("min_segment_blocks", c.min_segment_blocks, "segments with fewer blocks are not used")
        .min(3);
    s.field("max_segment_rms_sigmas", c.max_segment_rms_sigmas,
            "segments fitting worse than this many depth-noise sigmas are not planes")
        .positive();
    s.field("noise_per_m2", c.noise_per_m2, "depth noise of one pixel: sigma = this * z^2", "1/m")
        .positive();
    s.field("huber_sigmas", c.huber_sigmas, "Huber threshold in robust sigmas").positive();
    s.field("iterations", c.iterations, "Gauss-Newton iterations").min(1);
    s.field("change_tolerance", c.change_tolerance,
            "stops when the largest coefficient change is below this")
        .min(0.0);
    s.field("bin_smoothness", c.bin_smoothness,
            "weight of the penalty holding each bin's coefficients to their neighbours' in depth")
        .min(0.0);
    s.field("min_bin_share", c.min_bin_share,
            "a depth bin is estimated when its share of the blocks' interpolation weight is at "
            "least this; the others copy the nearest estimated bin")
        .range(0.0, 1.0);
    s.field("damping", c.damping,
            "ridge added to the normal equations, relative to their largest diagonal entry")
        .min(0.0);
    s.field("max_split_disagreement", c.max_split_disagreement,
            "the two halves of the scan fitted apart may differ by at most this (median over the "
            "image beyond a projective part, 1 and 3 m); else the bend is not determined (0: no "
            "check)")
        .min(0.0);
    s.field("estimate_affine", c.estimate_affine,
            "also estimate each bin's affine terms, less the part that keeps planes planes (a + z "
            "(b + c u + d v)); off: they stay neutral");
    s.field("scale_gauge_over_data", c.scale_gauge_over_data,
            "set the model's scale growing with depth (b of a + z (b + c u + d v)) to 0 over the "
            "cells with data instead of over the whole image");
    s.field("min_cell_valid", c.min_cell_valid,
            "a table cell has data when at least this share of its pixels over the frames hold "
            "depth")
        .range(0.0, 1.0);
    s.field("frame_step", c.frame_step, "every frame_step-th frame is used").min(1);
    s.field("num_threads", c.num_threads, "worker threads (0 = TBB default)").min(0);
}

Status validate(const PlanarDistortionConfig& c) {
    auto bad = [](const char* what) {
        return invalidArgument(fmt::format("planar distortion config: {}", what));
    };
    if (c.grid_columns < 8 || c.grid_rows < 8) return bad("the grid needs at least 8 x 8 blocks");
    if (!(c.min_depth_m >= 0.0 && c.max_depth_m > c.min_depth_m)) {
        return bad("need 0 <= min_depth_m < max_depth_m");
    }
    if (!(c.min_block_valid >= 0.0 && c.min_block_valid <= 1.0)) {
        return bad("min_block_valid not in [0, 1]");
    }
    if (!(c.max_block_spread > 0.0 && c.max_depth_step > 0.0)) {
        return bad("max_block_spread and max_depth_step must be positive");
    }
    if (c.normal_stencil < 1 || 2 * c.normal_stencil >= std::min(c.grid_columns, c.grid_rows)) {
        return bad("normal_stencil must be at least 1 and fit the grid");
    }
    if (!(c.max_neighbour_angle_deg > 0.0 && c.max_segment_spread_deg > 0.0)) {
        return bad("the segment angles must be positive");
    }
    if (c.min_segment_blocks < 3) return bad("min_segment_blocks must be at least 3");
    if (!(c.max_segment_rms_sigmas > 0.0 && c.noise_per_m2 > 0.0 && c.huber_sigmas > 0.0)) {
        return bad("max_segment_rms_sigmas, noise_per_m2 and huber_sigmas must be positive");
    }
    if (c.iterations < 1) return bad("iterations must be at least 1");
    if (!(c.change_tolerance >= 0.0 && c.bin_smoothness >= 0.0)) {
        return bad("change_tolerance and bin_smoothness must not be negative");
    }
    if (!(c.min_bin_share >= 0.0 && c.min_bin_share <= 1.0)) {
        return bad("min_bin_share not in [0, 1]");
    }
    if (!(c.damping >= 0.0 && c.max_split_disagreement >= 0.0)) {
        return bad("damping and max_split_disagreement must not be negative");
    }
    if (!(c.min_cell_valid >= 0.0 && c.min_cell_valid <= 1.0)) {
        return bad("min_cell_valid not in [0, 1]");
    }
    if (c.frame_step < 1) return bad("frame_step must be at least 1");
    if (c.num_threads < 0) return bad("num_threads must not be negative");
    return Status::ok();
}

PlanarDistortionEstimator::PlanarDistortionEstimator(const PinholeCamera& camera,
                                                     const PlanarDistortionConfig& config)
    : camera_(camera),
      config_(config),
      columns_(std::max(1, std::min(config.grid_columns, camera.width / 4))),
      rows_(std::max(1, std::min(config.grid_rows, camera.height / 4))) {
    constexpr int n = DistortionTable::kCellsPerSide;
    cell_column_.resize(static_cast<size_t>(std::max(0, camera_.width)));
    cell_row_start_.resize(static_cast<size_t>(std::max(0, camera_.height)));
    for (size_t x = 0; x < cell_column_.size(); ++x) {
        cell_column_[x] = std::min<size_t>(n - 1, x * n / cell_column_.size());
    }
    for (size_t y = 0; y < cell_row_start_.size(); ++y) {
        cell_row_start_[y] = std::min<size_t>(n - 1, y * n / cell_row_start_.size()) * n;
    }
    cell_pixels_.assign(static_cast<size_t>(n) * n, 0);
    cell_valid_.assign(static_cast<size_t>(n) * n, 0);
    for (int y = 0; y < camera_.height; ++y) {
        for (int x = 0; x < camera_.width; ++x) ++cell_pixels_[cellOf(x, y)];
    }
}

std::vector<bool> PlanarDistortionEstimator::cellsWithData() const {
    std::vector<bool> data(cell_valid_.size(), false);
    for (size_t i = 0; i < data.size(); ++i) {
        const double pixels = static_cast<double>(cell_pixels_[i]) * frames_.size();
        data[i] = pixels > 0.0 && cell_valid_[i] > 0 &&
                  static_cast<double>(cell_valid_[i]) >= config_.min_cell_valid * pixels;
    }
    return data;
}

Status PlanarDistortionEstimator::addFrame(const DepthImage& raw) {
    if (raw.width() != camera_.width || raw.height() != camera_.height) {
        return invalidArgument(fmt::format("planar distortion: a {}x{} frame from a {}x{} camera",
                                           raw.width(), raw.height(), camera_.width,
                                           camera_.height));
    }
    if (added_++ % static_cast<size_t>(config_.frame_step) != 0) return Status::ok();
    const int columns = columns_, rows = rows_;
    std::vector<Block> blocks(static_cast<size_t>(columns) * rows, Block{0, 0, 0, 0, 0});
    const double sx = 640.0 / camera_.width, sy = 480.0 / camera_.height;
    for (int gy = 0; gy < rows; ++gy) {
        const int y0 = gy * camera_.height / rows, y1 = (gy + 1) * camera_.height / rows;
        for (int gx = 0; gx < columns; ++gx) {
            const int x0 = gx * camera_.width / columns, x1 = (gx + 1) * camera_.width / columns;
            Eigen::Vector3d p = Eigen::Vector3d::Zero();
            double u = 0.0, v = 0.0, zmin = 1e9, zmax = 0.0;
            int valid = 0;
            for (int y = y0; y < y1; ++y) {
                for (int x = x0; x < x1; ++x) {
                    const float z = raw(x, y);
                    if (!(z > 0.0F) || !std::isfinite(z)) continue;
                    ++cell_valid_[cellOf(x, y)];
                    const int xo = config_.at_block_origin ? x - x % 2 : x;
                    const int yo = config_.at_block_origin ? y - y % 2 : y;
                    p += camera_.unproject(xo, yo, z);
                    u += (xo * sx - 320.0) / 320.0;
                    v += (yo * sy - 240.0) / 240.0;
                    zmin = std::min(zmin, static_cast<double>(z));
                    zmax = std::max(zmax, static_cast<double>(z));
                    ++valid;
                }
            }
            const int pixels = (x1 - x0) * (y1 - y0);
            if (valid == 0 || valid < config_.min_block_valid * pixels) continue;
            p /= valid;
            if (p.z() < config_.min_depth_m || p.z() > config_.max_depth_m) continue;
            if (zmax - zmin > config_.max_block_spread * p.z()) continue;
            blocks[static_cast<size_t>(gy) * columns + gx] = Block{
                static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()),
                static_cast<float>(u / valid), static_cast<float>(v / valid)};
        }
    }
    frames_.push_back(std::move(blocks));
    return Status::ok();
}

Result<PlanarEstimate> PlanarDistortionEstimator::estimate(const Observer& observer) const {
    Result<PlanarEstimate> all = fit(0, frames_.size(), observer);
    if (!all.isOk()) return all;
    if (Status s = checkHalves(&*all); !s.isOk()) return s;
    if (config_.scale_gauge_over_data) {
        const std::vector<bool> data = cellsWithData();
        all->cells_with_data = static_cast<size_t>(std::count(data.begin(), data.end(), true));
        all->removed_depth_scale_per_m =
            removeDepthScaleOverData(binsOf(all->estimated_bins), data, &all->model);
    }
    return all;
}

Status PlanarDistortionEstimator::checkHalves(PlanarEstimate* all) const {
    if (config_.max_split_disagreement <= 0.0) return Status::ok();
    // The two halves of the scan, fitted apart, must agree: a scan whose planes do not
    // determine the bend (a few views of one corner, curved surfaces seen from one side) gives
    // halves that differ by far more than their noise.
    const size_t half = frames_.size() / 2;
    Result<PlanarEstimate> first = fit(0, half, {});
    Result<PlanarEstimate> second = fit(half, frames_.size(), {});
    if (!first.isOk() || !second.isOk()) {
        return failedPrecondition(fmt::format(
            "planar distortion: a half of the scan holds no planar segment ({} frames); scan "
            "more of the room",
            frames_.size()));
    }
    DistortionEstimate everywhere;
    everywhere.covered.assign(
        static_cast<size_t>(DistortionTable::kCellsPerSide) * DistortionTable::kCellsPerSide, 0b11);
    Result<TableComparison> c =
        compareTables(first->model.toTable(), everywhere, second->model.toTable());
    if (!c.isOk()) return c.status();
    all->split_disagreement = std::max(c->bins[0].median_error_beyond_projective,
                                       c->bins[1].median_error_beyond_projective);
    if (all->split_disagreement > config_.max_split_disagreement) {
        return failedPrecondition(fmt::format(
            "planar distortion: the scan's planes do not determine the bend: its two halves "
            "disagree by {:.2f} % (at most {:.2f} %); scan more of the room, turning the camera "
            "so that walls and floor cross the whole image",
            100.0 * all->split_disagreement, 100.0 * config_.max_split_disagreement));
    }
    return Status::ok();
}

std::vector<std::vector<SegmentPlane>> PlanarDistortionEstimator::framePlanes(
    const PlanarDistortion& model) const {
    std::vector<std::vector<SegmentPlane>> out(frames_.size());
    const Fitter fitter(config_, columns_, rows_);
    plumb::parallelFor(config_.num_threads, static_cast<int>(frames_.size()), [&](int k) {
        const CorrectedFrame f = fitter.correct(frames_[static_cast<size_t>(k)], model);
        for (const std::vector<size_t>& seg : fitter.segment(f)) {
            const auto fit = fitter.fitSegment(f, seg);
            if (!fit.ok) continue;
            const double rms = std::sqrt(fit.cost / fit.wsum);
            if (rms > config_.max_segment_rms_sigmas) continue;
            SegmentPlane plane;
            plane.normal = fit.n;
            plane.distance = fit.d;
            for (size_t i : seg) plane.mean_depth += f.q[i].z();
            plane.mean_depth /= static_cast<double>(seg.size());
            plane.blocks = seg.size();
            plane.rms_sigmas = rms;
            out[static_cast<size_t>(k)].push_back(plane);
        }
    });
    return out;
}

Result<PlanarEstimate> PlanarDistortionEstimator::fit(size_t begin, size_t end,
                                                      const Observer& observer) const {
    PlanarEstimate out;
    out.frames = end - begin;
    const Fitter fitter(config_, columns_, rows_);
    for (int it = 0; it < config_.iterations; ++it) {
        std::vector<FrameSystem> systems(end - begin);
        plumb::parallelFor(config_.num_threads, static_cast<int>(end - begin), [&](int k) {
            const std::vector<Block>& blocks = frames_[begin + static_cast<size_t>(k)];
            const CorrectedFrame f = fitter.correct(blocks, out.model);
            fitter.accumulate(blocks, f, fitter.segment(f), it > 0,
                              &systems[static_cast<size_t>(k)]);
        });
        FrameSystem total;
        for (const FrameSystem& s : systems) {  // in frame order: thread-count independent
            total.h += s.h;
            total.g += s.g;
            total.bin_weight += s.bin_weight;
            total.cost += s.cost;
            total.weight += s.weight;
            total.segments += s.segments;
            total.blocks += s.blocks;
        }
        if (total.segments == 0) {
            return failedPrecondition(
                "planar distortion: no frame holds a planar segment in the depth range");
        }
        ParamMatrix h = total.h.selfadjointView<Eigen::Lower>();
        ParamVector g = total.g;
        // Bins with little data are not unknowns: they copy the nearest bin that has (flat in
        // depth beyond the data); the estimated bins are held to the linear extrapolation of
        // their neighbours by bin_smoothness.
        const double min_bin_weight = config_.min_bin_share * total.bin_weight.sum();
        std::vector<int> estimated;
        out.estimated_bins = 0;
        for (int b = 0; b < kBins; ++b) {
            if (total.bin_weight[b] >= min_bin_weight) {
                estimated.push_back(b);
                out.estimated_bins |= 1U << b;
            }
        }
        const int terms = config_.estimate_affine ? kTerms : kCurvedTerms;
        double max_diagonal = 0.0;
        for (int b = 0; b < kBins; ++b) {
            for (int k = 0; k < terms; ++k) {
                max_diagonal = std::max(max_diagonal, h(b * kTerms + k, b * kTerms + k));
            }
        }
        const double lambda = config_.bin_smoothness * max_diagonal / std::max(1.0, total.weight);
        for (size_t e = 1; e + 1 < estimated.size(); ++e) {
            for (int k = 0; k < kTerms; ++k) {
                const int i0 = estimated[e - 1] * kTerms + k, i1 = estimated[e] * kTerms + k,
                          i2 = estimated[e + 1] * kTerms + k;
                const std::array<int, 3> idx{i0, i1, i2};
                const std::array<double, 3> coef{1.0, -2.0, 1.0};
                double r = 0.0;
                for (int a = 0; a < 3; ++a) r += coef[a] * out.model.c[idx[a] / kTerms][k];
                for (int a = 0; a < 3; ++a) {
                    g[idx[a]] += lambda * coef[a] * r;
                    for (int c = 0; c < 3; ++c) h(idx[a], idx[c]) += lambda * coef[a] * coef[c];
                }
            }
        }
        std::vector<int> param_index;
        for (int b : estimated) {
            for (int k = 0; k < terms; ++k) param_index.push_back(b * kTerms + k);
        }
        const int m = static_cast<int>(param_index.size());
        Eigen::MatrixXd hr(m, m);
        Eigen::VectorXd gr(m);
        for (int a = 0; a < m; ++a) {
            gr[a] = g[param_index[a]];
            for (int c = 0; c < m; ++c) hr(a, c) = h(param_index[a], param_index[c]);
        }
        hr.diagonal().array() += config_.damping * hr.diagonal().maxCoeff() + 1e-12;
        const Eigen::VectorXd step = -hr.ldlt().solve(gr);
        PlanarIteration rec;
        rec.iteration = it;
        rec.segments = total.segments;
        rec.blocks = total.blocks;
        rec.rms_sigmas = std::sqrt(total.cost / std::max(total.weight, 1.0));
        for (int a = 0; a < m; ++a) {
            out.model.c[param_index[a] / kTerms][param_index[a] % kTerms] += step[a];
            rec.max_change = std::max(rec.max_change, std::abs(step[a]));
        }
        if (config_.estimate_affine) removeDisparityAffine(estimated, &out.model);
        copyToUnestimatedBins(estimated, &out.model);
        out.iterations.push_back(rec);
        if (observer) observer(rec);
        if (rec.max_change < config_.change_tolerance) break;
    }
    return out;
}

}  // namespace plumb::calibration
