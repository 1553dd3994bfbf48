// SPDX-License-Identifier: Apache-2.0
#include "backend/calibration/self_calibration.hpp"

#include <emmintrin.h>
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <utility>

#include "common/calibration/depth_calibration.hpp"
#include "common/core/parallel.hpp"
#include "common/tsdf/tsdf_config.hpp"

namespace plumb::calibration {
namespace {

using Table = DistortionTable;
constexpr int kBins = Table::kBins;
constexpr int kSide = Table::kCellsPerSide;

/// Median of `v` (reordered); 0 when empty.
double medianOf(std::vector<double>* v) {
    if (v->empty()) return 0.0;
    const size_t mid = v->size() / 2;
    std::nth_element(v->begin(), v->begin() + static_cast<std::ptrdiff_t>(mid), v->end());
    double m = (*v)[mid];
    if (v->size() % 2 == 0) {
        m = 0.5 *
            (m + *std::max_element(v->begin(), v->begin() + static_cast<std::ptrdiff_t>(mid)));
    }
    return m;
}

/// The fit of one cell.
struct CellFit {
    std::array<double, kBins> factor{};
    uint8_t covered = 0;  ///< bit i: bin i covered by the cell's own samples
    size_t outliers = 0;
};

/// The depth segment of z: 0 below the first bin centre, s in 1..4 between centres s - 1 and
/// s, 5 beyond the last (binWeights(z): lo = max(s - 1, 0), hi = min(s, 4)).
int depthSegment(double z) { return std::min(static_cast<int>((z + 1.0) / 2.0), kBins); }

/// One robust pass's weighted sums over one depth segment's samples: with a the interpolation
/// weight on the segment's upper bin (0 where it has one bin), r the ratio and w the Huber
/// weight of the residual e = |r - (f_lo + a df)| (1 up to `huber`, huber / e up to `cutoff`,
/// 0 beyond: an outlier), the sums of w, w a, w a^2, w r and w a r, and over the inliers of 1,
/// a and a^2.
struct SegmentSums {
    double sw = 0, swa = 0, swaa = 0, swr = 0, swar = 0;
    double n0 = 0, n1 = 0, n2 = 0;
    size_t outliers = 0;
};

/// SegmentSums of `samples`, two at a time in the two lanes of SSE2 registers (sample k into
/// lane k % 2, the lanes added last): the same sums on every run.
template <typename SampleT>
SegmentSums sumSegment(const std::vector<SampleT>& samples, int segment, bool interpolated,
                       double f_lo, double df, double huber, double cutoff) {
    static_assert(sizeof(SampleT) == 2 * sizeof(float) && offsetof(SampleT, z_model) == 0 &&
                      offsetof(SampleT, ratio) == sizeof(float),
                  "sumSegment loads samples as (z_model, ratio) float pairs");
    // a = (z - (2 (segment - 1) + 1)) / 2 on an interpolated segment (weightOnHi), else 0.
    const __m128d a_offset = _mm_set1_pd(interpolated ? 2.0 * (segment - 1) + 1.0 : 0.0);
    const __m128d a_scale = _mm_set1_pd(interpolated ? 0.5 : 0.0);
    const __m128d v_f_lo = _mm_set1_pd(f_lo), v_df = _mm_set1_pd(df);
    const __m128d v_huber = _mm_set1_pd(huber), v_cutoff = _mm_set1_pd(cutoff);
    const __m128d one = _mm_set1_pd(1.0);
    const __m128d abs_mask = _mm_castsi128_pd(_mm_set1_epi64x(0x7fffffffffffffffLL));
    __m128d sw = _mm_setzero_pd(), swa = sw, swaa = sw, swr = sw, swar = sw, n0 = sw, n1 = sw,
            n2 = sw;
    auto add = [&](__m128d z, __m128d r) {
        const __m128d a = _mm_mul_pd(_mm_sub_pd(z, a_offset), a_scale);
        const __m128d e =
            _mm_and_pd(_mm_sub_pd(r, _mm_add_pd(v_f_lo, _mm_mul_pd(a, v_df))), abs_mask);
        const __m128d inlier = _mm_and_pd(_mm_cmple_pd(e, v_cutoff), one);
        // Huber: 1 up to huber (x / x = 1), huber / e beyond; 0 for outliers.
        const __m128d w = _mm_mul_pd(inlier, _mm_div_pd(v_huber, _mm_max_pd(e, v_huber)));
        const __m128d wa = _mm_mul_pd(w, a);
        const __m128d ia = _mm_mul_pd(inlier, a);
        sw = _mm_add_pd(sw, w);
        swa = _mm_add_pd(swa, wa);
        swaa = _mm_add_pd(swaa, _mm_mul_pd(wa, a));
        swr = _mm_add_pd(swr, _mm_mul_pd(w, r));
        swar = _mm_add_pd(swar, _mm_mul_pd(wa, r));
        n0 = _mm_add_pd(n0, inlier);
        n1 = _mm_add_pd(n1, ia);
        n2 = _mm_add_pd(n2, _mm_mul_pd(ia, a));
    };
    const size_t n = samples.size();
    const float* data = reinterpret_cast<const float*>(samples.data());
    size_t k = 0;
    for (; k + 2 <= n; k += 2) {
        const __m128 pair = _mm_loadu_ps(data + 2 * k);  // z0 r0 z1 r1
        add(_mm_cvtps_pd(_mm_shuffle_ps(pair, pair, _MM_SHUFFLE(2, 0, 2, 0))),
            _mm_cvtps_pd(_mm_shuffle_ps(pair, pair, _MM_SHUFFLE(3, 1, 3, 1))));
    }
    if (k < n) {
        // The last, odd sample in lane 0; lane 1 an outlier (a ratio of 1e30: weight 0, and
        // 0 * 1e30 adds exact zeros where an infinite ratio would add NaN).
        const __m128d z = _mm_set_pd(0.0, samples[k].z_model);
        const __m128d r = _mm_set_pd(1e30, samples[k].ratio);
        add(z, r);
    }
    auto total = [](__m128d v) { return _mm_cvtsd_f64(_mm_add_sd(v, _mm_unpackhi_pd(v, v))); };
    SegmentSums out;
    out.sw = total(sw);
    out.swa = total(swa);
    out.swaa = total(swaa);
    out.swr = total(swr);
    out.swar = total(swar);
    out.n0 = total(n0);
    out.n1 = total(n1);
    out.n2 = total(n2);
    out.outliers = n - static_cast<size_t>(out.n0);
    return out;
}

/// Robust least squares of Eq. (1) over one cell's samples (see the header), given per depth
/// segment (`segments[s]`, depthSegment): within a segment the two factors a sample depends on
/// are the same, so each pass reads the samples once and sums the normal equations per segment,
/// then folds them onto the unknowns (the covered bins; an uncovered bin counts as the nearest
/// covered one).
template <typename SampleT>
CellFit fitCell(const std::vector<SampleT>* segments, int num_segments,
                const SelfCalibrationConfig& c) {
    CellFit fit;
    fit.factor.fill(1.0);
    size_t n = 0;
    for (int s = 0; s < num_segments; ++s) n += segments[s].size();
    if (static_cast<double>(n) < c.min_samples) return fit;
    // Medians over every stride-th sample (SelfCalibrationConfig::median_samples), taken in
    // segment order.
    const size_t limit = c.median_samples > 0 ? static_cast<size_t>(c.median_samples) : n;
    const size_t stride = (n + limit - 1) / limit;
    std::vector<double> scratch;
    scratch.reserve((n + stride - 1) / stride);
    // Segment s: its bins and the interpolation weight a of depth z on bin hi.
    auto bins = [](int s) { return std::make_pair(std::max(s - 1, 0), std::min(s, kBins - 1)); };
    auto weightOnHi = [](int s, double z) { return (z - (2.0 * (s - 1) + 1.0)) / 2.0; };
    auto subsample = [&](const auto& value) {
        scratch.clear();
        size_t k = 0;
        for (int s = 0; s < num_segments; ++s) {
            const std::vector<SampleT>& seg = segments[s];
            for (; k < seg.size(); k += stride) scratch.push_back(value(s, seg[k]));
            k -= seg.size();
        }
    };

    // Initial estimate: the median ratio in every bin.
    subsample([](int, const SampleT& x) { return double{x.ratio}; });
    std::array<double, kBins> f;
    f.fill(medianOf(&scratch));

    uint8_t covered = 0;
    for (int pass = 0; pass <= c.robust_iterations; ++pass) {
        // Robust sigma from the median absolute residual at the current factors.
        subsample([&](int s, const SampleT& x) {
            const auto [lo, hi] = bins(s);
            const double a = lo == hi ? 0.0 : weightOnHi(s, x.z_model);
            return std::abs(x.ratio - ((1.0 - a) * f[static_cast<size_t>(lo)] +
                                       a * f[static_cast<size_t>(hi)]));
        });
        const double sigma = std::max(1.4826 * medianOf(&scratch), c.min_sigma);
        const double huber = c.huber_k * sigma;
        const double cutoff = c.outlier_sigmas * sigma;
        // Huber weights, each bin's support and the normal equations of Eq. (1), summed per
        // segment in powers of a: (1 - a)^2 = 1 - 2a + a^2, a (1 - a) = a - a^2.
        std::array<double, kBins> support{};
        Eigen::Matrix<double, kBins, kBins> A = Eigen::Matrix<double, kBins, kBins>::Zero();
        Eigen::Matrix<double, kBins, 1> b = Eigen::Matrix<double, kBins, 1>::Zero();
        size_t outliers = 0;
        for (int s = 0; s < num_segments; ++s) {
            const auto [lo, hi] = bins(s);
            const double f_lo = f[static_cast<size_t>(lo)];
            const double df = f[static_cast<size_t>(hi)] - f_lo;
            const bool interpolated = lo != hi;
            const SegmentSums m = sumSegment(segments[s], s, interpolated, f_lo, df, huber, cutoff);
            outliers += m.outliers;
            if (!interpolated) {
                support[static_cast<size_t>(lo)] += m.n0;
                A(lo, lo) += m.sw;
                b(lo) += m.swr;
                continue;
            }
            support[static_cast<size_t>(lo)] += m.n0 - 2.0 * m.n1 + m.n2;
            support[static_cast<size_t>(hi)] += m.n2;
            A(lo, lo) += m.sw - 2.0 * m.swa + m.swaa;
            A(hi, hi) += m.swaa;
            A(lo, hi) += m.swa - m.swaa;
            A(hi, lo) += m.swa - m.swaa;
            b(lo) += m.swr - m.swar;
            b(hi) += m.swar;
        }
        // Unknowns: the covered bins; an uncovered bin is tied to the nearest covered one.
        std::array<int, kBins> unknown_of{};
        std::array<int, kBins> covered_bins{};
        int num_unknowns = 0;
        covered = 0;
        for (int i = 0; i < kBins; ++i) {
            if (support[static_cast<size_t>(i)] >= c.min_samples) {
                covered |= static_cast<uint8_t>(1U << i);
                covered_bins[static_cast<size_t>(num_unknowns++)] = i;
            }
        }
        if (num_unknowns == 0) {
            fit.factor.fill(1.0);
            fit.covered = 0;
            return fit;
        }
        for (int i = 0; i < kBins; ++i) {
            int best = 0;
            for (int u = 1; u < num_unknowns; ++u) {
                if (std::abs(covered_bins[static_cast<size_t>(u)] - i) <
                    std::abs(covered_bins[static_cast<size_t>(best)] - i)) {
                    best = u;
                }
            }
            unknown_of[static_cast<size_t>(i)] = best;
        }
        // The bins' equations folded onto the unknowns, plus the smoothness penalty between
        // consecutive unknowns.
        Eigen::MatrixXd A_u = Eigen::MatrixXd::Zero(num_unknowns, num_unknowns);
        Eigen::VectorXd b_u = Eigen::VectorXd::Zero(num_unknowns);
        for (int i = 0; i < kBins; ++i) {
            const int p = unknown_of[static_cast<size_t>(i)];
            b_u(p) += b(i);
            for (int j = 0; j < kBins; ++j) A_u(p, unknown_of[static_cast<size_t>(j)]) += A(i, j);
        }
        for (int u = 0; u + 1 < num_unknowns; ++u) {
            A_u(u, u) += c.bin_smoothness;
            A_u(u + 1, u + 1) += c.bin_smoothness;
            A_u(u, u + 1) -= c.bin_smoothness;
            A_u(u + 1, u) -= c.bin_smoothness;
        }
        const Eigen::VectorXd x = A_u.ldlt().solve(b_u);
        for (int i = 0; i < kBins; ++i) {
            f[static_cast<size_t>(i)] = x(unknown_of[static_cast<size_t>(i)]);
        }
        fit.outliers = outliers;
    }
    fit.factor = f;
    fit.covered = covered;
    return fit;
}

/// The camera whose pixel (i, j) is pixel (2i, 2j) of `camera`: the origins of the 2x2 blocks.
PinholeCamera blockOriginCamera(const PinholeCamera& camera) {
    PinholeCamera half = camera;
    half.width = (camera.width + 1) / 2;
    half.height = (camera.height + 1) / 2;
    half.fx = camera.fx / 2.0;
    half.fy = camera.fy / 2.0;
    half.cx = camera.cx / 2.0;
    half.cy = camera.cy / 2.0;
    return half;
}

/// Pixels (2i, 2j) of `image`.
template <typename T>
Image<T> blockOrigins(const Image<T>& image) {
    Image<T> out((image.width() + 1) / 2, (image.height() + 1) / 2);
    for (int j = 0; j < out.height(); ++j) {
        for (int i = 0; i < out.width(); ++i) out(i, j) = image(2 * i, 2 * j);
    }
    return out;
}

}  // namespace

void describe(config::Schema& s, SelfCalibrationConfig& c) {
    s.field("min_depth_m", c.min_depth_m, "model depths below this are not compared", "m").min(0.0);
    s.field("max_depth_m", c.max_depth_m, "model depths above this are not compared", "m")
        .positive();
    s.field("min_view_cos", c.min_view_cos,
            "pixels whose model surface is seen at a smaller |cos| of the viewing angle are not "
            "compared")
        .range(0.0, 1.0);
    s.field("max_ratio_deviation", c.max_ratio_deviation,
            "ratios z_model / z_raw further than this from 1 are not compared (depth edges, "
            "surfaces the model lacks)")
        .positive();
    s.field("pixel_stride", c.pixel_stride,
            "every pixel_stride-th pixel along rows and columns is compared", "px")
        .min(1);
    s.field("compare_at_block_origin", c.compare_at_block_origin,
            "compare the raw depth of a pixel with the model at the origin of its 2x2 disparity "
            "block (where a structured-light sensor measures it) instead of at the pixel, and "
            "fuse and render the model at the block origins only");
    s.field("min_samples", c.min_samples,
            "a cell's depth bin is estimated when the squared interpolation weights of its "
            "inlier samples on it sum to at least this; cells with no such bin keep the factor 1",
            "samples")
        .positive();
    s.field("median_samples", c.median_samples,
            "the robust fit's initial median and robust sigmas are taken over at most this many "
            "of a cell's samples (every k-th); 0 = all")
        .min(0);
    s.field("robust_iterations", c.robust_iterations,
            "reweighting passes of the per-cell robust fit after the initial median")
        .min(0);
    s.field("huber_k", c.huber_k, "Huber threshold of the robust fit, in robust sigmas").positive();
    s.field("outlier_sigmas", c.outlier_sigmas,
            "residuals beyond this many robust sigmas get weight 0")
        .positive();
    s.field("min_sigma", c.min_sigma, "lower bound of the robust sigma of a cell's ratios")
        .positive();
    s.field("bin_smoothness", c.bin_smoothness,
            "weight of the penalty (f[i] - f[i+1])^2 between adjacent estimated bins", "samples")
        .min(0.0);
    s.field("max_iterations", c.max_iterations,
            "at most this many undistort-fuse-estimate steps of the alternation")
        .min(1);
    s.field("change_tolerance", c.change_tolerance,
            "the alternation stops when the median |change| of the estimated factors is below "
            "this")
        .positive();
    s.field("relaxation", c.relaxation,
            "from the second step on, each estimated factor moves the previous one by this "
            "multiple of its change (in log space): f <- f_prev * (f_est / f_prev)^relaxation")
        .min(1.0)
        .lessThan(2.0);
    s.section("planar", c.planar,
              "the first stage: the bend from each frame's planes, without poses");
    s.section("right_angles", c.right_angles,
              "after each planar stage: the offset of the disparity that keeps planes planes, from "
              "the right angles between each frame's planes");
    s.section("tsdf", c.tsdf, "the model: TSDF fused from the undistorted frames");
    s.section("raycast", c.raycast, "the model's depth at each frame's pose");
    s.field("num_threads", c.num_threads,
            "worker threads of the per-cell fit (0 = all); results do not depend on it")
        .min(0);
}

Status validate(const SelfCalibrationConfig& c) {
    auto bad = [](const char* what) {
        return invalidArgument(fmt::format("self-calibration config: {}", what));
    };
    if (!(c.min_depth_m >= 0.0 && c.max_depth_m > c.min_depth_m)) {
        return bad("need 0 <= min_depth_m < max_depth_m");
    }
    if (!(c.min_view_cos >= 0.0 && c.min_view_cos <= 1.0)) return bad("min_view_cos not in [0, 1]");
    if (!(c.max_ratio_deviation > 0.0)) return bad("max_ratio_deviation must be positive");
    if (c.pixel_stride < 1) return bad("pixel_stride must be at least 1");
    if (!(c.min_samples > 0.0)) return bad("min_samples must be positive");
    if (c.robust_iterations < 0) return bad("robust_iterations must be >= 0");
    if (c.median_samples < 0) return bad("median_samples must be >= 0");
    if (!(c.huber_k > 0.0 && c.outlier_sigmas > 0.0 && c.min_sigma > 0.0)) {
        return bad("huber_k, outlier_sigmas and min_sigma must be positive");
    }
    if (!(c.bin_smoothness >= 0.0)) return bad("bin_smoothness must be >= 0");
    if (c.max_iterations < 1) return bad("max_iterations must be at least 1");
    if (!(c.change_tolerance > 0.0)) return bad("change_tolerance must be positive");
    if (!(c.relaxation >= 1.0 && c.relaxation < 2.0)) return bad("relaxation not in [1, 2)");
    if (Status s = validate(c.planar); !s.isOk()) return s;
    if (Status s = validate(c.right_angles); !s.isOk()) return s;
    if (c.num_threads < 0) return bad("num_threads must be >= 0");
    return c.tsdf.validate();
}

DistortionEstimator::DistortionEstimator(int width, int height, const SelfCalibrationConfig& config)
    : width_(width),
      height_(height),
      config_(config),
      cell_of_column_(static_cast<size_t>(std::max(width, 0))),
      samples_(static_cast<size_t>(kSide) * kSide * kSegments) {
    PLUMB_CHECK(width > 0 && height > 0) << "image size " << width << "x" << height;
    // Cells as the sensor model finds them (drivers/sim/noise.cpp): the pixel scaled to 640x480.
    for (int u = 0; u < width; ++u) cell_of_column_[u] = Table::cellX(u * 640 / width);
    // Rows [rows_of_cell_[y], rows_of_cell_[y + 1]) are those of cell row y (rising with v).
    rows_of_cell_.assign(static_cast<size_t>(kSide) + 1, height);
    for (int v = height - 1; v >= 0; --v) {
        rows_of_cell_[static_cast<size_t>(Table::cellY(v * 480 / height))] = v;
    }
    for (int y = kSide - 1; y >= 0; --y) {
        rows_of_cell_[static_cast<size_t>(y)] = std::min(rows_of_cell_[static_cast<size_t>(y)],
                                                         rows_of_cell_[static_cast<size_t>(y) + 1]);
    }
}

void DistortionEstimator::clear() {
    for (std::vector<Sample>& cell_segment : samples_) cell_segment.clear();
    num_samples_ = 0;
}

Status DistortionEstimator::addFrame(const DepthImage& raw, const DepthImage& model,
                                     const Image<float>& view_cos) {
    auto sizeError = [&](const char* what, int w, int h) {
        return invalidArgument(fmt::format("self-calibration: {} is {}x{}, the frames are {}x{}",
                                           what, w, h, width_, height_));
    };
    if (raw.width() != width_ || raw.height() != height_) {
        return sizeError("the raw depth", raw.width(), raw.height());
    }
    const SelfCalibrationConfig& c = config_;
    // The model and the view cosines: per pixel, or (compare_at_block_origin) per block origin.
    const bool half = c.compare_at_block_origin && model.width() == (width_ + 1) / 2 &&
                      model.height() == (height_ + 1) / 2;
    const int model_w = half ? (width_ + 1) / 2 : width_;
    const int model_h = half ? (height_ + 1) / 2 : height_;
    if (model.width() != model_w || model.height() != model_h) {
        return sizeError("the model depth", model.width(), model.height());
    }
    if (!view_cos.empty() && (view_cos.width() != model_w || view_cos.height() != model_h)) {
        return sizeError("the view cosine image", view_cos.width(), view_cos.height());
    }
    const int step = c.pixel_stride;
    // Rows of one row of cells add to those cells only: the rows of cells run in parallel and
    // every cell gets its samples in the same order whatever the threads.
    std::vector<size_t> added(static_cast<size_t>(kSide), 0);
    plumb::parallelFor(c.num_threads, kSide, [&](int cell_row) {
        size_t n = 0;
        const int first = rows_of_cell_[static_cast<size_t>(cell_row)];
        const int last = rows_of_cell_[static_cast<size_t>(cell_row) + 1];
        for (int v = first + (step - first % step) % step; v < last; v += step) {
            const int mv = half ? v / 2 : (c.compare_at_block_origin ? v - v % 2 : v);
            for (int u = 0; u < width_; u += step) {
                const int mu = half ? u / 2 : (c.compare_at_block_origin ? u - u % 2 : u);
                const double z_raw = raw(u, v);
                const double z_model = model(mu, mv);
                if (!(z_raw > 0.0) || !(z_model >= c.min_depth_m && z_model <= c.max_depth_m)) {
                    continue;
                }
                if (!view_cos.empty() && !(view_cos(mu, mv) >= c.min_view_cos)) continue;
                const double ratio = z_model / z_raw;
                if (!(std::abs(ratio - 1.0) <= c.max_ratio_deviation)) continue;
                const size_t cell =
                    static_cast<size_t>(cell_row) * kSide + cell_of_column_[static_cast<size_t>(u)];
                samples_[cell * kSegments + static_cast<size_t>(depthSegment(z_model))].push_back(
                    {static_cast<float>(z_model), static_cast<float>(ratio)});
                ++n;
            }
        }
        added[static_cast<size_t>(cell_row)] = n;
    });
    for (const size_t n : added) num_samples_ += n;
    return Status::ok();
}

Result<DistortionEstimate> DistortionEstimator::estimate(const Table* previous) const {
    const size_t num_cells = samples_.size() / kSegments;
    std::vector<CellFit> fits(num_cells);
    plumb::parallelFor(config_.num_threads, static_cast<int>(num_cells), [&](int i) {
        fits[static_cast<size_t>(i)] =
            fitCell(&samples_[static_cast<size_t>(i) * kSegments], kSegments, config_);
    });

    DistortionEstimate out;
    out.samples = num_samples_;
    out.covered.assign(num_cells, 0);
    for (size_t i = 0; i < num_cells; ++i) {
        out.covered[i] = fits[i].covered;
        out.outliers += fits[i].outliers;
        for (int b = 0; b < kBins; ++b)
            out.covered_cells[static_cast<size_t>(b)] += (fits[i].covered >> b) & 1;
    }
    // Gauge: the mean factor of the nearest covered bin is 1.
    int gauge_bin = -1;
    for (int b = 0; b < kBins && gauge_bin < 0; ++b) {
        if (out.covered_cells[static_cast<size_t>(b)] > 0) gauge_bin = b;
    }
    if (gauge_bin < 0) {
        return failedPrecondition(fmt::format(
            "self-calibration: no image cell has {} samples in any depth bin ({} samples in all)",
            config_.min_samples, num_samples_));
    }
    double sum = 0.0;
    for (size_t i = 0; i < num_cells; ++i) {
        if ((fits[i].covered >> gauge_bin) & 1)
            sum += fits[i].factor[static_cast<size_t>(gauge_bin)];
    }
    const double scale = sum / out.covered_cells[static_cast<size_t>(gauge_bin)];
    out.gauge_bin = gauge_bin;
    out.gauge_scale = scale;

    std::vector<std::array<float, kBins>> cells(num_cells);
    for (size_t i = 0; i < num_cells; ++i) {
        for (int b = 0; b < kBins; ++b) {
            cells[i][static_cast<size_t>(b)] =
                fits[i].covered == 0
                    ? 1.0F
                    : static_cast<float>(fits[i].factor[static_cast<size_t>(b)] / scale);
        }
    }
    out.table = Table::fromCells(std::move(cells));

    // Change from the previous table over the covered factors.
    const Table neutral = Table::neutral();
    const Table& before = previous == nullptr ? neutral : *previous;
    std::vector<double> changes;
    for (int y = 0; y < kSide; ++y) {
        for (int x = 0; x < kSide; ++x) {
            for (int b = 0; b < kBins; ++b) {
                if (!out.isCovered(x, y, b)) continue;
                changes.push_back(
                    std::abs(static_cast<double>(out.table.cell(x, y)[b]) - before.cell(x, y)[b]));
            }
        }
    }
    out.compared_factors = changes.size();
    if (!changes.empty()) {
        out.max_change = *std::max_element(changes.begin(), changes.end());
        out.median_change = medianOf(&changes);
    }
    return out;
}

namespace {

/// The median |e_i - (a + b u_i + c v_i)| after the least-squares affine fit over rows (1, u, v).
double medianBeyondAffine(const std::vector<Eigen::Vector3d>& at, const std::vector<double>& e) {
    Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
    Eigen::Vector3d atb = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < at.size(); ++i) {
        ata += at[i] * at[i].transpose();
        atb += at[i] * e[i];
    }
    const Eigen::Vector3d k = ata.ldlt().solve(atb);
    std::vector<double> residual(e.size());
    for (size_t i = 0; i < e.size(); ++i) residual[i] = std::abs(e[i] - k.dot(at[i]));
    return medianOf(&residual);
}

}  // namespace

Result<TableComparison> compareTables(const DistortionTable& learned,
                                      const DistortionEstimate& coverage,
                                      const DistortionTable& reference) {
    const int side = DistortionTable::kCellsPerSide;
    auto compared = [&](int x, int y, int bin) {
        return coverage.isCovered(x, y, bin) && reference.cell(x, y)[bin] != 0.0F;
    };
    std::vector<double> ratios;
    for (int bin : {0, 1}) {
        for (int y = 0; y < side; ++y) {
            for (int x = 0; x < side; ++x) {
                if (!compared(x, y, bin)) continue;
                ratios.push_back(double{learned.cell(x, y)[bin]} / reference.cell(x, y)[bin]);
            }
        }
    }
    if (ratios.empty()) {
        return failedPrecondition(
            "the learned table covers no cell of the 1 m or 3 m bin that the reference holds");
    }
    TableComparison out;
    out.scale = medianOf(&ratios);
    for (int bin = 0; bin < DistortionTable::kBins; ++bin) {
        std::vector<double> errors, uncalibrated;
        std::vector<Eigen::Vector3d> at;  // (1, u, v) of the compared cells
        std::vector<double> inverse_error, inverse_uncalibrated;
        for (int y = 0; y < side; ++y) {
            for (int x = 0; x < side; ++x) {
                if (!compared(x, y, bin)) continue;
                const double r = reference.cell(x, y)[bin];
                const double l = learned.cell(x, y)[bin] / out.scale;
                errors.push_back(std::abs(l - r));
                uncalibrated.push_back(std::abs(1.0 - r));
                at.emplace_back(1.0, (x + 0.5) / (side / 2.0) - 1.0,
                                (y + 0.5) / (side / 2.0) - 1.0);
                inverse_error.push_back(1.0 / l - 1.0 / r);
                inverse_uncalibrated.push_back(1.0 - 1.0 / r);
            }
        }
        TableComparison::Bin& b = out.bins[static_cast<size_t>(bin)];
        b.cells = errors.size();
        if (errors.empty()) continue;
        b.median_error = medianOf(&errors);
        b.median_uncalibrated = medianOf(&uncalibrated);
        b.median_error_beyond_projective = medianBeyondAffine(at, inverse_error);
        b.median_uncalibrated_beyond_projective = medianBeyondAffine(at, inverse_uncalibrated);
    }
    return out;
}

Image<float> viewCosines(const tsdf::RaycastResult& ray, const PinholeCamera& camera,
                         const Eigen::Isometry3d& T_V_C) {
    const int w = ray.depth.width();
    const int h = ray.depth.height();
    Image<float> out(w, h, 0.0F);
    const Eigen::Matrix3f R_C_V = T_V_C.rotation().transpose().cast<float>();
    plumb::parallelFor(0, h, [&](int v) {  // rows are independent
        for (int u = 0; u < w; ++u) {
            if (!(ray.depth(u, v) > 0.0F)) continue;
            const Eigen::Vector3f& n_V = ray.normals_V(u, v);
            if (!tsdf::isValid(n_V)) continue;
            const Eigen::Vector3f n_C = R_C_V * n_V;
            const Eigen::Vector3f d_C = camera.ray(u, v).cast<float>().normalized();
            out(u, v) = std::abs(n_C.dot(d_C));
        }
    });
    return out;
}

namespace {

/// The alternation: per iteration the poses from `poses` (when given, else the previous
/// iteration's), refined by `aligner` (when given) against the iteration's model.
Result<SelfCalibrationResult> alternate(const std::vector<DepthImage>& raw,
                                        const PinholeCamera& camera,
                                        std::vector<Eigen::Isometry3d> T_W_C,
                                        const PoseProvider& poses, const FrameAligner& aligner,
                                        const SelfCalibrationConfig& config, const Table* initial,
                                        const IterationObserver& observer) {
    if (Status s = validate(config); !s.isOk()) return s;
    if (Status s = camera.validate(); !s.isOk()) return s;
    if (raw.empty()) return invalidArgument("self-calibration: no frames");
    for (size_t k = 0; k < raw.size(); ++k) {
        if (raw[k].width() != camera.width || raw[k].height() != camera.height) {
            return invalidArgument(
                fmt::format("self-calibration: frame {} is {}x{}, the camera is {}x{}", k,
                            raw[k].width(), raw[k].height(), camera.width, camera.height));
        }
    }

    SelfCalibrationResult result;
    result.table = initial != nullptr ? *initial : Table::neutral();
    std::vector<DepthImage> undistorted(raw.size());
    // One estimator for every iteration: its samples' memory is reused.
    DistortionEstimator estimator(camera.width, camera.height, config);
    for (int it = 0; it < config.max_iterations; ++it) {
        // Undistort with the current table: at the block origins only when the model is fused
        // from them (below) and no pose provider reads the whole frames.
        const bool blocks = config.compare_at_block_origin;
        const bool block_origins_only = blocks && !poses;
        const DepthCalibration calibration(result.table, "the current estimate");
        for (size_t k = 0; k < raw.size(); ++k) {
            undistorted[k] = block_origins_only ? calibration.undistortBlockOrigins(raw[k])
                                                : calibration.undistort(raw[k]);
        }
        if (poses) {
            Result<std::vector<Eigen::Isometry3d>> provided = poses(undistorted);
            if (!provided.isOk()) return provided.status();
            T_W_C = std::move(provided).value();
        }
        if (T_W_C.size() != raw.size()) {
            return invalidArgument(
                fmt::format("self-calibration: {} poses for {} frames", T_W_C.size(), raw.size()));
        }
        for (size_t k = 0; k < raw.size(); ++k) {
            if (!T_W_C[k].matrix().allFinite()) {
                return invalidArgument(
                    fmt::format("self-calibration: the pose of frame {} is not finite", k));
            }
        }
        // Fuse the model: from the block origins only when the sensor measures on 2x2 blocks
        // (a pixel's depth belongs to its block origin; fused at the pixel itself, every view
        // would shift the surface by half a pixel up and left in its image).
        const PinholeCamera model_camera = blocks ? blockOriginCamera(camera) : camera;
        std::vector<DepthImage> fused(blocks && !block_origins_only ? raw.size() : 0);
        for (size_t k = 0; k < fused.size(); ++k) fused[k] = blockOrigins(undistorted[k]);
        const std::vector<DepthImage>& model_input =
            blocks && !block_origins_only ? fused : undistorted;
        tsdf::TsdfVolume volume(config.tsdf);
        for (size_t k = 0; k < raw.size(); ++k) {
            Result<tsdf::IntegrationStats> s =
                volume.integrate(model_input[k], model_camera, T_W_C[k]);
            if (!s.isOk()) {
                return Status(
                    s.status().code(),
                    fmt::format("self-calibration: fusing frame {}: {}", k, s.status().message()));
            }
        }
        if (aligner) {
            for (size_t k = 0; k < raw.size(); ++k) {
                Result<Eigen::Isometry3d> refined =
                    aligner(k, model_input[k], model_camera, volume, T_W_C[k]);
                if (!refined.isOk()) return refined.status();
                if (refined->matrix().allFinite()) T_W_C[k] = *refined;
            }
        }
        // Compare every raw frame with the model at its pose.
        estimator.clear();
        tsdf::RaycastConfig ray_config = config.raycast;
        ray_config.max_depth_m =
            std::min(ray_config.max_depth_m, static_cast<float>(config.max_depth_m));
        for (size_t k = 0; k < raw.size(); ++k) {
            const tsdf::RaycastResult ray = tsdf::raycast(
                volume, model_camera, T_W_C[k], ray_config, aligner ? nullptr : &model_input[k]);
            Image<float> view_cos = viewCosines(ray, model_camera, T_W_C[k]);
            const Status s = estimator.addFrame(raw[k], ray.depth, view_cos);
            if (!s.isOk()) return s;
        }
        Result<DistortionEstimate> estimate = estimator.estimate(&result.table);
        if (!estimate.isOk()) return estimate.status();
        CalibrationIteration step;
        step.iteration = it;
        step.fused_blocks = volume.numBlocks();
        step.estimate = std::move(estimate).value();
        // Over-relaxed update of the covered factors (from the second step on):
        // f <- f_previous * (f_estimated / f_previous)^relaxation.
        if (it > 0 && config.relaxation != 1.0) {
            std::vector<std::array<float, kBins>> cells(static_cast<size_t>(kSide) * kSide);
            for (int y = 0; y < kSide; ++y) {
                for (int x = 0; x < kSide; ++x) {
                    std::array<float, kBins>& c = cells[static_cast<size_t>(y) * kSide + x];
                    c = step.estimate.table.cell(x, y);
                    for (int b = 0; b < kBins; ++b) {
                        const double before = result.table.cell(x, y)[static_cast<size_t>(b)];
                        if (!step.estimate.isCovered(x, y, b) || !(before > 0.0)) continue;
                        c[static_cast<size_t>(b)] =
                            static_cast<float>(before * std::pow(c[static_cast<size_t>(b)] / before,
                                                                 config.relaxation));
                    }
                }
            }
            step.estimate.table = Table::fromCells(std::move(cells));
        }
        result.table = step.estimate.table;
        result.T_W_C = T_W_C;
        const bool small = it > 0 && step.estimate.median_change < config.change_tolerance;
        if (observer) observer(step);
        result.iterations.push_back(std::move(step));
        if (small) {
            result.converged = true;
            break;
        }
    }
    return result;
}

}  // namespace

Result<SelfCalibrationResult> selfCalibrate(const std::vector<DepthImage>& raw,
                                            const PinholeCamera& camera, const PoseProvider& poses,
                                            const SelfCalibrationConfig& config,
                                            const Table* initial,
                                            const IterationObserver& observer) {
    if (!poses) return invalidArgument("self-calibration: no pose provider");
    return alternate(raw, camera, {}, poses, FrameAligner{}, config, initial, observer);
}

Result<SelfCalibrationResult> selfCalibrate(const std::vector<DepthImage>& raw,
                                            const PinholeCamera& camera,
                                            const std::vector<Eigen::Isometry3d>& T_W_C,
                                            const SelfCalibrationConfig& config,
                                            const Table* initial, const IterationObserver& observer,
                                            const FrameAligner& aligner) {
    return alternate(raw, camera, T_W_C, PoseProvider{}, aligner, config, initial, observer);
}

}  // namespace plumb::calibration
