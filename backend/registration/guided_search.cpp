// SPDX-License-Identifier: Apache-2.0
#include "backend/registration/guided_search.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <numbers>
#include <utility>
#include <vector>

namespace plumb::registration {

void describe(config::Schema& s, GuidedSearchConfig& c) {
    s.field("enabled", c.enabled,
            "also search loops between fragments of one tracking segment by translation voting "
            "under the odometry's rotation (FPFH is ambiguous in bare rooms)");
    s.field("radius_m", c.radius_m, "largest translation drift searched (per axis)", "m")
        .positive();
    s.field("drift_per_fragment_m", c.drift_per_fragment_m,
            "expected odometry drift from one fragment to the next; the odometry prior's deviation "
            "is this x sqrt(fragments apart)",
            "m")
        .positive();
    s.field("max_offset_sigmas", c.max_offset_sigmas,
            "loops of one segment that move further than this many prior deviations from the "
            "odometry are rejected (0 = no check)")
        .min(0.0);
    s.field("max_rotation_deg", c.max_rotation_deg,
            "guided alignments that ICP turns further than this from the odometry are dropped",
            "deg")
        .range(0.0, 180.0);
    s.field("bin_m", c.bin_m, "edge of a translation vote bin", "m").positive();
    s.field("max_normal_angle_deg", c.max_normal_angle_deg,
            "point pairs vote only when their normals agree within this", "deg")
        .range(0.0, 90.0);
    s.field("max_peaks", c.max_peaks, "at most this many vote peaks are refined and verified")
        .min(1);
}

namespace {

/// Integer cell coordinates packed into one key (21 bits each, offset to be non-negative).
int64_t cellKey(const Eigen::Vector3i& c) {
    constexpr int64_t kOffset = 1 << 20;
    return ((c.x() + kOffset) << 42) | ((c.y() + kOffset) << 21) | (c.z() + kOffset);
}

Eigen::Vector3i cellOf(const Eigen::Vector3f& p, float inv_cell) {
    return (p * inv_cell).array().floor().cast<int>();
}

/// Four float or int lanes (GCC vector extensions: SSE2 on x86-64, NEON on aarch64).
using Float4 = float __attribute__((vector_size(16)));
using Int4 = int32_t __attribute__((vector_size(16)));

/// std::round (half away from zero) lane by lane, for |x| < 2^23: x - trunc(x) is exact there.
Int4 roundHalfAway(Float4 x) {
    const Int4 t = __builtin_convertvector(x, Int4);  // truncates towards zero
    const Float4 frac = x - __builtin_convertvector(t, Float4);
    return t - (frac >= 0.5f) + (frac <= -0.5f);  // a true lane is -1
}

/// The source points of a vote, positions and normals coordinate by coordinate (padded by three
/// lanes), so that four candidates go through the normal and window tests together.
class SortedPoints {
  public:
    explicit SortedPoints(size_t n) {
        for (auto* a : {&px_, &py_, &pz_, &nx_, &ny_, &nz_}) a->assign(n + 3, 0.0f);
    }
    void set(size_t k, const Eigen::Vector3f& p, const Eigen::Vector3f& n) {
        px_[k] = p.x(), py_[k] = p.y(), pz_[k] = p.z();
        nx_[k] = n.x(), ny_[k] = n.y(), nz_[k] = n.z();
    }
    /// Calls vote(b) with the bin offset b = round((p_k - q) * inv_bin) of every point k in
    /// [begin, end) whose normal agrees with nq (n_k . nq >= cos_max, the dot product summed as
    /// Eigen's Vector3f::dot sums it) and whose offset lies within h bins on every axis: the
    /// scalar test's float operations in lanes, so the same votes.
    template <typename Vote>
    void vote(size_t begin, size_t end, const Eigen::Vector3f& q, const Eigen::Vector3f& nq,
              float cos_max, float inv_bin, int h, Vote&& vote) const {
        const Int4 lane = {0, 1, 2, 3};
        for (size_t k = begin; k < end; k += 4) {
            const Float4 nx = load(nx_, k), ny = load(ny_, k), nz = load(nz_, k);
            const Float4 dot = nx * nq.x() + (ny * nq.y() + nz * nq.z());
            Int4 pass = (lane < static_cast<int32_t>(end - k)) & ~(dot < cos_max);
            if (!any(pass)) continue;
            const Int4 bx = roundHalfAway((load(px_, k) - q.x()) * inv_bin);
            const Int4 by = roundHalfAway((load(py_, k) - q.y()) * inv_bin);
            const Int4 bz = roundHalfAway((load(pz_, k) - q.z()) * inv_bin);
            pass &= (bx <= h) & (bx >= -h) & (by <= h) & (by >= -h) & (bz <= h) & (bz >= -h);
            for (int l = 0; l < 4; ++l)
                if (pass[l] != 0) vote(bx[l], by[l], bz[l]);
        }
    }

  private:
    static Float4 load(const std::vector<float>& a, size_t k) {
        Float4 v;
        std::memcpy(&v, a.data() + k, sizeof(v));
        return v;
    }
    static bool any(Int4 m) { return (m[0] | m[1] | m[2] | m[3]) != 0; }

    std::vector<float> px_, py_, pz_, nx_, ny_, nz_;
};

}  // namespace

double odometryPriorSigma(const GuidedSearchConfig& config, uint32_t apart) {
    return config.drift_per_fragment_m * std::sqrt(static_cast<double>(std::max(apart, 1u)));
}

std::vector<GuidedCandidate> guidedCandidates(const FragmentIndex& source,
                                              const FragmentIndex& target,
                                              const Eigen::Isometry3d& T_odo, double prior_sigma_m,
                                              const GuidedSearchConfig& config) {
    const PointCloud& src = source.coarse.cloud();
    const PointCloud& tgt = target.coarse.cloud();
    if (src.empty() || tgt.empty() || !src.hasNormals() || !tgt.hasNormals()) return {};
    if (!(config.radius_m > 0.0) || !(config.bin_m > 0.0) || config.max_peaks < 1) return {};

    // Source points sorted by cell of edge radius, positions and normals copied in that order: a
    // target point's partners within the search box lie in the 27 cells around it, and the three
    // cells along z of each (x, y) column are one contiguous run of keys.
    const float radius = static_cast<float>(config.radius_m);
    const float inv_cell = 1.0f / radius;
    std::vector<std::pair<int64_t, uint32_t>> cells(src.size());
    for (size_t i = 0; i < src.size(); ++i) {
        cells[i] = {cellKey(cellOf(src.points[i], inv_cell)), static_cast<uint32_t>(i)};
    }
    std::sort(cells.begin(), cells.end());
    std::vector<int64_t> keys(cells.size());
    SortedPoints sorted(cells.size());
    for (size_t k = 0; k < cells.size(); ++k) {
        keys[k] = cells[k].first;
        sorted.set(k, src.points[cells[k].second], src.normals[cells[k].second]);
    }

    // Vote grid over offsets d in [-h, h]^3 bins (at most 201 per axis: a wider window gets
    // coarser bins rather than gigabytes of votes).
    constexpr double kMaxHalfBins = 100.0;
    const double bin = std::max(config.bin_m, config.radius_m / kMaxHalfBins);
    const int h = static_cast<int>(std::ceil(config.radius_m / bin));
    const int m = 2 * h + 1;
    auto at = [m](int x, int y, int z) {
        return (static_cast<size_t>(z) * static_cast<size_t>(m) + static_cast<size_t>(y)) *
                   static_cast<size_t>(m) +
               static_cast<size_t>(x);
    };
    // Every vote adds 1: the counts are exact whatever the order the pairs are visited in.
    std::vector<float> votes(static_cast<size_t>(m) * m * m, 0.0f);
    const float cos_max =
        static_cast<float>(std::cos(config.max_normal_angle_deg * std::numbers::pi / 180.0));
    const Eigen::Matrix3f R = T_odo.rotation().cast<float>();
    const Eigen::Vector3f t = T_odo.translation().cast<float>();
    const float inv_bin = static_cast<float>(1.0 / bin);
    for (size_t j = 0; j < tgt.size(); ++j) {
        const Eigen::Vector3f q = R * tgt.points[j] + t;
        const Eigen::Vector3f nq = R * tgt.normals[j];
        const Eigen::Vector3i c = cellOf(q, inv_cell);
        for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
                const int64_t first = cellKey(c + Eigen::Vector3i(dx, dy, -1));
                const int64_t last = cellKey(c + Eigen::Vector3i(dx, dy, 1));
                const auto begin = std::lower_bound(keys.begin(), keys.end(), first);
                const auto end = std::upper_bound(begin, keys.end(), last);
                sorted.vote(static_cast<size_t>(begin - keys.begin()),
                            static_cast<size_t>(end - keys.begin()), q, nq, cos_max, inv_bin, h,
                            [&](int x, int y, int z) { votes[at(x + h, y + h, z + h)] += 1.0f; });
            }
        }
    }

    // Box-smoothed votes (3x3x3): a peak split across neighbouring bins still counts whole.
    std::vector<float> smooth(votes.size(), 0.0f);
    for (int z = 0; z < m; ++z) {
        for (int y = 0; y < m; ++y) {
            for (int x = 0; x < m; ++x) {
                float s = 0.0f;
                for (int c = std::max(z - 1, 0); c <= std::min(z + 1, m - 1); ++c) {
                    for (int b = std::max(y - 1, 0); b <= std::min(y + 1, m - 1); ++b) {
                        for (int a = std::max(x - 1, 0); a <= std::min(x + 1, m - 1); ++a) {
                            s += votes[at(a, b, c)];
                        }
                    }
                }
                smooth[at(x, y, z)] = s;
            }
        }
    }

    // The odometry as a prior on the drift. Planes of only one or two directions vote for a ridge
    // of equal offsets; the prior picks its point nearest the odometry, while a real peak (three
    // plane directions, furniture) stands out regardless.
    // The offset (in bins) of grid index k.
    auto offset = [m, h](size_t k) {
        const int x = static_cast<int>(k % static_cast<size_t>(m)) - h;
        const int y = static_cast<int>((k / static_cast<size_t>(m)) % static_cast<size_t>(m)) - h;
        const int z = static_cast<int>(k / (static_cast<size_t>(m) * static_cast<size_t>(m))) - h;
        return Eigen::Vector3i(x, y, z);
    };
    const double sigma_bins = std::max(prior_sigma_m, bin) / bin;
    for (size_t k = 0; k < smooth.size(); ++k) {
        smooth[k] *= static_cast<float>(std::exp(
            -0.5 * static_cast<double>(offset(k).squaredNorm()) / (sigma_bins * sigma_bins)));
    }

    // Peaks, strongest first; equal scores go to the smaller offset (closer to the odometry).
    // A peak needs half the strongest's score: only those bins are ordered.
    std::vector<GuidedCandidate> out;
    const float best = *std::max_element(smooth.begin(), smooth.end());
    if (!(best > 0.0f)) return out;
    std::vector<size_t> order;
    for (size_t k = 0; k < smooth.size(); ++k)
        if (smooth[k] >= 0.5f * best) order.push_back(k);
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
        if (smooth[a] != smooth[b]) return smooth[a] > smooth[b];
        const int na = offset(a).squaredNorm(), nb = offset(b).squaredNorm();
        return na != nb ? na < nb : a < b;
    });
    std::vector<Eigen::Vector3i> taken;
    for (size_t k : order) {
        if (static_cast<int>(out.size()) >= config.max_peaks || smooth[k] < 0.5f * best) break;
        const Eigen::Vector3i o = offset(k);
        bool near = false;
        for (const Eigen::Vector3i& p : taken) near = near || (p - o).cwiseAbs().maxCoeff() < 3;
        if (near) continue;
        taken.push_back(o);
        // Sub-bin offset: the vote-weighted mean over the 3x3x3 neighbourhood.
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        double w = 0.0;
        for (int c = -1; c <= 1; ++c) {
            for (int b = -1; b <= 1; ++b) {
                for (int a = -1; a <= 1; ++a) {
                    const Eigen::Vector3i n = o + Eigen::Vector3i(a, b, c);
                    if (n.cwiseAbs().maxCoeff() > h) continue;
                    const double v = votes[at(n.x() + h, n.y() + h, n.z() + h)];
                    sum += v * n.cast<double>();
                    w += v;
                }
            }
        }
        const Eigen::Vector3d d =
            (w > 0.0 ? Eigen::Vector3d(sum / w) : Eigen::Vector3d(o.cast<double>())) * bin;
        GuidedCandidate g;
        g.T_source_target = Eigen::Translation3d(d) * T_odo;
        g.votes = smooth[k];
        out.push_back(g);
    }
    return out;
}

}  // namespace plumb::registration
