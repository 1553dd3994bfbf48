// SPDX-License-Identifier: Apache-2.0
#include "device/tracking/icp.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <optional>
#include <string>
#include <utility>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "common/core/parallel.hpp"
#include "common/core/simd.hpp"
#include "common/geometry/solution_remapping.hpp"

namespace plumb::device {
namespace {

/// Normal equations of one chunk of rows; summed in chunk order for determinism.
struct Accumulator {
    Matrix6d JtJ = Matrix6d::Zero();
    Vector6d Jtr = Vector6d::Zero();
    double r2 = 0.0;
    size_t count = 0;
};

static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "point images are 3 floats a pixel");

/// What the correspondence search needs, in plain floats (no Eigen in the AVX2 kernel).
struct CorrespondenceParams {
    float R[9], t[3];            ///< T_M_C, row-major rotation
    float R_pm[9], t_pm[3];      ///< T_P_M
    float fx, fy, cx, cy;        ///< model camera
    int mw, mh;                  ///< model image size
    float max_d2, min_cos;       ///< gates
    const float* model_normals;  ///< model images, 3 floats a pixel
    const float* model_points;
};

#if defined(__x86_64__) && defined(__GNUC__)
/// m[0] a + (m[1] b + m[2] d): one row of a 3x3 product, in Eigen's order.
__attribute__((target("avx2"), always_inline)) inline __m256 row(const float* m, __m256 a, __m256 b,
                                                                 __m256 d) {
    return _mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(m[0]), a),
                         _mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(m[1]), b),
                                       _mm256_mul_ps(_mm256_set1_ps(m[2]), d)));
}

/// Steps 1-2 for 8 consecutive frame pixels in AVX2 lanes: transform, projective association and
/// the gates, with the same operations in the same order as the scalar loop (Eigen evaluates
/// a 3x3 product row as a0 + (a1 + a2), and a dot product the same way; no FMA), so the same
/// pixels pass. Returns the mask of the lanes that pass and their model pixels.
__attribute__((target("avx2"))) unsigned correspondencesAvx2(const CorrespondenceParams& c,
                                                             const float* normals,
                                                             const float* points,
                                                             int32_t* model_pixel) {
    const __m256i idx3 = _mm256_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21);
    const __m256 nx = _mm256_i32gather_ps(normals, idx3, 4);
    const __m256 ny = _mm256_i32gather_ps(normals + 1, idx3, 4);
    const __m256 nz = _mm256_i32gather_ps(normals + 2, idx3, 4);
    __m256 ok = _mm256_cmp_ps(nx, nx, _CMP_ORD_Q);  // valid normal
    if (_mm256_movemask_ps(ok) == 0) return 0;
    const __m256 px = _mm256_i32gather_ps(points, idx3, 4);
    const __m256 py = _mm256_i32gather_ps(points + 1, idx3, 4);
    const __m256 pz = _mm256_i32gather_ps(points + 2, idx3, 4);
    const __m256 x0 = _mm256_add_ps(row(c.R, px, py, pz), _mm256_set1_ps(c.t[0]));
    const __m256 x1 = _mm256_add_ps(row(c.R + 3, px, py, pz), _mm256_set1_ps(c.t[1]));
    const __m256 x2 = _mm256_add_ps(row(c.R + 6, px, py, pz), _mm256_set1_ps(c.t[2]));
    const __m256 xp0 = _mm256_add_ps(row(c.R_pm, x0, x1, x2), _mm256_set1_ps(c.t_pm[0]));
    const __m256 xp1 = _mm256_add_ps(row(c.R_pm + 3, x0, x1, x2), _mm256_set1_ps(c.t_pm[1]));
    const __m256 xp2 = _mm256_add_ps(row(c.R_pm + 6, x0, x1, x2), _mm256_set1_ps(c.t_pm[2]));
    ok = _mm256_and_ps(ok, _mm256_cmp_ps(xp2, _mm256_setzero_ps(), _CMP_NLE_UQ));
    const __m256 inv_z = _mm256_div_ps(_mm256_set1_ps(1.0f), xp2);
    const __m256 half = _mm256_set1_ps(0.5f);
    const __m256i mu = _mm256_cvttps_epi32(_mm256_floor_ps(
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(c.fx), xp0), inv_z),
                                    _mm256_set1_ps(c.cx)),
                      half)));
    const __m256i mv = _mm256_cvttps_epi32(_mm256_floor_ps(
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(c.fy), xp1), inv_z),
                                    _mm256_set1_ps(c.cy)),
                      half)));
    const __m256i minus1 = _mm256_set1_epi32(-1);
    const __m256i inside = _mm256_and_si256(
        _mm256_and_si256(_mm256_cmpgt_epi32(mu, minus1), _mm256_cmpgt_epi32(mv, minus1)),
        _mm256_and_si256(_mm256_cmpgt_epi32(_mm256_set1_epi32(c.mw), mu),
                         _mm256_cmpgt_epi32(_mm256_set1_epi32(c.mh), mv)));
    ok = _mm256_and_ps(ok, _mm256_castsi256_ps(inside));
    if (_mm256_movemask_ps(ok) == 0) return 0;
    // Model pixel of each lane (0 where the lane already failed: a valid address to gather).
    const __m256i mp =
        _mm256_and_si256(_mm256_castps_si256(ok),
                         _mm256_add_epi32(_mm256_mullo_epi32(mv, _mm256_set1_epi32(c.mw)), mu));
    const __m256i mp3 = _mm256_add_epi32(_mm256_add_epi32(mp, mp), mp);
    const __m256 mnx = _mm256_i32gather_ps(c.model_normals, mp3, 4);
    ok = _mm256_and_ps(ok, _mm256_cmp_ps(mnx, mnx, _CMP_ORD_Q));
    if (_mm256_movemask_ps(ok) == 0) return 0;
    const __m256 mny = _mm256_i32gather_ps(c.model_normals + 1, mp3, 4);
    const __m256 mnz = _mm256_i32gather_ps(c.model_normals + 2, mp3, 4);
    const __m256 d0 = _mm256_sub_ps(x0, _mm256_i32gather_ps(c.model_points, mp3, 4));
    const __m256 d1 = _mm256_sub_ps(x1, _mm256_i32gather_ps(c.model_points + 1, mp3, 4));
    const __m256 d2 = _mm256_sub_ps(x2, _mm256_i32gather_ps(c.model_points + 2, mp3, 4));
    const __m256 dist2 = _mm256_add_ps(_mm256_mul_ps(d0, d0),
                                       _mm256_add_ps(_mm256_mul_ps(d1, d1), _mm256_mul_ps(d2, d2)));
    ok = _mm256_and_ps(ok, _mm256_cmp_ps(dist2, _mm256_set1_ps(c.max_d2), _CMP_NGT_UQ));
    const __m256 rn0 = row(c.R, nx, ny, nz);
    const __m256 rn1 = row(c.R + 3, nx, ny, nz);
    const __m256 rn2 = row(c.R + 6, nx, ny, nz);
    const __m256 cosine = _mm256_add_ps(
        _mm256_mul_ps(rn0, mnx), _mm256_add_ps(_mm256_mul_ps(rn1, mny), _mm256_mul_ps(rn2, mnz)));
    ok = _mm256_and_ps(ok, _mm256_cmp_ps(cosine, _mm256_set1_ps(c.min_cos), _CMP_NLT_UQ));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(model_pixel), mp);
    return static_cast<unsigned>(_mm256_movemask_ps(ok));
}
#endif

Accumulator buildSystem(const PyramidLevel& level, const ModelLevel& model,
                        const Eigen::Isometry3d& T_M_C, const Eigen::Isometry3d& T_P_M,
                        const IcpConfig& config) {
    const int w = level.depth.width(), h = level.depth.height();
    const Eigen::Matrix3f R = T_M_C.linear().cast<float>();
    const Eigen::Vector3f t = T_M_C.translation().cast<float>();
    const Eigen::Matrix3f R_pm = T_P_M.linear().cast<float>();
    const Eigen::Vector3f t_pm = T_P_M.translation().cast<float>();
    const float fx = static_cast<float>(model.camera.fx), fy = static_cast<float>(model.camera.fy);
    const float cx = static_cast<float>(model.camera.cx), cy = static_cast<float>(model.camera.cy);
    const int mw = model.camera.width, mh = model.camera.height;
    const float max_d2 = config.max_distance_m * config.max_distance_m;
    const float min_cos =
        std::cos(config.max_normal_angle_deg * std::numbers::pi_v<float> / 180.0f);
    constexpr int kRowsPerChunk = 8;
    const int num_chunks = (h + kRowsPerChunk - 1) / kRowsPerChunk;
    std::vector<Accumulator> chunks(static_cast<size_t>(num_chunks));
    const bool use_avx2 = simd::best() == simd::Level::kAvx2;
    CorrespondenceParams cp{};
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
            cp.R[3 * i + j] = R(i, j);
            cp.R_pm[3 * i + j] = R_pm(i, j);
        }
        cp.t[i] = t[i];
        cp.t_pm[i] = t_pm[i];
    }
    cp.fx = fx;
    cp.fy = fy;
    cp.cx = cx;
    cp.cy = cy;
    cp.mw = mw;
    cp.mh = mh;
    cp.max_d2 = max_d2;
    cp.min_cos = min_cos;
    cp.model_normals = reinterpret_cast<const float*>(model.normals_M.data());
    cp.model_points = reinterpret_cast<const float*>(model.points_M.data());
    parallelFor(config.num_threads, num_chunks, [&](int c) {
        Accumulator& acc = chunks[static_cast<size_t>(c)];
        // Per row: the 21 upper-triangular entries of J^T J, the 6 of J^T r and r^2 summed in
        // float (at most one image row of terms), then added to the chunk's double sums.
        std::array<double, 28> chunk_sum{};
        const int v_end = std::min(h, (c + 1) * kRowsPerChunk);
        for (int v = c * kRowsPerChunk; v < v_end; ++v) {
            std::array<float, 28> row{};
            size_t row_count = 0;
            // Step 3 for one correspondence: r = n^T (x - v), J = [(x x n)^T, n^T].
            const auto add = [&](const Eigen::Vector3f& x, const Eigen::Vector3f& nm,
                                 const Eigen::Vector3f& diff) {
                const float r = nm.dot(diff);
                const Eigen::Vector3f xn = x.cross(nm);
                const float J[6] = {xn.x(), xn.y(), xn.z(), nm.x(), nm.y(), nm.z()};
                int k = 0;
                for (int i = 0; i < 6; ++i) {
                    for (int j = i; j < 6; ++j) row[static_cast<size_t>(k++)] += J[i] * J[j];
                }
                for (int i = 0; i < 6; ++i) row[static_cast<size_t>(21 + i)] += J[i] * r;
                row[27] += r * r;
                ++row_count;
            };
            int u = 0;
#if defined(__x86_64__) && defined(__GNUC__)
            if (use_avx2) {
                // Steps 1-2 for 8 pixels at a time in AVX2 lanes, step 3 for the lanes that pass,
                // in pixel order (the sums are those of the scalar loop, bit for bit).
                for (; u + 8 <= w; u += 8) {
                    int32_t model_pixel[8];
                    const unsigned pass = correspondencesAvx2(
                        cp, reinterpret_cast<const float*>(&level.normals_C(u, v)),
                        reinterpret_cast<const float*>(&level.points_C(u, v)), model_pixel);
                    for (unsigned lanes = pass; lanes != 0; lanes &= lanes - 1) {
                        const int k = __builtin_ctz(lanes);
                        const Eigen::Vector3f x = R * level.points_C(u + k, v) + t;
                        const auto mp = static_cast<size_t>(model_pixel[k]);
                        const Eigen::Vector3f& nm = model.normals_M.data()[mp];
                        add(x, nm, x - model.points_M.data()[mp]);
                    }
                }
            }
#endif
            for (; u < w; ++u) {
                const Eigen::Vector3f& n = level.normals_C(u, v);
                if (!tsdf::isValid(n)) continue;
                const Eigen::Vector3f& p = level.points_C(u, v);
                const Eigen::Vector3f x = R * p + t;  // step 1: x = T V_k(u)
                const Eigen::Vector3f x_p = R_pm * x + t_pm;
                if (x_p.z() <= 0.0f) continue;
                const float inv_z = 1.0f / x_p.z();
                const int mu = static_cast<int>(std::floor(fx * x_p.x() * inv_z + cx + 0.5f));
                const int mv = static_cast<int>(std::floor(fy * x_p.y() * inv_z + cy + 0.5f));
                if (mu < 0 || mv < 0 || mu >= mw || mv >= mh) continue;
                const Eigen::Vector3f& nm = model.normals_M(mu, mv);
                if (!tsdf::isValid(nm)) continue;
                const Eigen::Vector3f diff = x - model.points_M(mu, mv);  // step 2: gates
                if (diff.squaredNorm() > max_d2) continue;
                if ((R * n).dot(nm) < min_cos) continue;
                add(x, nm, diff);  // step 3
            }
            for (size_t i = 0; i < 28; ++i) chunk_sum[i] += static_cast<double>(row[i]);
            acc.count += row_count;
        }
        int k = 0;
        for (int i = 0; i < 6; ++i) {
            for (int j = i; j < 6; ++j) {
                acc.JtJ(i, j) = chunk_sum[static_cast<size_t>(k)];
                acc.JtJ(j, i) = chunk_sum[static_cast<size_t>(k)];
                ++k;
            }
        }
        for (int i = 0; i < 6; ++i) acc.Jtr(i) = chunk_sum[static_cast<size_t>(21 + i)];
        acc.r2 = chunk_sum[27];
    });
    Accumulator total;
    for (const Accumulator& a : chunks) {
        total.JtJ += a.JtJ;
        total.Jtr += a.Jtr;
        total.r2 += a.r2;
        total.count += a.count;
    }
    return total;
}

size_t countValidNormals(const PyramidLevel& level) {
    size_t n = 0;
    for (const auto& v : level.normals_C.pixels()) n += tsdf::isValid(v) ? 1 : 0;
    return n;
}

/// Eigen-decomposition of sum n n^T / inliers (the translation block of J^T J per inlier): its
/// eigenvalues are the mean (n.t)^2 along its axes t, compared with min_normal_spread.
Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> translationSpread(const Accumulator& sys) {
    return Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(sys.JtJ.bottomRightCorner<3, 3>() *
                                                          (1.0 / static_cast<double>(sys.count)));
}

/// Step 4: (sum J^T J) xi = -sum J^T r, solved with solution remapping (Zhang, Kaess, Singh, ICRA
/// 2016): directions the data does not constrain keep the prediction instead of following noise.
/// They are (a) translations along axes t of sum n n^T / inliers with mean (n.t)^2 below
/// min_normal_spread -- sliding along a wall, down a corridor, along the line where a wall meets
/// the floor -- removed before the solve, and (b) eigen-directions of the remaining system whose
/// eigenvalue per inlier is below min_normalized_eigenvalue. The (a) translations keep the current
/// pose; the (b) directions move to `xi_prior`, the left twist from the current pose to the prior
/// pose (the prediction with its weakly observed motion decayed, see IcpConfig).
Vector6d solveStep(const Accumulator& sys, const Vector6d& xi_prior, const IcpConfig& config) {
    const double per_inlier = 1.0 / static_cast<double>(sys.count);
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> spread = translationSpread(sys);
    // The directions solved for: the three rotations and the constrained translations.
    using Square = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 6, 6>;
    using Vector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 6, 1>;
    const remapping::Basis basis = remapping::solvedDirections(spread, config.min_normal_spread);
    const int k = static_cast<int>(basis.cols());
    const Square H = basis.transpose() * sys.JtJ * basis;
    const Vector g = basis.transpose() * (-sys.Jtr);
    const Eigen::SelfAdjointEigenSolver<Square> es(H);
    const Vector b = es.eigenvectors().transpose() * g;
    const Vector prior = es.eigenvectors().transpose() * (basis.transpose() * xi_prior);
    Vector y = Vector::Zero(k);
    for (int i = 0; i < k; ++i) {
        const double ev = es.eigenvalues()(i);
        const bool constrained = ev * per_inlier >= config.min_normalized_eigenvalue;
        y += es.eigenvectors().col(i) * (constrained ? b(i) / ev : prior(i));
    }
    return basis * y;
}

}  // namespace

std::vector<ModelLevel> predictModel(const tsdf::TsdfVolume& volume, const FramePyramid& frame,
                                     const Eigen::Isometry3d& T_M_P,
                                     const tsdf::RaycastConfig& config, int raycast_level,
                                     const DepthImage* start_hint) {
    // One raycast at level `raycast_level`; finer levels use it as it is (projective association
    // looks up the model in its own camera, and a point-to-plane residual does not change when
    // the model point slides along its plane), coarser levels average the valid points (and
    // normals) of each 2x2 block of the finer level that lie within 3 cm of its first valid
    // point, as the frame pyramid does for depth (KinFu's resized vertex and normal maps).
    PLUMB_CHECK(!frame.levels.empty()) << "empty frame pyramid";
    const size_t cast =
        std::min(static_cast<size_t>(std::max(raycast_level, 0)), frame.levels.size() - 1);
    std::vector<ModelLevel> model(frame.levels.size());
    {
        ModelLevel& m = model[cast];
        m.camera = frame.levels[cast].camera;
        tsdf::RaycastResult r = tsdf::raycast(volume, m.camera, T_M_P, config, start_hint);
        m.points_M = std::move(r.points_V);
        m.normals_M = std::move(r.normals_V);
    }
    for (size_t l = 0; l < cast; ++l) model[l] = model[cast];
    for (size_t l = cast + 1; l < frame.levels.size(); ++l) {
        model[l].camera = frame.levels[l].camera;
        const ModelLevel& finer = model[l - 1];
        const int w = model[l].camera.width, h = model[l].camera.height;
        model[l].points_M = PointImage(w, h, tsdf::invalidPoint());
        model[l].normals_M = PointImage(w, h, tsdf::invalidPoint());
        const int fw = finer.points_M.width(), fh = finer.points_M.height();
        parallelFor(config.num_threads, h, [&](int v) {
            for (int u = 0; u < w; ++u) {
                Eigen::Vector3f ps = Eigen::Vector3f::Zero(), ns = Eigen::Vector3f::Zero();
                const Eigen::Vector3f* ref = nullptr;
                int n = 0;
                for (int k = 0; k < 4; ++k) {
                    const int x = 2 * u + (k & 1), y = 2 * v + (k >> 1);
                    if (x >= fw || y >= fh) continue;
                    const Eigen::Vector3f& p = finer.points_M(x, y);
                    const Eigen::Vector3f& nn = finer.normals_M(x, y);
                    if (!tsdf::isValid(p) || !tsdf::isValid(nn)) continue;
                    if (ref == nullptr) ref = &p;
                    if ((p - *ref).squaredNorm() > 0.03f * 0.03f) continue;
                    ps += p;
                    ns += nn;
                    ++n;
                }
                if (n == 0 || !(ns.squaredNorm() > 0.0f)) continue;
                model[l].points_M(u, v) = ps / static_cast<float>(n);
                model[l].normals_M(u, v) = ns.normalized();
            }
        });
    }
    return model;
}

Status IcpConfig::validate() const {
    for (int it : iterations) {
        if (it < 0 || it > 100) return invalidArgument("icp: iterations must be in [0, 100]");
    }
    if (!(max_distance_m > 0.0f)) return invalidArgument("icp: max_distance_m must be positive");
    if (!(max_normal_angle_deg > 0.0f && max_normal_angle_deg <= 90.0f)) {
        return invalidArgument("icp: max_normal_angle_deg must be in (0, 90]");
    }
    if (!(min_inlier_fraction >= 0.0 && min_inlier_fraction <= 1.0)) {
        return invalidArgument("icp: min_inlier_fraction must be in [0, 1]");
    }
    if (!(weak_motion_decay >= 0.0 && weak_motion_decay <= 1.0)) {
        return invalidArgument("icp: weak_motion_decay must be in [0, 1]");
    }
    return Status::ok();
}

namespace {

/// The system of one level: point-to-plane ICP plus, with colour, the photometric term weighed
/// into point-to-plane units (w = lambda (depth_sigma / intensity_sigma)^2, times the reference's
/// thinning scale). `count` stays the ICP's correspondence count.
struct LevelSystem {
    Accumulator combined;
    double icp_r2 = 0.0;  ///< the point-to-plane part of combined.r2
    PhotometricSystem photo;
};

LevelSystem buildLevelSystem(const FramePyramid& frame, const std::vector<ModelLevel>& model,
                             size_t l, const Eigen::Isometry3d& T, const Eigen::Isometry3d& T_P_M,
                             const IcpConfig& config, const PhotometricInput* ph,
                             const Brightness& br) {
    LevelSystem s;
    s.combined = buildSystem(frame.levels[l], model[l], T, T_P_M, config);
    s.icp_r2 = s.combined.r2;
    if (ph == nullptr) return s;
    const PhotometricConfig& pc = ph->config;
    s.photo = buildPhotometricSystem(ph->reference->levels[l], (*ph->current)[l], ph->T_M_R, T, br,
                                     pc, config.num_threads);
    const double ratio = pc.depth_sigma_m / pc.intensity_sigma;
    const double w = pc.weight * ratio * ratio * ph->reference->level_scale[l];
    s.combined.JtJ += w * s.photo.JtJ;
    s.combined.Jtr += w * s.photo.Jtr;
    s.combined.r2 += w * s.photo.r2;
    return s;
}

/// Coarse-to-fine Gauss-Newton with solution remapping; the photometric term joins every level
/// when `ph` is given.
IcpResult align(const FramePyramid& frame, const std::vector<ModelLevel>& model,
                const Eigen::Isometry3d& T_M_P, const Eigen::Isometry3d& T_M_C_init,
                const Eigen::Isometry3d& T_M_moved_from, const IcpConfig& config,
                const PhotometricInput* ph) {
    IcpResult result;
    Eigen::Isometry3d T = T_M_C_init;
    const Eigen::Isometry3d T_P_M = T_M_P.inverse();
    // The prior of the weakly observed directions: the predicted motion from the model pose,
    // scaled by weak_motion_decay (left twists, as the updates).
    const Eigen::Isometry3d T_prior =
        lie::expSE3(config.weak_motion_decay * lie::logSE3(T_M_C_init * T_P_M)) * T_M_P;
    const int num_levels = static_cast<int>(frame.levels.size());
    const bool affine = ph != nullptr && ph->config.affine_brightness;
    Brightness br;
    if (affine) {
        // The brightness of the frame at the start pose, from the coarsest level.
        const size_t l = static_cast<size_t>(num_levels - 1);
        br = buildPhotometricSystem(ph->reference->levels[l], (*ph->current)[l], ph->T_M_R, T, br,
                                    ph->config, config.num_threads)
                 .brightness;
    }
    // The finest level's system of the last iteration, when that iteration converged: the pose
    // then moved by less than min_update_norm and the system is the final statistics.
    std::optional<LevelSystem> converged;
    for (int l = num_levels - 1; l >= 0; --l) {
        const int iterations = l < 3 ? config.iterations[static_cast<size_t>(l)] : 4;
        for (int it = 0; it < iterations; ++it) {
            LevelSystem sys =
                buildLevelSystem(frame, model, static_cast<size_t>(l), T, T_P_M, config, ph, br);
            if (sys.combined.count < 6) break;
            ++result.iterations;
            if (affine) br = sys.photo.brightness;
            const Vector6d xi = solveStep(sys.combined, lie::logSE3(T_prior * T.inverse()), config);
            if (!xi.allFinite()) break;
            T = lie::orthonormalized(lie::expSE3(xi) * T);
            if (xi.norm() < config.min_update_norm) {
                if (l == 0) converged = std::move(sys);
                break;
            }
        }
    }
    // Final statistics at the finest level, at the final pose.
    const LevelSystem final_sys =
        converged ? *converged : buildLevelSystem(frame, model, 0, T, T_P_M, config, ph, br);
    const Accumulator& last = final_sys.combined;
    result.T_M_C = T;
    if (ph != nullptr) {
        PhotometricStats& st = result.photometric;
        const PhotometricSystem& p = final_sys.photo;
        st.used = true;
        st.num_selected = ph->reference->num_selected;
        st.num_visible = p.num_visible;
        st.num_inliers = p.num_inliers;
        st.inlier_fraction =
            p.num_visible > 0 ? static_cast<double>(p.num_inliers) / p.num_visible : 0.0;
        st.rmse = p.num_used > 0 ? std::sqrt(p.r2 / p.num_used) : 0.0;
        st.brightness = br;
    }
    result.num_inliers = last.count;
    result.num_valid = countValidNormals(frame.levels[0]);
    result.inlier_fraction =
        result.num_valid > 0 ? static_cast<double>(last.count) / result.num_valid : 0.0;
    result.rmse_m = last.count > 0 ? std::sqrt(final_sys.icp_r2 / last.count) : 0.0;
    result.information = last.JtJ;
    const Eigen::SelfAdjointEigenSolver<Matrix6d> eig(last.JtJ, Eigen::EigenvaluesOnly);
    const double min_ev = eig.eigenvalues()(0), max_ev = eig.eigenvalues()(5);
    result.condition_number =
        min_ev > 0.0 ? max_ev / min_ev : std::numeric_limits<double>::infinity();
    result.min_normalized_eigenvalue =
        last.count > 0 ? min_ev / static_cast<double>(last.count) : 0.0;
    // Translations the geometry leaves free: eigenvalues of sum n n^T / inliers (the translation
    // block of J^T J) below min_normal_spread. A single plane leaves 2, a wall meeting the floor 1.
    result.num_degenerate_directions = 0;
    if (last.count > 0) {
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig_t = translationSpread(last);
        result.translation_spread = eig_t.eigenvalues();
        result.translation_axes_M = eig_t.eigenvectors();
        for (int i = 0; i < 3; ++i) {
            if (!(eig_t.eigenvalues()(i) >= config.min_normal_spread)) {
                ++result.num_degenerate_directions;
            }
        }
    }

    const Eigen::Isometry3d delta = T_M_moved_from.inverse() * T;
    const double moved = delta.translation().norm();
    const double turned_deg = lie::rotationAngle(delta) * 180.0 / std::numbers::pi;
    if (!lie::isValidPose(T, 1e-4)) {
        result.failure = "pose is not finite";
    } else if (result.num_valid == 0 || result.inlier_fraction < config.min_inlier_fraction) {
        result.failure = "too few inliers: " + std::to_string(last.count) + " of " +
                         std::to_string(result.num_valid) + " valid pixels";
    } else if (result.num_degenerate_directions > config.max_degenerate_directions) {
        result.failure =
            "degenerate geometry: " + std::to_string(result.num_degenerate_directions) +
            " unconstrained directions (smallest normalised eigenvalue " +
            std::to_string(result.min_normalized_eigenvalue) + ")";
    } else if (moved > config.max_translation_m) {
        result.failure = "implausible motion: moved " + std::to_string(moved) + " m";
    } else if (turned_deg > config.max_rotation_deg) {
        result.failure = "implausible motion: turned " + std::to_string(turned_deg) + " deg";
    }
    result.ok = result.failure.empty();
    return result;
}

}  // namespace

IcpResult alignFrameToModel(const FramePyramid& frame, const std::vector<ModelLevel>& model,
                            const Eigen::Isometry3d& T_M_P, const Eigen::Isometry3d& T_M_C_init,
                            const IcpConfig& config, const PhotometricInput* photometric,
                            const Eigen::Isometry3d* T_M_previous) {
    PLUMB_CHECK(!frame.levels.empty() && frame.levels.size() == model.size())
        << "frame has " << frame.levels.size() << " levels, model " << model.size();
    const PhotometricInput* ph = nullptr;
    std::string fallback;
    if (photometric != nullptr && photometric->current != nullptr &&
        photometric->reference != nullptr) {
        const PhotometricReference& ref = *photometric->reference;
        PLUMB_CHECK(photometric->current->size() == frame.levels.size() &&
                    ref.levels.size() == frame.levels.size())
            << "photometric levels do not match the frame pyramid";
        if (ref.num_selected < static_cast<size_t>(photometric->config.min_points)) {
            fallback = "too little texture: " + std::to_string(ref.num_selected) +
                       " textured pixels in the reference (min_points " +
                       std::to_string(photometric->config.min_points) + ")";
        } else {
            ph = photometric;
        }
    }
    const Eigen::Isometry3d& T_M_moved_from = T_M_previous != nullptr ? *T_M_previous : T_M_P;
    IcpResult result = align(frame, model, T_M_P, T_M_C_init, T_M_moved_from, config, ph);
    if (ph != nullptr && result.photometric.inlier_fraction < ph->config.min_inlier_fraction) {
        // The image disagrees with itself (exposure jump, blur, moving objects): depth only.
        PhotometricStats stats = result.photometric;
        char pct[32];
        std::snprintf(pct, sizeof pct, "%.0f%%", 100.0 * stats.inlier_fraction);
        fallback = std::string("photometric term rejected: ") + pct + " of " +
                   std::to_string(stats.num_visible) +
                   " reference points agree (exposure change, blur or motion)";
        result = align(frame, model, T_M_P, T_M_C_init, T_M_moved_from, config, nullptr);
        result.photometric = stats;
        result.photometric.used = false;
    } else if (photometric != nullptr && photometric->reference != nullptr && ph == nullptr) {
        result.photometric.num_selected = photometric->reference->num_selected;
    }
    result.photometric.fallback = fallback;
    return result;
}

}  // namespace plumb::device
