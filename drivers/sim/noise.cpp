// SPDX-License-Identifier: Apache-2.0
#include "drivers/sim/noise.hpp"

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>

#ifndef PLUMB_SHARED_DATA_DIR
#define PLUMB_SHARED_DATA_DIR "../shared/data"
#endif

namespace plumb::sim {
namespace {

constexpr int kTableBins = kNormalTableBins;

// Inverse of the standard normal CDF by bisection on erfc (used once, to fill the table).
double inverseNormalCdf(double p) {
    double lo = -10.0, hi = 10.0;
    for (int i = 0; i < 200; ++i) {
        const double mid = 0.5 * (lo + hi);
        if (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return 0.5 * (lo + hi);
}

const std::vector<float>& normalTable() {
    static const std::vector<float> table = [] {
        std::vector<float> t(kTableBins + 1);
        const double p_min = 0.5 / kTableBins;
        for (int k = 0; k <= kTableBins; ++k) {
            const double p = std::clamp(static_cast<double>(k) / kTableBins, p_min, 1.0 - p_min);
            t[k] = static_cast<float>(inverseNormalCdf(p));
        }
        return t;
    }();
    return table;
}

// Seeds of the generator of one row in one pass of one frame.
uint64_t rowSeed(uint64_t seed, uint64_t frame, int row, int pass) {
    return mixSeed(mixSeed(mixSeed(seed) ^ frame) ^ ((static_cast<uint64_t>(row) << 4) | pass));
}

double uniformFromBits(uint32_t bits) { return (bits + 0.5) * (1.0 / 4294967296.0); }

// standardNormalFromBits with the table looked up once per image instead of once per sample.
inline float normalFromBits(const float* table, uint32_t bits) {
    const uint32_t bin = bits >> 20;
    const float frac = static_cast<float>(bits & 0xFFFFFU) * (1.0F / 1048576.0F);
    return table[bin] + frac * (table[bin + 1] - table[bin]);
}

// Rows of the noisy image per task. Each task recomputes the masked rows it reads (pass 1, about
// half of its own rows plus one at either end), so no image-sized scratch buffer is allocated per
// frame; the result does not depend on the split.
constexpr int kRowsPerTask = 32;

}  // namespace

Mt19937_64::Mt19937_64(uint64_t seed) {
    // std::mersenne_twister_engine::seed: x_i = f (x_{i-1} ^ (x_{i-1} >> (w - 2))) + i.
    state_[0] = seed;
    for (int i = 1; i < kN; ++i) {
        const uint64_t x = state_[i - 1];
        state_[i] = 6364136223846793005ULL * (x ^ (x >> 62)) + static_cast<uint64_t>(i);
    }
}

void Mt19937_64::refill() {
    // The twist of std::mersenne_twister_engine::_M_gen_rand (n = 312, m = 156, r = 31), split at
    // the wrap-around so that each loop vectorises; the conditional xor of a is a mask.
    constexpr int kM = 156;
    constexpr uint64_t kUpper = ~uint64_t{0} << 31;
    constexpr uint64_t kLower = ~kUpper;
    constexpr uint64_t kA = 0xB5026F5AA96619E9ULL;
    auto twist = [](uint64_t x_k, uint64_t x_k1, uint64_t x_km) {
        const uint64_t y = (x_k & kUpper) | (x_k1 & kLower);
        return x_km ^ (y >> 1) ^ ((uint64_t{0} - (y & 1U)) & kA);
    };
    for (int k = 0; k < kN - kM; ++k) state_[k] = twist(state_[k], state_[k + 1], state_[k + kM]);
    for (int k = kN - kM; k < kN - 1; ++k) {
        state_[k] = twist(state_[k], state_[k + 1], state_[k + kM - kN]);
    }
    state_[kN - 1] = twist(state_[kN - 1], state_[0], state_[kM - 1]);
    // Tempering (u, d) = (29, 0x5555...), (s, b) = (17, 0x71D6...), (t, c) = (37, 0xFFF7...), l
    // = 43.
    for (int k = 0; k < kN; ++k) {
        uint64_t z = state_[k];
        z ^= (z >> 29) & 0x5555555555555555ULL;
        z ^= (z << 17) & 0x71D67FFFEDA60000ULL;
        z ^= (z << 37) & 0xFFF7EEE000000000ULL;
        z ^= z >> 43;
        out_[k] = z;
    }
    next_ = 0;
}

uint64_t mixSeed(uint64_t x) {
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}

float standardNormalFromBits(uint32_t bits) { return normalFromBits(normalTable().data(), bits); }

const float* standardNormalTable() { return normalTable().data(); }

Result<std::filesystem::path> findNoiseModelFile(const std::string& explicit_path) {
    if (!explicit_path.empty()) {
        if (std::filesystem::is_regular_file(explicit_path))
            return std::filesystem::path(explicit_path);
        return notFound(fmt::format("noise model file '{}' does not exist", explicit_path));
    }
    if (const char* env = std::getenv("PLUMB_NOISE_MODEL"); env != nullptr && *env != '\0') {
        if (std::filesystem::is_regular_file(env)) return std::filesystem::path(env);
        return notFound(fmt::format("PLUMB_NOISE_MODEL='{}' does not name an existing file", env));
    }
    const std::filesystem::path fallback =
        std::filesystem::path(PLUMB_SHARED_DATA_DIR) / "redwood-noise" / "dist-model.txt";
    if (std::filesystem::is_regular_file(fallback)) return fallback;
    return notFound(fmt::format(
        "the Redwood distortion table (dist-model.txt) was not found at {}; point at it with "
        "--noise-model FILE or the environment variable PLUMB_NOISE_MODEL, or use --noise "
        "parametric",
        fallback.string()));
}

DepthNoiseModel::DepthNoiseModel(const NoiseConfig& config, std::optional<DistortionTable> table,
                                 double cx, double cy)
    : config_(config), table_(std::move(table)), cx_(cx), cy_(cy) {
    PLUMB_CHECK(!config.enabled || config.distortion != DistortionKind::kTable || table_)
        << "the table distortion needs a DistortionTable";
    PLUMB_CHECK(config.baseline_focal_px_m > 0.0 && config.disparity_subpixel_steps > 0.0)
        << "baseline_focal_px_m and disparity_subpixel_steps must be positive";
    PLUMB_CHECK(cx > 0.0 && cy > 0.0) << "principal point must be positive";
}

DepthImage DepthNoiseModel::apply(const DepthImage& clean, const Image<float>& cos_view,
                                  uint64_t seed, uint64_t frame_index) const {
    DepthImage out;
    apply(clean, cos_view, seed, frame_index, &out);
    return out;
}

void DepthNoiseModel::maskRow(const DepthImage& clean, const Image<float>& cos_view, uint64_t seed,
                              uint64_t frame_index, int v, float* row) const {
    const int w = clean.width();
    const int h = clean.height();
    const NoiseConfig& c = config_;
    if (!c.missing_data) {
        for (int u = 0; u < w; u += 2) row[u / 2] = clean(u, v);
        return;
    }
    const bool have_cos = cos_view.width() == w && cos_view.height() == h;
    Mt19937_64 rng(rowSeed(seed, frame_index, v, 1));
    for (int u = 0; u < w; ++u) {
        const uint64_t bits = rng();  // one draw per pixel, read or not: the stream is per row
        if (u % 2 != 0) continue;
        const float z = clean(u, v);
        row[u / 2] = z;
        if (!(z > 0.0F)) continue;
        bool drop = uniformFromBits(static_cast<uint32_t>(bits)) < c.random_dropout;
        if (have_cos) {
            const double cs = cos_view(u, v);
            if (cs < c.grazing_cos_drop) {
                drop = true;
            } else if (cs < c.grazing_cos_keep) {
                const double p =
                    (c.grazing_cos_keep - cs) / (c.grazing_cos_keep - c.grazing_cos_drop);
                drop |= uniformFromBits(static_cast<uint32_t>(bits >> 32)) < p;
            }
        }
        if (!drop) {
            float lo = z, hi = z;
            for (int dv = -1; dv <= 1; ++dv) {
                for (int du = -1; du <= 1; ++du) {
                    const int uu = u + du, vv = v + dv;
                    if (uu < 0 || vv < 0 || uu >= w || vv >= h) continue;
                    const float zn = clean(uu, vv);
                    if (!(zn > 0.0F)) continue;
                    lo = std::min(lo, zn);
                    hi = std::max(hi, zn);
                }
            }
            drop = hi - lo > c.edge_relative_range * z;
        }
        if (drop) row[u / 2] = 0.0F;
    }
}

void DepthNoiseModel::apply(const DepthImage& clean, const Image<float>& cos_view, uint64_t seed,
                            uint64_t frame_index, DepthImage* out) const {
    PLUMB_CHECK(out != &clean && out != &cos_view) << "apply() cannot work in place";
    const int w = clean.width();
    const int h = clean.height();
    const NoiseConfig& c = config_;
    auto in_range = [&](double z) {
        return z >= c.min_depth_m && (c.max_depth_m <= 0.0 || z <= c.max_depth_m);
    };
    if (out->width() != w || out->height() != h || out->size() != clean.size()) {
        *out = DepthImage(w, h);  // else reused: every pixel is written below
    }
    if (!c.enabled) {
        for (size_t i = 0; i < clean.size(); ++i) {
            const float z = clean.data()[i];
            out->data()[i] = (z > 0.0F && in_range(z)) ? z : 0.0F;
        }
        return;
    }
    // A.2 reads the masked image (pass 1, §1.4.E) only at the top-left pixel (x - x%2, y - y%2)
    // of each 2x2 block, so pass 1 runs on even rows and columns only, into rows of half width.
    const int half_w = (w + 1) / 2;
    std::vector<int> cell_x(w), cell_y(h);  // A.3 table cells per column and row
    for (int x = 0; x < w; ++x) cell_x[x] = DistortionTable::cellX(x * 640 / w);
    for (int y = 0; y < h; ++y) cell_y[y] = DistortionTable::cellY(y * 480 / h);
    const float* normal = normalTable().data();

    // Pass 2 (§1.4.A): jitter, 2x2 sampling, distortion, disparity quantisation and noise.
    const double bf = c.baseline_focal_px_m;
    const double steps = c.disparity_subpixel_steps;
    auto noisy = [&](Mt19937_64& rng, int u, int v, const float* masked, int r0) -> float {
        const uint64_t r1 = rng();
        const uint64_t r2 = rng();
        // A.1: Gaussian pixel jitter, rounded to the nearest pixel.
        const double jx = c.jitter_std_px * normalFromBits(normal, static_cast<uint32_t>(r1));
        const double jy = c.jitter_std_px * normalFromBits(normal, static_cast<uint32_t>(r1 >> 32));
        const int x = std::clamp(static_cast<int>(std::nearbyint(u + jx)), 0, w - 1);
        const int y = std::clamp(static_cast<int>(std::nearbyint(v + jy)), 0, h - 1);
        // A.2: the disparity is measured at half resolution (2x2 blocks).
        double d = masked[static_cast<size_t>(y / 2 - r0) * half_w + x / 2];
        if (!(d > 0.0)) return 0.0F;
        // A.3: low-frequency distortion.
        if (c.distortion == DistortionKind::kTable) {
            const float f = table_->cellFactor(cell_x[x], cell_y[y], d);
            if (f == 0.0F) return 0.0F;
            d /= f;
        } else if (c.distortion == DistortionKind::kParametric) {
            const double rx = (x - cx_) / cx_;
            const double ry = (y - cy_) / cy_;
            const double rho = 0.5 * (rx * rx + ry * ry);
            const double k = c.k1 * std::clamp(d / 3.0, 0.0, 1.5);
            d /= 1.0 + k * rho + c.k2 * rx;
        }
        // A.4: disparity noise and 1/8-pixel quantisation.
        const double disparity =
            bf / d + c.disparity_noise_std * normalFromBits(normal, static_cast<uint32_t>(r2));
        const double level = std::nearbyint(disparity * steps);
        if (!(level > 0.0)) return 0.0F;
        const double z = bf * steps / level;
        return in_range(z) ? static_cast<float>(z) : 0.0F;
    };
    tbb::parallel_for(
        tbb::blocked_range<int>(0, h, kRowsPerTask),
        [&](const tbb::blocked_range<int>& rows) {
            // Masked rows r0..r1 (image rows 2r) cover the jittered rows v - 1 .. v + 1.
            const int r0 = std::max(0, rows.begin() - 1) / 2;
            const int r1 = std::min(h - 1, rows.end()) / 2;
            std::vector<float> masked(static_cast<size_t>(r1 - r0 + 1) * half_w);
            for (int r = r0; r <= r1; ++r) {
                maskRow(clean, cos_view, seed, frame_index, 2 * r,
                        masked.data() + static_cast<size_t>(r - r0) * half_w);
            }
            for (int v = rows.begin(); v < rows.end(); ++v) {
                Mt19937_64 rng(rowSeed(seed, frame_index, v, 2));
                for (int u = 0; u < w; ++u) (*out)(u, v) = noisy(rng, u, v, masked.data(), r0);
            }
        },
        tbb::simple_partitioner());
}

}  // namespace plumb::sim
