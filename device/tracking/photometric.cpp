// SPDX-License-Identifier: Apache-2.0
#include "device/tracking/photometric.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include "common/core/parallel.hpp"

namespace plumb::device {
namespace {

/// Separable Gaussian blur with edge clamping.
Image<float> gaussianBlur(const Image<float>& in, float sigma_px, int num_threads) {
    if (!(sigma_px > 0.0f)) return in;
    const int radius = std::max(1, static_cast<int>(std::ceil(2.0f * sigma_px)));
    std::vector<float> k(static_cast<size_t>(2 * radius + 1));
    float sum = 0.0f;
    for (int i = -radius; i <= radius; ++i) {
        const float w = std::exp(-0.5f * static_cast<float>(i * i) / (sigma_px * sigma_px));
        k[static_cast<size_t>(i + radius)] = w;
        sum += w;
    }
    for (float& w : k) w /= sum;
    const int w = in.width(), h = in.height();
    Image<float> tmp(w, h), out(w, h);
    // Each output pixel sums k[i] * sample over i = 0 .. 2 radius in that order, the samples
    // clamped to the image; the loops run over whole rows per tap so that they vectorise.
    const int lo = std::min(radius, w), hi = std::max(lo, w - radius);  // [lo, hi): no clamping
    parallelFor(num_threads, h, [&](int v) {
        const float* src = &in(0, v);
        float* dst = &tmp(0, v);
        for (int u = 0; u < w; ++u) dst[u] = 0.0f;
        for (int i = -radius; i <= radius; ++i) {
            const float ki = k[static_cast<size_t>(i + radius)];
            for (int u = lo; u < hi; ++u) dst[u] += ki * src[u + i];
            for (int u = 0; u < lo; ++u) dst[u] += ki * src[std::clamp(u + i, 0, w - 1)];
            for (int u = hi; u < w; ++u) dst[u] += ki * src[std::clamp(u + i, 0, w - 1)];
        }
    });
    parallelFor(num_threads, h, [&](int v) {
        float* dst = &out(0, v);
        for (int u = 0; u < w; ++u) dst[u] = 0.0f;
        for (int i = -radius; i <= radius; ++i) {
            const float ki = k[static_cast<size_t>(i + radius)];
            const float* src = &tmp(0, std::clamp(v + i, 0, h - 1));
            for (int u = 0; u < w; ++u) dst[u] += ki * src[u];
        }
    });
    return out;
}

/// Intensity (image.hpp intensity()) of every pixel, rows in parallel.
Image<float> intensityOf(const ColourImage& colour, int num_threads) {
    Image<float> out(colour.width(), colour.height());
    const int w = colour.width();
    parallelFor(num_threads, colour.height(), [&](int v) {
        for (int u = 0; u < w; ++u) out(u, v) = intensity(colour(u, v));
    });
    return out;
}

/// 2x2 mean to the given size (pixel centres kept: level l+1 pixel u covers 2u and 2u+1).
Image<float> halve(const Image<float>& in, int w, int h, int num_threads) {
    Image<float> out(w, h);
    parallelFor(num_threads, h, [&](int v) {
        for (int u = 0; u < w; ++u) {
            out(u, v) = 0.25f * (in(2 * u, 2 * v) + in(2 * u + 1, 2 * v) + in(2 * u, 2 * v + 1) +
                                 in(2 * u + 1, 2 * v + 1));
        }
    });
    return out;
}

/// Central-difference gradients; one-sided at the border.
void gradients(const Image<float>& I, Image<float>* gu, Image<float>* gv, int num_threads) {
    const int w = I.width(), h = I.height();
    *gu = Image<float>(w, h);
    *gv = Image<float>(w, h);
    parallelFor(num_threads, h, [&](int v) {
        const int v0 = std::max(v - 1, 0), v1 = std::min(v + 1, h - 1);
        for (int u = 0; u < w; ++u) {
            const int u0 = std::max(u - 1, 0), u1 = std::min(u + 1, w - 1);
            (*gu)(u, v) = (I(u1, v) - I(u0, v)) / static_cast<float>(std::max(u1 - u0, 1));
            (*gv)(u, v) = (I(u, v1) - I(u, v0)) / static_cast<float>(std::max(v1 - v0, 1));
        }
    });
}

/// What one reference point contributes: the warped pixel, residual and Jacobian.
struct Term {
    float r = 0.0f;
    float I_c = 0.0f;  ///< the current intensity at the warped pixel (before brightness)
    float J[6] = {};
};

/// Eq. (7b.1) and its Jacobian; `R_C_M`, `t_C_M` = T_C_M, `q` = T_M_R p_R.
bool evaluate(const Eigen::Vector3f& q, float I_ref, const IntensityLevel& cur,
              const Eigen::Matrix3f& R_C_M, const Eigen::Vector3f& t_C_M, float a, float b,
              Term* term) {
    const Eigen::Vector3f p = R_C_M * q + t_C_M;
    if (!(p.z() > 1e-3f)) return false;
    const PinholeCamera& cam = cur.camera;
    const float inv_z = 1.0f / p.z();
    const float fx = static_cast<float>(cam.fx), fy = static_cast<float>(cam.fy);
    const float x = fx * p.x() * inv_z + static_cast<float>(cam.cx);
    const float y = fy * p.y() * inv_z + static_cast<float>(cam.cy);
    float I = 0.0f, gx = 0.0f, gy = 0.0f;
    if (!sampleBilinear(cur.intensity, x, y, &I)) return false;
    sampleBilinear(cur.grad_u, x, y, &gx);
    sampleBilinear(cur.grad_v, x, y, &gy);
    term->I_c = I;
    term->r = a * I + b - I_ref;
    // g = a (d pi / d p)^T grad I, d pi / d p = [fx/z, 0, -fx x/z^2; 0, fy/z, -fy y/z^2].
    const float ax = a * gx * fx * inv_z, ay = a * gy * fy * inv_z;
    const Eigen::Vector3f g(ax, ay, -(ax * p.x() + ay * p.y()) * inv_z);
    const Eigen::Vector3f h = R_C_M.transpose() * g;  // h = R_M_C g
    const Eigen::Vector3f hq = h.cross(q);
    term->J[0] = hq.x();
    term->J[1] = hq.y();
    term->J[2] = hq.z();
    term->J[3] = -h.x();
    term->J[4] = -h.y();
    term->J[5] = -h.z();
    return true;
}

}  // namespace

Status PhotometricConfig::validate() const {
    if (!(weight >= 0.0)) return invalidArgument("tracking: weight must be >= 0");
    if (!(depth_sigma_m > 0.0)) return invalidArgument("tracking: depth_sigma_m must be > 0");
    if (!(intensity_sigma > 0.0)) return invalidArgument("tracking: intensity_sigma must be > 0");
    if (!(huber_delta > 0.0f)) return invalidArgument("tracking: huber_delta must be > 0");
    if (!(max_residual >= huber_delta)) {
        return invalidArgument("tracking: max_residual must be >= huber_delta");
    }
    if (!(min_gradient >= 0.0f)) return invalidArgument("tracking: min_gradient must be >= 0");
    if (max_points < 1) return invalidArgument("tracking: max_points must be >= 1");
    if (min_points < 0) return invalidArgument("tracking: min_points must be >= 0");
    if (!(min_inlier_fraction >= 0.0 && min_inlier_fraction <= 1.0)) {
        return invalidArgument("tracking: min_inlier_fraction must be in [0, 1]");
    }
    if (!(smoothing_sigma_px >= 0.0f && smoothing_sigma_px <= 5.0f)) {
        return invalidArgument("tracking: smoothing_sigma_px must be in [0, 5]");
    }
    return Status::ok();
}

bool sampleBilinear(const Image<float>& image, float x, float y, float* value) {
    const int w = image.width(), h = image.height();
    if (!(x >= 0.0f && y >= 0.0f && x <= static_cast<float>(w - 1) &&
          y <= static_cast<float>(h - 1))) {
        return false;
    }
    const int u0 = std::min(static_cast<int>(x), w - 2), v0 = std::min(static_cast<int>(y), h - 2);
    const float fu = x - static_cast<float>(u0), fv = y - static_cast<float>(v0);
    const float* row0 = image.data() + static_cast<size_t>(v0) * w + u0;
    const float* row1 = row0 + w;
    const float top = row0[0] + fu * (row0[1] - row0[0]);
    const float bottom = row1[0] + fu * (row1[1] - row1[0]);
    *value = top + fv * (bottom - top);
    return true;
}

IntensityLevel makeIntensityLevel(const PinholeCamera& camera, Image<float> intensity,
                                  int num_threads) {
    IntensityLevel level;
    level.camera = camera;
    level.intensity = std::move(intensity);
    gradients(level.intensity, &level.grad_u, &level.grad_v, num_threads);
    return level;
}

std::vector<IntensityLevel> buildIntensityPyramid(const ColourImage& colour,
                                                  const FramePyramid& frame,
                                                  const PhotometricConfig& config,
                                                  int num_threads) {
    PLUMB_CHECK(!frame.levels.empty()) << "empty frame pyramid";
    PLUMB_CHECK(colour.width() == frame.levels[0].camera.width &&
                colour.height() == frame.levels[0].camera.height)
        << "colour " << colour.width() << "x" << colour.height() << " for camera "
        << frame.levels[0].camera.toString();
    std::vector<IntensityLevel> levels(frame.levels.size());
    for (size_t l = 0; l < levels.size(); ++l) {
        const PinholeCamera& camera = frame.levels[l].camera;
        levels[l] = makeIntensityLevel(
            camera,
            l == 0 ? gaussianBlur(intensityOf(colour, num_threads), config.smoothing_sigma_px,
                                  num_threads)
                   : halve(levels[l - 1].intensity, camera.width, camera.height, num_threads),
            num_threads);
    }
    return levels;
}

PhotometricReference selectReference(const FramePyramid& frame,
                                     const std::vector<IntensityLevel>& intensity,
                                     const PhotometricConfig& config, int num_threads) {
    PLUMB_CHECK(intensity.size() == frame.levels.size())
        << intensity.size() << " intensity levels for " << frame.levels.size() << " depth levels";
    PhotometricReference ref;
    ref.levels.resize(frame.levels.size());
    ref.level_scale.assign(frame.levels.size(), 1.0);
    const float min_g2 = config.min_gradient * config.min_gradient;
    for (size_t l = 0; l < frame.levels.size(); ++l) {
        const PyramidLevel& depth = frame.levels[l];
        const IntensityLevel& I = intensity[l];
        const int w = depth.depth.width(), h = depth.depth.height();
        // One pixel border: its gradient is one-sided. Fixed chunks of rows, joined in row
        // order: raster order whatever the thread count.
        constexpr int kRowsPerChunk = 16;
        const int num_chunks = (h + kRowsPerChunk - 1) / kRowsPerChunk;
        std::vector<std::vector<size_t>> chunks(static_cast<size_t>(num_chunks));
        parallelFor(num_threads, num_chunks, [&](int c) {
            std::vector<size_t>& chunk = chunks[static_cast<size_t>(c)];
            const int v_end = std::min(h - 1, (c + 1) * kRowsPerChunk);
            for (int v = std::max(1, c * kRowsPerChunk); v < v_end; ++v) {
                for (int u = 1; u + 1 < w; ++u) {
                    if (!tsdf::isValid(depth.points_C(u, v))) continue;
                    const float gu = I.grad_u(u, v), gv = I.grad_v(u, v);
                    if (gu * gu + gv * gv < min_g2) continue;
                    chunk.push_back(static_cast<size_t>(v) * w + u);
                }
            }
        });
        std::vector<size_t> selected;
        for (const std::vector<size_t>& chunk : chunks) {
            selected.insert(selected.end(), chunk.begin(), chunk.end());
        }
        if (l == 0) ref.num_selected = selected.size();
        // Thin evenly to max_points: every (n / max_points)-th pixel in raster order.
        const size_t n = selected.size(),
                     keep = std::min(n, static_cast<size_t>(config.max_points));
        std::vector<ReferencePoint>& out = ref.levels[l];
        if (keep > 0) ref.level_scale[l] = static_cast<double>(n) / static_cast<double>(keep);
        out.reserve(keep);
        for (size_t i = 0; i < keep; ++i) {
            const size_t idx = selected[i * n / keep];
            out.push_back({depth.points_C.data()[idx], I.intensity.data()[idx]});
        }
    }
    return ref;
}

bool photometricResidual(const ReferencePoint& point, const IntensityLevel& current,
                         const Eigen::Isometry3d& T_M_R, const Eigen::Isometry3d& T_M_C,
                         const Brightness& br, double* r, Vector6d* J) {
    const Eigen::Isometry3d T_C_M = T_M_C.inverse();
    const Eigen::Vector3f q = (T_M_R.cast<float>() * point.p_R);
    Term term;
    if (!evaluate(q, point.intensity, current, T_C_M.linear().cast<float>(),
                  T_C_M.translation().cast<float>(), static_cast<float>(br.a),
                  static_cast<float>(br.b), &term)) {
        return false;
    }
    *r = term.r;
    for (int i = 0; i < 6; ++i) (*J)(i) = term.J[i];
    return true;
}

PhotometricSystem buildPhotometricSystem(const std::vector<ReferencePoint>& reference,
                                         const IntensityLevel& current,
                                         const Eigen::Isometry3d& T_M_R,
                                         const Eigen::Isometry3d& T_M_C, const Brightness& br,
                                         const PhotometricConfig& config, int num_threads) {
    const Eigen::Isometry3d T_C_M = T_M_C.inverse();
    const Eigen::Matrix3f R_C_M = T_C_M.linear().cast<float>();
    const Eigen::Vector3f t_C_M = T_C_M.translation().cast<float>();
    const Eigen::Matrix3f R_M_R = T_M_R.linear().cast<float>();
    const Eigen::Vector3f t_M_R = T_M_R.translation().cast<float>();
    const float a = static_cast<float>(br.a), b = static_cast<float>(br.b);
    const float delta = config.huber_delta, max_r = config.max_residual;
    // Per chunk: 21 + 6 + 1 entries of the system, 5 sums of the brightness fit (w, w I_c,
    // w I_c^2, w I_r, w I_c I_r), 3 counts; chunks are added in order (deterministic).
    constexpr int kChunk = 512;
    const int n = static_cast<int>(reference.size());
    const int num_chunks = (n + kChunk - 1) / kChunk;
    struct Sums {
        std::array<double, 33> s{};
        size_t visible = 0, used = 0, inliers = 0;
    };
    std::vector<Sums> chunks(static_cast<size_t>(num_chunks));
    parallelFor(num_threads, num_chunks, [&](int c) {
        std::array<float, 33> f{};
        Sums& out = chunks[static_cast<size_t>(c)];
        const int end = std::min(n, (c + 1) * kChunk);
        for (int i = c * kChunk; i < end; ++i) {
            const ReferencePoint& rp = reference[static_cast<size_t>(i)];
            const Eigen::Vector3f q = R_M_R * rp.p_R + t_M_R;
            Term t;
            if (!evaluate(q, rp.intensity, current, R_C_M, t_C_M, a, b, &t)) continue;
            ++out.visible;
            const float abs_r = std::abs(t.r);
            if (abs_r > max_r) continue;
            ++out.used;
            if (abs_r <= delta) ++out.inliers;
            const float w = abs_r <= delta ? 1.0f : delta / abs_r;  // Huber
            int k = 0;
            for (int p = 0; p < 6; ++p) {
                const float wj = w * t.J[p];
                for (int q2 = p; q2 < 6; ++q2) f[static_cast<size_t>(k++)] += wj * t.J[q2];
            }
            for (int p = 0; p < 6; ++p) f[static_cast<size_t>(21 + p)] += w * t.J[p] * t.r;
            f[27] += w * t.r * t.r;
            f[28] += w;
            f[29] += w * t.I_c;
            f[30] += w * t.I_c * t.I_c;
            f[31] += w * rp.intensity;
            f[32] += w * t.I_c * rp.intensity;
        }
        for (size_t k = 0; k < f.size(); ++k) out.s[k] = f[k];
    });
    std::array<double, 33> s{};
    PhotometricSystem sys;
    for (const Sums& c : chunks) {
        for (size_t k = 0; k < s.size(); ++k) s[k] += c.s[k];
        sys.num_visible += c.visible;
        sys.num_used += c.used;
        sys.num_inliers += c.inliers;
    }
    int k = 0;
    for (int p = 0; p < 6; ++p) {
        for (int q2 = p; q2 < 6; ++q2) {
            sys.JtJ(p, q2) = s[static_cast<size_t>(k)];
            sys.JtJ(q2, p) = s[static_cast<size_t>(k)];
            ++k;
        }
    }
    for (int p = 0; p < 6; ++p) sys.Jtr(p) = s[static_cast<size_t>(21 + p)];
    sys.r2 = s[27];
    // Weighted least squares I_r = a I_c + b over the used points; kept when well posed.
    sys.brightness = br;
    const double sw = s[28], sc = s[29], scc = s[30], sr = s[31], scr = s[32];
    const double det = sw * scc - sc * sc;
    if (sw > 50.0 && det > 1e-6 * sw * sw) {
        const double a_fit = (sw * scr - sc * sr) / det;
        if (a_fit > 0.5 && a_fit < 2.0) sys.brightness = {a_fit, (sr - a_fit * sc) / sw};
    }
    return sys;
}

}  // namespace plumb::device
