// SPDX-License-Identifier: Apache-2.0
#include "drivers/sim/noise.hpp"

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <random>
#include <sstream>

#ifndef PLUMB_SHARED_DATA_DIR
#define PLUMB_SHARED_DATA_DIR "../shared/data"
#endif

namespace plumb::sim {
namespace {

constexpr int kCells = 80;
constexpr int kNumbersPerCell = 23;
constexpr int kTableBins = 4096;

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

}  // namespace

uint64_t mixSeed(uint64_t x) {
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}

float standardNormalFromBits(uint32_t bits) {
    const std::vector<float>& t = normalTable();
    const uint32_t bin = bits >> 20;
    const float frac = static_cast<float>(bits & 0xFFFFFU) * (1.0F / 1048576.0F);
    return t[bin] + frac * (t[bin + 1] - t[bin]);
}

Result<DistortionTable> DistortionTable::parse(const std::string& text, const std::string& source) {
    std::istringstream in(text);
    std::string line;
    int line_no = 0;
    std::vector<double> numbers;
    numbers.reserve(kCells * kCells * kNumbersPerCell);
    while (std::getline(in, line)) {
        ++line_no;
        if (line_no <= 5) continue;  // header: 8 6 2 80 80
        const size_t pct = line.find('%');
        if (pct != std::string::npos) line.resize(pct);
        std::istringstream fields(line);
        std::string token;
        while (fields >> token) {
            char* end = nullptr;
            const double v = std::strtod(token.c_str(), &end);
            if (end == token.c_str() || *end != '\0' || !std::isfinite(v)) {
                return corrupt(fmt::format("{}:{}: '{}' is not a number", source, line_no, token));
            }
            numbers.push_back(v);
        }
    }
    const size_t needed = static_cast<size_t>(kCells) * kCells * kNumbersPerCell;
    if (line_no <= 5 || numbers.size() < needed) {
        return corrupt(fmt::format(
            "{}: distortion table has {} numbers after the 5 header lines, need {} (80x80 cells "
            "x 23)",
            source, numbers.size(), needed));
    }
    DistortionTable table;
    table.cells_.resize(kCells * kCells);
    for (int c = 0; c < kCells * kCells; ++c) {
        const size_t base = static_cast<size_t>(c) * kNumbersPerCell + 3;
        bool all_low = true;
        for (int i = 0; i < 5; ++i) all_low &= numbers[base + i] < 8000.0;
        for (int i = 0; i < 5; ++i) {
            table.cells_[c][i] = all_low ? 0.0F : static_cast<float>(numbers[base + 15 + i]);
        }
    }
    return table;
}

Result<DistortionTable> DistortionTable::load(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return notFound(fmt::format("{}: cannot open the distortion table", path.string()));
    std::ostringstream text;
    text << in.rdbuf();
    return parse(text.str(), path.string());
}

float DistortionTable::factor(int x640, int y480, double z) const {
    // Eq. A.3: bins centred at 1, 3, 5, 7, 9 m, linear in between, clamped at both ends.
    const int i2 = static_cast<int>((z + 1.0) / 2.0);
    const int i1 = i2 - 1;
    const double a = (z - (2.0 * i1 + 1.0)) / 2.0;
    const int cx = std::clamp(x640 / 8, 0, kCells - 1);
    const int cy = std::clamp(y480 / 6, 0, kCells - 1);
    const std::array<float, 5>& cell = cells_[static_cast<size_t>(cy) * kCells + cx];
    return static_cast<float>((1.0 - a) * cell[std::clamp(i1, 0, 4)] + a * cell[std::min(i2, 4)]);
}

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
    const int w = clean.width();
    const int h = clean.height();
    const NoiseConfig& c = config_;
    const bool have_cos = cos_view.width() == w && cos_view.height() == h;
    auto in_range = [&](double z) {
        return z >= c.min_depth_m && (c.max_depth_m <= 0.0 || z <= c.max_depth_m);
    };
    DepthImage out(w, h, 0.0F);
    if (!c.enabled) {
        for (size_t i = 0; i < clean.size(); ++i) {
            const float z = clean.data()[i];
            out.data()[i] = (z > 0.0F && in_range(z)) ? z : 0.0F;
        }
        return out;
    }

    // Pass 1 (§1.4.E): missing data decided on the clean image.
    DepthImage src = clean;
    if (c.missing_data) {
        tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
            for (int v = rows.begin(); v < rows.end(); ++v) {
                std::mt19937_64 rng(rowSeed(seed, frame_index, v, 1));
                for (int u = 0; u < w; ++u) {
                    const uint64_t bits = rng();
                    const float z = clean(u, v);
                    if (!(z > 0.0F)) continue;
                    bool drop = uniformFromBits(static_cast<uint32_t>(bits)) < c.random_dropout;
                    if (have_cos) {
                        const double cs = cos_view(u, v);
                        if (cs < c.grazing_cos_drop) {
                            drop = true;
                        } else if (cs < c.grazing_cos_keep) {
                            const double p = (c.grazing_cos_keep - cs) /
                                             (c.grazing_cos_keep - c.grazing_cos_drop);
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
                    if (drop) src(u, v) = 0.0F;
                }
            }
        });
    }

    // Pass 2 (§1.4.A): jitter, 2x2 sampling, distortion, disparity quantisation and noise.
    const double bf = c.baseline_focal_px_m;
    const double steps = c.disparity_subpixel_steps;
    tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
        for (int v = rows.begin(); v < rows.end(); ++v) {
            std::mt19937_64 rng(rowSeed(seed, frame_index, v, 2));
            for (int u = 0; u < w; ++u) {
                const uint64_t r1 = rng();
                const uint64_t r2 = rng();
                // A.1: Gaussian pixel jitter, rounded to the nearest pixel.
                const double jx =
                    c.jitter_std_px * standardNormalFromBits(static_cast<uint32_t>(r1));
                const double jy =
                    c.jitter_std_px * standardNormalFromBits(static_cast<uint32_t>(r1 >> 32));
                const int x = std::clamp(static_cast<int>(std::nearbyint(u + jx)), 0, w - 1);
                const int y = std::clamp(static_cast<int>(std::nearbyint(v + jy)), 0, h - 1);
                // A.2: the disparity is measured at half resolution (2x2 blocks).
                double d = src(x - x % 2, y - y % 2);
                if (!(d > 0.0)) continue;
                // A.3: low-frequency distortion.
                if (c.distortion == DistortionKind::kTable) {
                    const float f = table_->factor(x * 640 / w, y * 480 / h, d);
                    if (f == 0.0F) continue;
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
                    bf / d +
                    c.disparity_noise_std * standardNormalFromBits(static_cast<uint32_t>(r2));
                const double level = std::nearbyint(disparity * steps);
                if (!(level > 0.0)) continue;
                const double z = bf * steps / level;
                if (in_range(z)) out(u, v) = static_cast<float>(z);
            }
        }
    });
    return out;
}

}  // namespace plumb::sim
