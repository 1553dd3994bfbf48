// SPDX-License-Identifier: Apache-2.0
#include "device/tracking/icp.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <utility>

#include "common/tsdf/parallel.hpp"

namespace plumb::device {
namespace {

/// Normal equations of one chunk of rows; summed in chunk order for determinism.
struct Accumulator {
    Matrix6d JtJ = Matrix6d::Zero();
    Vector6d Jtr = Vector6d::Zero();
    double r2 = 0.0;
    size_t count = 0;
};

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
    tsdf::parallelFor(config.num_threads, num_chunks, [&](int c) {
        Accumulator& acc = chunks[static_cast<size_t>(c)];
        // Upper-triangular accumulation in double; symmetric fill at the end.
        Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
        const int v_end = std::min(h, (c + 1) * kRowsPerChunk);
        for (int v = c * kRowsPerChunk; v < v_end; ++v) {
            for (int u = 0; u < w; ++u) {
                const Eigen::Vector3f& p = level.points_C(u, v);
                const Eigen::Vector3f& n = level.normals_C(u, v);
                if (!tsdf::isValid(n)) continue;
                const Eigen::Vector3f x = R * p + t;  // step 1: x = T V_k(u)
                const Eigen::Vector3f x_p = R_pm * x + t_pm;
                if (x_p.z() <= 0.0f) continue;
                const int mu = static_cast<int>(std::floor(fx * x_p.x() / x_p.z() + cx + 0.5f));
                const int mv = static_cast<int>(std::floor(fy * x_p.y() / x_p.z() + cy + 0.5f));
                if (mu < 0 || mv < 0 || mu >= mw || mv >= mh) continue;
                const Eigen::Vector3f& vm = model.points_M(mu, mv);
                const Eigen::Vector3f& nm = model.normals_M(mu, mv);
                if (!tsdf::isValid(nm)) continue;
                const Eigen::Vector3f diff = x - vm;  // step 2: gates
                if (diff.squaredNorm() > max_d2) continue;
                if ((R * n).dot(nm) < min_cos) continue;
                // Step 3: r = n^T (x - v), J = [(x x n)^T, n^T].
                const double r = nm.dot(diff);
                Vector6d J;
                J.head<3>() = x.cross(nm).cast<double>();
                J.tail<3>() = nm.cast<double>();
                A.selfadjointView<Eigen::Upper>().rankUpdate(J);
                acc.Jtr += J * r;
                acc.r2 += r * r;
                ++acc.count;
            }
        }
        acc.JtJ = A.selfadjointView<Eigen::Upper>();
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

}  // namespace

std::vector<ModelLevel> predictModel(const tsdf::TsdfVolume& volume, const FramePyramid& frame,
                                     const Eigen::Isometry3d& T_M_P,
                                     const tsdf::RaycastConfig& config) {
    std::vector<ModelLevel> model(frame.levels.size());
    for (size_t l = 0; l < frame.levels.size(); ++l) {
        tsdf::RaycastResult r = tsdf::raycast(volume, frame.levels[l].camera, T_M_P, config);
        model[l].camera = frame.levels[l].camera;
        model[l].points_M = std::move(r.points_V);
        model[l].normals_M = std::move(r.normals_V);
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
    return Status::ok();
}

IcpResult alignFrameToModel(const FramePyramid& frame, const std::vector<ModelLevel>& model,
                            const Eigen::Isometry3d& T_M_P, const Eigen::Isometry3d& T_M_C_init,
                            const IcpConfig& config) {
    PLUMB_CHECK(!frame.levels.empty() && frame.levels.size() == model.size())
        << "frame has " << frame.levels.size() << " levels, model " << model.size();
    IcpResult result;
    Eigen::Isometry3d T = T_M_C_init;
    const Eigen::Isometry3d T_P_M = T_M_P.inverse();
    const int num_levels = static_cast<int>(frame.levels.size());
    Accumulator last;
    for (int l = num_levels - 1; l >= 0; --l) {
        const int iterations = l < 3 ? config.iterations[static_cast<size_t>(l)] : 4;
        const PyramidLevel& level = frame.levels[static_cast<size_t>(l)];
        for (int it = 0; it < iterations; ++it) {
            Accumulator sys = buildSystem(level, model[static_cast<size_t>(l)], T, T_P_M, config);
            if (sys.count < 6) break;
            ++result.iterations;
            // Step 4: (sum J^T J) xi = -sum J^T r, T <- Exp(xi) T.
            const Vector6d xi = sys.JtJ.ldlt().solve(-sys.Jtr);
            if (!xi.allFinite()) break;
            T = lie::orthonormalized(lie::expSE3(xi) * T);
            if (xi.norm() < config.min_update_norm) break;
        }
    }
    // Final statistics at the finest level, at the final pose.
    last = buildSystem(frame.levels[0], model[0], T, T_P_M, config);
    result.T_M_C = T;
    result.num_inliers = last.count;
    result.num_valid = countValidNormals(frame.levels[0]);
    result.inlier_fraction =
        result.num_valid > 0 ? static_cast<double>(last.count) / result.num_valid : 0.0;
    result.rmse_m = last.count > 0 ? std::sqrt(last.r2 / last.count) : 0.0;
    result.information = last.JtJ;
    const Eigen::SelfAdjointEigenSolver<Matrix6d> eig(last.JtJ, Eigen::EigenvaluesOnly);
    const double min_ev = eig.eigenvalues()(0), max_ev = eig.eigenvalues()(5);
    result.condition_number =
        min_ev > 0.0 ? max_ev / min_ev : std::numeric_limits<double>::infinity();
    result.min_normalized_eigenvalue =
        last.count > 0 ? min_ev / static_cast<double>(last.count) : 0.0;

    const Eigen::Isometry3d delta = T_M_P.inverse() * T;
    const double moved = delta.translation().norm();
    const double turned_deg = lie::rotationAngle(delta) * 180.0 / std::numbers::pi;
    if (!lie::isValidPose(T, 1e-4)) {
        result.failure = "pose is not finite";
    } else if (result.num_valid == 0 || result.inlier_fraction < config.min_inlier_fraction) {
        result.failure = "too few inliers: " + std::to_string(last.count) + " of " +
                         std::to_string(result.num_valid) + " valid pixels";
    } else if (result.min_normalized_eigenvalue < config.min_normalized_eigenvalue) {
        result.failure = "degenerate geometry: smallest normalised eigenvalue " +
                         std::to_string(result.min_normalized_eigenvalue);
    } else if (moved > config.max_translation_m) {
        result.failure = "implausible motion: moved " + std::to_string(moved) + " m";
    } else if (turned_deg > config.max_rotation_deg) {
        result.failure = "implausible motion: turned " + std::to_string(turned_deg) + " deg";
    }
    result.ok = result.failure.empty();
    return result;
}

}  // namespace plumb::device
