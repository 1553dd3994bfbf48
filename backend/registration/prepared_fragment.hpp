// SPDX-License-Identifier: Apache-2.0
#pragma once

// Fragment preprocessing for registration (reference §3.1, Choi et al. 2015 §4): voxel
// downsampling, normals and Fast Point Feature Histograms (Rusu, Blodow, Beetz, ICRA 2009).
//
// FPFH follows the 33-bin layout of Open3D's ComputeFPFHFeature (three 11-bin histograms of the
// Darboux-frame angles alpha, phi, theta; neighbours weighted by 1 / squared distance; each block
// normalised to sum 100), so features are comparable with the peer in the benchmark.
//
// Everything here is deterministic: the output depends on the input and the configuration only,
// never on the thread count.
//
// Thread-safety: the functions keep no state between calls and may run concurrently;
// each parallelises internally over num_threads.

#include <array>
#include <cstdint>
#include <vector>

#include "common/cloud/point_cloud.hpp"
#include "common/config/schema.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"

namespace plumb::registration {

using Fpfh33 = std::array<float, 33>;

struct PrepareConfig {
    /// Voxel edge of the downsampled cloud used for features and loop closure (Open3D: 0.05).
    double voxel_size_m = 0.05;
    /// Recompute normals by PCA over neighbours instead of averaging the fragment's fused normals.
    bool recompute_normals = false;
    /// PCA normal neighbourhood: radius (Open3D: 2 x voxel) and maximum neighbour count.
    double normal_radius_m = 0.10;
    int normal_max_nn = 30;
    /// FPFH neighbourhood: radius (Open3D: 5 x voxel) and maximum neighbour count.
    double fpfh_radius_m = 0.25;
    int fpfh_max_nn = 100;
    /// Worker threads (0 = all available); results do not depend on it.
    int num_threads = 0;
};
void describe(config::Schema& s, PrepareConfig& c);

/// A fragment ready for registration: its downsampled oriented cloud (fragment frame F) and one
/// FPFH descriptor per point.
struct PreparedFragment {
    uint32_t id = 0;
    /// Downsampled, with unit normals (and the voxel-averaged colours when the fragment has
    /// colours), fragment frame, metres.
    PointCloud points;
    std::vector<Fpfh33> fpfh;  ///< one per point of `points`
};

/// Downsamples, computes normals (averaged or PCA) and FPFH. A fragment without finite points
/// gives an empty PreparedFragment (registration then keeps it on its odometry edge).
/// Errors: inconsistent attribute sizes or an invalid config.
Result<PreparedFragment> prepareFragment(const Fragment& fragment, const PrepareConfig& config);

/// PCA normals over up to `max_nn` neighbours within `radius_m`, oriented towards `viewpoint`
/// (points with fewer than 3 neighbours get the direction to the viewpoint).
std::vector<Eigen::Vector3f> estimateNormals(const std::vector<Eigen::Vector3f>& points,
                                             double radius_m, int max_nn,
                                             const Eigen::Vector3f& viewpoint, int num_threads);

/// FPFH of every point of `cloud` (which must have normals) over up to `max_nn` neighbours within
/// `radius_m`. A point without neighbours gets an all-zero descriptor.
std::vector<Fpfh33> computeFpfh(const PointCloud& cloud, double radius_m, int max_nn,
                                int num_threads);

/// Deterministic voxel-grid average of points, of normals (renormalised) and of colours (per
/// channel, rounded to the nearest 8-bit value), each when present. A voxel whose normals
/// cancel is dropped with its point and colour.
PointCloud voxelDownsample(const PointCloud& cloud, double voxel_m);

}  // namespace plumb::registration
