// SPDX-License-Identifier: Apache-2.0
#include "device/preprocess/preprocess.hpp"

#include <array>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "common/core/parallel.hpp"

namespace plumb::device {

Status PreprocessConfig::validate() const {
    if (!(min_depth_m >= 0.0f && max_depth_m > min_depth_m)) {
        return invalidArgument("preprocess: need 0 <= min_depth_m < max_depth_m");
    }
    if (bilateral_radius_px < 0 || bilateral_radius_px > 10) {
        return invalidArgument("preprocess: bilateral_radius_px must be in [0, 10]");
    }
    if (!(bilateral_sigma_space_px > 0.0f) || !(bilateral_sigma_depth_m > 0.0f)) {
        return invalidArgument("preprocess: bilateral sigmas must be positive");
    }
    if (num_levels < 1 || num_levels > 5) {
        return invalidArgument("preprocess: num_levels must be in [1, 5], got " +
                               std::to_string(num_levels));
    }
    if (min_level_width_px < 1) {
        return invalidArgument("preprocess: min_level_width_px must be >= 1, got " +
                               std::to_string(min_level_width_px));
    }
    if (!(max_normal_depth_jump_m > 0.0f)) {
        return invalidArgument("preprocess: max_normal_depth_jump_m must be positive");
    }
    return Status::ok();
}

DepthImage gateDepth(const DepthImage& depth, const PreprocessConfig& config) {
    const int w = depth.width();
    std::vector<float> out(depth.size());
    parallelFor(config.num_threads, depth.height(), [&](int v) {
        const float* in = depth.data() + static_cast<size_t>(v) * w;
        float* row = out.data() + static_cast<size_t>(v) * w;
        for (int u = 0; u < w; ++u) {
            const float d = in[u];
            row[u] =
                std::isfinite(d) && d >= config.min_depth_m && d <= config.max_depth_m ? d : 0.0f;
        }
    });
    return DepthImage(w, depth.height(), std::move(out));
}

namespace {

#if defined(__x86_64__) && defined(__GNUC__)
/// The interior of one row of the bilateral filter, 8 pixels at a time in AVX2 lanes: pixels
/// [u_begin, u_end) of row v, each window wholly inside the image. Per pixel the same operations
/// in the same order as the portable loop below (no FMA), so the output is identical bit for bit;
/// the range table is read with one gather per tap. Returns the first pixel not filtered.
__attribute__((target("avx2"))) int bilateralSpanAvx2(const float* depth, int w, int v, int r,
                                                      int u_begin, int u_end, const float* spatial,
                                                      const float* range_lut, float max_diff,
                                                      float lut_scale, float* out) {
    const int side = 2 * r + 1;
    const __m256 zero = _mm256_setzero_ps();
    const __m256 sign = _mm256_set1_ps(-0.0f);
    const __m256 maxd = _mm256_set1_ps(max_diff);
    const __m256 scale = _mm256_set1_ps(lut_scale);
    const __m256 half = _mm256_set1_ps(0.5f);
    int u = u_begin;
    for (; u + 8 <= u_end; u += 8) {
        const __m256 dc = _mm256_loadu_ps(depth + static_cast<ptrdiff_t>(v) * w + u);
        const __m256 centre_valid = _mm256_cmp_ps(dc, zero, _CMP_GT_OQ);
        if (_mm256_movemask_ps(centre_valid) == 0) continue;  // 8 holes: the output stays 0
        __m256 sum = zero, wsum = zero;
        for (int dy = -r; dy <= r; ++dy) {
            const float* row = depth + static_cast<ptrdiff_t>(v + dy) * w + (u - r);
            const float* sw = spatial + static_cast<ptrdiff_t>(dy + r) * side;
            for (int i = 0; i < side; ++i) {
                const __m256 d = _mm256_loadu_ps(row + i);
                const __m256 ad = _mm256_andnot_ps(sign, _mm256_sub_ps(d, dc));
                const __m256 valid = _mm256_and_ps(_mm256_cmp_ps(d, zero, _CMP_GT_OQ),
                                                   _mm256_cmp_ps(ad, maxd, _CMP_LE_OQ));
                const __m256i bin = _mm256_cvttps_epi32(
                    _mm256_add_ps(_mm256_mul_ps(_mm256_min_ps(ad, maxd), scale), half));
                const __m256 range = _mm256_i32gather_ps(range_lut, bin, 4);
                const __m256 wt = _mm256_and_ps(valid, _mm256_mul_ps(_mm256_set1_ps(sw[i]), range));
                sum = _mm256_add_ps(sum, _mm256_mul_ps(wt, _mm256_and_ps(valid, d)));
                wsum = _mm256_add_ps(wsum, wt);
            }
        }
        // Holes stay 0 (their wsum may be 0); elsewhere wsum >= 1 (the centre pixel).
        const __m256 filtered =
            _mm256_div_ps(sum, _mm256_blendv_ps(_mm256_set1_ps(1.0f), wsum, centre_valid));
        _mm256_storeu_ps(out + static_cast<ptrdiff_t>(v) * w + u,
                         _mm256_and_ps(centre_valid, filtered));
    }
    return u;
}
#endif

}  // namespace

DepthImage bilateralFilter(const DepthImage& depth, const PreprocessConfig& config) {
    return bilateralFilter(depth, config, simd::best());
}

DepthImage bilateralFilter(const DepthImage& depth, const PreprocessConfig& config,
                           simd::Level simd_level) {
    const int w = depth.width(), h = depth.height();
    const int r = config.bilateral_radius_px;
    const float sigma_s = config.bilateral_sigma_space_px * static_cast<float>(w) / 640.0f;
    const float inv_2ss = 1.0f / (2.0f * sigma_s * sigma_s);
    const float sigma_r = config.bilateral_sigma_depth_m;
    const float inv_2sr = 1.0f / (2.0f * sigma_r * sigma_r);
    const float max_diff = 3.0f * sigma_r;
    std::vector<float> spatial(static_cast<size_t>((2 * r + 1) * (2 * r + 1)));
    for (int dy = -r; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
            spatial[static_cast<size_t>((dy + r) * (2 * r + 1) + dx + r)] =
                std::exp(-static_cast<float>(dx * dx + dy * dy) * inv_2ss);
        }
    }
    // Range weights exp(-diff^2 / 2 sigma_r^2) tabulated over |diff| in [0, 3 sigma_r] (nearest
    // of kRangeBins + 1 samples): no exp() in the inner loop.
    constexpr int kRangeBins = 256;
    std::array<float, kRangeBins + 1> range_lut{};
    for (int i = 0; i <= kRangeBins; ++i) {
        const float diff = max_diff * static_cast<float>(i) / kRangeBins;
        range_lut[static_cast<size_t>(i)] = std::exp(-diff * diff * inv_2sr);
    }
    const float lut_scale = kRangeBins / max_diff;
    DepthImage out(w, h, 0.0f);
    const int side = 2 * r + 1;
    const bool use_avx2 = simd_level == simd::Level::kAvx2;
    parallelFor(config.num_threads, h, [&](int v) {
        const bool interior_row = v >= r && v < h - r;
        [[maybe_unused]] bool vector_span = interior_row && use_avx2;
        for (int u = 0; u < w; ++u) {
#if defined(__x86_64__) && defined(__GNUC__)
            if (vector_span && u == r) {
                // The interior of the row in AVX2 lanes, the rest (its < 8 last pixels and the
                // borders) below.
                vector_span = false;
                u = bilateralSpanAvx2(depth.data(), w, v, r, r, w - r, spatial.data(),
                                      range_lut.data(), max_diff, lut_scale, out.data());
                if (u >= w) break;
            }
#endif
            const float dc = depth(u, v);
            if (dc <= 0.0f) continue;
            float sum = 0.0f, wsum = 0.0f;
            if (interior_row && u >= r && u < w - r) {
                // Whole window inside the image: no bounds tests, and no branch per tap (holes
                // and depth edges would mispredict it); a skipped tap adds an exact zero.
                for (int dy = -r; dy <= r; ++dy) {
                    const float* row = &depth(u - r, v + dy);
                    const float* sw = &spatial[static_cast<size_t>((dy + r) * side)];
                    for (int i = 0; i < side; ++i) {
                        const float d = row[i];
                        const float ad = std::abs(d - dc);
                        const bool valid = d > 0.0f && ad <= max_diff;
                        const int bin = static_cast<int>(std::min(ad, max_diff) * lut_scale + 0.5f);
                        const float wt = valid ? sw[i] * range_lut[static_cast<size_t>(bin)] : 0.0f;
                        sum += wt * (valid ? d : 0.0f);
                        wsum += wt;
                    }
                }
                out(u, v) = sum / wsum;  // wsum >= 1 (the centre pixel)
                continue;
            }
            for (int dy = -r; dy <= r; ++dy) {
                const int y = v + dy;
                if (y < 0 || y >= h) continue;
                for (int dx = -r; dx <= r; ++dx) {
                    const int x = u + dx;
                    if (x < 0 || x >= w) continue;
                    const float d = depth(x, y);
                    const float diff = d - dc;
                    if (d <= 0.0f || std::abs(diff) > max_diff) continue;
                    const float wt =
                        spatial[static_cast<size_t>((dy + r) * side + dx + r)] *
                        range_lut[static_cast<size_t>(std::abs(diff) * lut_scale + 0.5f)];
                    sum += wt * d;
                    wsum += wt;
                }
            }
            out(u, v) = sum / wsum;  // wsum >= 1 (the centre pixel)
        }
    });
    return out;
}

DepthImage downsampleDepth(const DepthImage& depth, float sigma_depth_m, int num_threads) {
    const int w = depth.width() / 2, h = depth.height() / 2;
    DepthImage out(w, h, 0.0f);
    const float max_diff = 3.0f * sigma_depth_m;
    parallelFor(num_threads, h, [&](int v) {
        for (int u = 0; u < w; ++u) {
            const float s[4] = {depth(2 * u, 2 * v), depth(2 * u + 1, 2 * v),
                                depth(2 * u, 2 * v + 1), depth(2 * u + 1, 2 * v + 1)};
            float ref = 0.0f;
            for (float d : s) {
                if (d > 0.0f) {
                    ref = d;
                    break;
                }
            }
            if (ref <= 0.0f) continue;
            float sum = 0.0f;
            int n = 0;
            for (float d : s) {
                if (d > 0.0f && std::abs(d - ref) <= max_diff) {
                    sum += d;
                    ++n;
                }
            }
            out(u, v) = sum / static_cast<float>(n);
        }
    });
    return out;
}

void computeVertexNormalMaps(const DepthImage& depth, const PinholeCamera& camera,
                             float max_depth_jump_m, PointImage* points_C, PointImage* normals_C,
                             int num_threads) {
    const int w = depth.width(), h = depth.height();
    // Every pixel of both maps is written below, rows in parallel: no serial fill first
    // (Eigen vectors are left uninitialised by their default constructor).
    std::vector<Eigen::Vector3f> points(depth.size()), normals(depth.size());
    // The ray factors (u - cx) / fx of camera.unproject, once per column.
    std::vector<double> ray_x(static_cast<size_t>(w));
    for (int u = 0; u < w; ++u) ray_x[static_cast<size_t>(u)] = (u - camera.cx) / camera.fx;
    parallelFor(num_threads, h, [&](int v) {
        const double ray_y = (v - camera.cy) / camera.fy;
        Eigen::Vector3f* row = points.data() + static_cast<size_t>(v) * w;
        for (int u = 0; u < w; ++u) {
            const double d = depth(u, v);
            row[u] = d > 0.0
                         ? Eigen::Vector3f(static_cast<float>(ray_x[static_cast<size_t>(u)] * d),
                                           static_cast<float>(ray_y * d), static_cast<float>(d))
                         : tsdf::invalidPoint();
        }
    });
    *points_C = PointImage(w, h, std::move(points));
    parallelFor(num_threads, h, [&](int v) {
        Eigen::Vector3f* row = normals.data() + static_cast<size_t>(v) * w;
        for (int u = 0; u < w; ++u) {
            Eigen::Vector3f n;
            if (tsdf::neighbourNormal(*points_C, depth, u, v, max_depth_jump_m, &n)) {
                if (n.dot((*points_C)(u, v)) > 0.0f) n = -n;  // face the camera
                row[u] = n;
            } else {
                row[u] = tsdf::invalidPoint();
            }
        }
    });
    *normals_C = PointImage(w, h, std::move(normals));
}

Result<FramePyramid> preprocess(const DepthImage& depth, const PinholeCamera& camera,
                                const PreprocessConfig& config) {
    PLUMB_RETURN_IF_ERROR(config.validate());
    if (depth.width() != camera.width || depth.height() != camera.height) {
        return invalidArgument("preprocess: depth is " + std::to_string(depth.width()) + "x" +
                               std::to_string(depth.height()) + " but the camera is " +
                               camera.toString());
    }
    FramePyramid pyramid;
    pyramid.depth = gateDepth(depth, config);
    int num_levels = 1;
    while (num_levels < config.num_levels &&
           (camera.width >> num_levels) >= config.min_level_width_px) {
        ++num_levels;
    }
    pyramid.levels.resize(static_cast<size_t>(num_levels));
    for (int l = 0; l < num_levels; ++l) {
        PyramidLevel& level = pyramid.levels[static_cast<size_t>(l)];
        if (l == 0) {
            level.camera = camera;
            level.depth = config.bilateral ? bilateralFilter(pyramid.depth, config) : pyramid.depth;
        } else {
            const PyramidLevel& finer = pyramid.levels[static_cast<size_t>(l - 1)];
            level.camera = finer.camera.scaled(0.5);
            level.depth =
                downsampleDepth(finer.depth, config.bilateral_sigma_depth_m, config.num_threads);
            level.camera.width = level.depth.width();
            level.camera.height = level.depth.height();
        }
        computeVertexNormalMaps(level.depth, level.camera, config.max_normal_depth_jump_m,
                                &level.points_C, &level.normals_C, config.num_threads);
    }
    return pyramid;
}

}  // namespace plumb::device
