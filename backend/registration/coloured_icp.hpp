// SPDX-License-Identifier: Apache-2.0
#pragma once

// Coloured ICP between fragments (Park, Zhou, Koltun, "Colored Point Cloud Registration
// Revisited", ICCV 2017; reference §7b.3). The fixed cloud P carries normals n_p, intensities
// C(p) and tangent-plane intensity gradients d_p; the moving cloud Q carries intensities C(q).
// With the pose-graph naming of pair_registration.hpp, P is the *source* fragment (indexed) and
// Q the *target* fragment, moved into the source frame by T = T_source_target: x = T q.
//
//   E(T)   = (1 - δ) E_C(T) + δ E_G(T)                                   Eq. (1)
//   E_G(T) = Σ_(p,q) ((T q - p)·n_p)^2                                   Eq. (2)
//   E_C(T) = Σ_(p,q) (C_p(f(T q)) - C(q))^2                              Eq. (3)
//   f(s)   = s - ((s - p)·n_p) n_p   (projection onto p's tangent plane) Eq. (4)
//   C_p(u) ≈ C(p) + d_p·(u - p)      (continuous intensity on the plane) Eq. (5)
//   d_p    = argmin Σ_(p' ∈ N(p)) (C(p) + d·(f(p') - p) - C(p'))^2, d·n_p = 0   Eq. (6)
//
// (p, q) are nearest-neighbour correspondences within the level's distance, found anew every
// iteration; δ is Open3D's lambda_geometric (0.968). Intensity is the BT.601 luma in [0, 1]
// (common/image/image.hpp intensity(), the tracker's photometric intensity); Open3D averages
// the three channels instead.
//
// Determinism: per-point work is independent and sums are reduced over fixed chunks in a fixed
// order, so every result is identical for any thread count.
//
// Thread-safety: the functions keep no state between calls and may run concurrently;
// each parallelises internally over num_threads.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "backend/registration/pair_registration.hpp"
#include "common/cloud/point_cloud.hpp"
#include "common/geometry/lie.hpp"

namespace plumb::registration {

/// Intensity (BT.601 luma, [0, 1]) of every colour.
std::vector<float> intensitiesOf(const std::vector<Color3u8>& colors);

/// Fits the tangent-plane intensity gradient d_p of every point of `cloud` (Eq. (6)) over up to
/// `max_nn` nearest neighbours within `radius_m` (the point itself included, as it adds nothing).
/// The constraint d·n_p = 0 is exact: the fit is solved in an orthonormal basis of the tangent
/// plane, whose coordinates of p' - p are those of f(p') - p. A point whose neighbours do not
/// span the plane (fewer than 3 others, or a smallest second moment of their tangent offsets
/// below (0.1 radius)^2) gets d_p = 0, so it adds nothing to the colour term.
/// Preconditions: `cloud` has normals and colours. Units: intensity per metre.
std::vector<Eigen::Vector3f> intensityGradients(const PointCloud& cloud,
                                                const std::vector<float>& intensity,
                                                double radius_m, int max_nn, int num_threads);
/// The same over an indexed cloud, with its k-d tree (the same neighbours, the same result).
std::vector<Eigen::Vector3f> intensityGradients(const IndexedCloud& cloud,
                                                const std::vector<float>& intensity,
                                                double radius_m, int max_nn, int num_threads);

/// The colour residual of one correspondence and its Jacobian with respect to a left
/// perturbation T <- Exp(ξ) T, ξ = (ω, υ) (rotation first):
///   r_C = C(p) + d_p·(f(x) - p) - C(q),   x = T q                    Eq. (3)-(5)
/// Derivation: f(x) - p = (I - n n^T)(x - p) and d_p·n_p = 0, so d_p·(f(x) - p) = d_p·(x - p);
/// with d(Exp(ξ) x)/dξ = [-[x]_x | I],  dr_C/dξ = d_p^T [-[x]_x | I] = [(x × d_p)^T, d_p^T].
/// The Jacobian relies on d_p ⟂ n_p (as intensityGradients() guarantees); the residual is the
/// full Eq. (3)-(5) expression either way.
double colourResidual(const Eigen::Vector3d& p, const Eigen::Vector3d& n_p, double c_p,
                      const Eigen::Vector3d& d_p, const Eigen::Vector3d& x, double c_q,
                      Eigen::Matrix<double, 1, 6>* jacobian);

/// Coloured ICP of `target` onto `source` from `init`, one level: Gauss-Newton on Eq. (1) with
/// left updates T <- Exp(ξ) T. Each correspondence adds δ J_G^T J_G + (1 - δ) J_C^T J_C to the
/// normal equations (J_G = [(x × n_p)^T, n_p^T], the point-to-plane row of icpPointToPlane).
/// `source_intensity` / `source_gradient` belong to the source cloud's points,
/// `target_intensity` to the target's. Stops when fitness, point-to-plane RMSE and colour RMSE
/// all change by less than `relative_change` (Open3D watches the first two only, which a slide
/// along a textured wall leaves unchanged); fitness goes to `overlap`, the point-to-plane RMSE to
/// `inlier_rmse_m`. A step that undoes the previous one (a limit cycle between two sets of
/// correspondences) ends the level half-way between the two poses. Solution remapping as in
/// icpPointToPlane, on the combined system: a translation t is not solved for when t^T H_tt t / (δ
/// · correspondences) is below `min_normal_spread`, H_tt the translation block of the normal
/// equations; without colour (d_p = 0) that is exactly mean (n·t)^2, and texture along a direction
/// the geometry leaves free makes it solvable. Fails with fewer than 6 correspondences, on a
/// non-finite step, or when sizes do not match (`lambda_geometric` must lie in (0, 1]).
PairResult icpColoured(const IndexedCloud& source, const std::vector<float>& source_intensity,
                       const std::vector<Eigen::Vector3f>& source_gradient,
                       const PointCloud& target, const std::vector<float>& target_intensity,
                       const Eigen::Isometry3d& init, double max_distance_m, int max_iterations,
                       double relative_change, double lambda_geometric, double min_normal_spread,
                       int num_threads);

}  // namespace plumb::registration
