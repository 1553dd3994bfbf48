// SPDX-License-Identifier: Apache-2.0
#pragma once

// Per-fragment plane extraction, the first half of the paper's layout estimation (§3.2,
// reference §4.1-4.5). Everything runs in the fragment frame F and does not depend on the
// fragment's pose, so the backend computes it once per fragment and caches it across the
// outer iterations of Algorithm 1.
//
//   1. voxel-downsample the fragment's oriented points to the working sample;
//   2. supervoxels (PCL VCCS, Papon et al. CVPR 2013) over the sample;
//   3. plane hypotheses from every triangle of mutually adjacent planar supervoxel centres;
//   4. T-linkage over supervoxels (residual Eq. 2-3: mean |n.p + d| of a supervoxel's points),
//      merges restricted to adjacent clusters; clusters refitted by least squares;
//   5. graph-cut multi-model fitting of every sample point (Eq. 4-5): data term |n.p + d|, a null
//      label of constant cost gamma, a Potts term over k-NN pairs closer than r_N; minimised by
//      alpha-expansion, then PEARL-style refits (Isack & Boykov 2012) that drop labels with too
//      little support, repeated.
//
// Deterministic (no randomness; PCL's VCCS is deterministic for a given input order).
//
// Thread-safety: extractFragmentPlanes keeps no state between calls; fragments may be processed
// concurrently.

#include <nlohmann/json_fwd.hpp>

#include <Eigen/Geometry>
#include <vector>

#include "common/cloud/point_cloud.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"

namespace plumb::config {
class Schema;
}

namespace plumb::layout {

/// Parameters of per-fragment plane extraction. Defaults and their reasons: docs/layout.md.
struct FragmentPlaneConfig {
    /// Working sample spacing (voxel-grid average), metres. 3 cm keeps a 50-frame fragment at
    /// ~10-20k points, enough for walls and the 100 ms budget (reference §4.1 suggests 2 cm).
    double sample_voxel_m = 0.03;
    /// VCCS voxel resolution, metres (= the sample spacing: one sample point per voxel).
    double supervoxel_voxel_m = 0.03;
    /// VCCS seed resolution, metres (reference §4.2: 0.10-0.20).
    double supervoxel_seed_m = 0.15;
    /// VCCS weights of the spatial and normal distances (PCL defaults 0.4 / 1.0; colour unused).
    double spatial_importance = 0.4;
    double normal_importance = 1.0;
    /// Supervoxels with PCA curvature lambda_min / sum(lambda) above this take no part in
    /// hypothesis generation (they straddle corners, reference §4.2 pitfall 3).
    double max_supervoxel_curvature = 0.02;
    /// Hypothesis triangles with sin(angle at the first centre) below this are near collinear
    /// and dropped (reference §4.3).
    double min_triangle_sine = 0.2;
    /// A hypothesis is dropped when it makes more than this angle with all three supervoxel
    /// normals, degrees.
    double max_hypothesis_normal_angle_deg = 30.0;
    /// At most this many hypotheses (uniform deterministic subsample beyond).
    int max_hypotheses = 3000;
    /// T-linkage inlier scale tau, metres (reference §4.4: 0.01-0.015 for TSDF fragments).
    double tau_m = 0.012;
    /// Preferences vanish beyond cutoff_factor * tau.
    double cutoff_factor = 5.0;
    /// T-linkage clusters with fewer supervoxels or less area are outliers (reference §4.4).
    int min_cluster_supervoxels = 3;
    double min_cluster_area_m2 = 0.1;
    /// Null-label cost gamma = null_cost_factor * tau (reference §4.5: 3 tau).
    double null_cost_factor = 3.0;
    /// Potts weight lambda_s = smoothness_factor * tau per neighbour pair (reference §4.5: 0.5).
    double smoothness_factor = 0.5;
    /// Graph neighbourhood: k nearest neighbours closer than the radius (paper: "points within
    /// a predefined distance among k-NN"); radius ~2.5x the sample spacing.
    int knn = 8;
    double neighbour_radius_m = 0.08;
    /// Data-term normal gate: a point whose normal makes more than this angle with a plane pays
    /// 2 gamma for it (it cannot lie on that surface); 180 disables, degrees.
    double max_point_normal_angle_deg = 35.0;
    /// Alpha-expansion cycle limit per round and refit rounds (reference §4.5: 2-3).
    int max_expansion_cycles = 5;
    int refit_rounds = 3;
    /// Labels with fewer points or less area after a round are dropped (PEARL label-cost
    /// stand-in; reference §4.5: 200 points or 0.25 m^2 at 2 cm).
    int min_label_points = 60;
    double min_label_area_m2 = 0.2;
    /// Labels whose planes differ by less than this angle and whose point sets lie within the
    /// offset of each other's plane are merged after each round.
    double merge_angle_deg = 3.0;
    double merge_offset_m = 0.02;
};
void describe(config::Schema& s, FragmentPlaneConfig& c);

/// One plane found in a fragment, in its frame F.
struct FragmentPlane {
    Eigen::Vector3d normal_F = Eigen::Vector3d::UnitZ();  ///< unit; sign follows the points'
                                                          ///< normals (towards free space)
    double d_F = 0.0;                                     ///< n.x + d = 0, metres
    Eigen::Vector3d centroid_F = Eigen::Vector3d::Zero();
    int num_points = 0;    ///< sample points labelled with this plane
    double area_m2 = 0.0;  ///< num_points * sample spacing^2
    double rms_m = 0.0;    ///< RMS point-to-plane distance of its points
};

struct FragmentPlaneDiagnostics {
    int num_input_points = 0;
    int num_sample_points = 0;
    int num_supervoxels = 0;
    int num_planar_supervoxels = 0;
    int num_adjacency_pairs = 0;
    int num_hypotheses = 0;         ///< after the collinearity and normal checks (and cap)
    int num_tlinkage_clusters = 0;  ///< all clusters, before outlier rejection
    int num_clusters_kept = 0;      ///< labels entering the graph cut
    double initial_energy = 0.0;    ///< graph-cut energy of the T-linkage labelling, metres
    double final_energy = 0.0;      ///< after the last expansion round
    int expansion_cycles = 0;       ///< over all rounds
    int max_flow_calls = 0;
    int labels_dropped = 0;  ///< by the support test
    int labels_merged = 0;   ///< by the coplanarity merge
    int num_null_points = 0;
    double ms_sample = 0.0;
    double ms_supervoxels = 0.0;
    double ms_hypotheses = 0.0;
    double ms_tlinkage = 0.0;
    double ms_graph_cut = 0.0;
    double ms_total = 0.0;
};

/// The planes of one fragment with the point labels they came from (cacheable; pose-free).
struct FragmentPlanes {
    uint32_t fragment_id = 0;
    double sample_spacing_m = 0.0;
    PointCloud sample_F;      ///< the working sample (with normals), fragment frame
    std::vector<int> labels;  ///< per sample point: plane index or -1 (null label)
    std::vector<FragmentPlane> planes;
    FragmentPlaneDiagnostics diagnostics;
};

/// Extracts the planes of `fragment`. Errors: no points, non-finite points only, inconsistent
/// normals, an invalid configuration. A fragment without any planar structure gives an empty
/// plane list (not an error).
Result<FragmentPlanes> extractFragmentPlanes(const Fragment& fragment,
                                             const FragmentPlaneConfig& config = {});

/// Diagnostics as a JSON object (for reports).
nlohmann::json toJson(const FragmentPlaneDiagnostics& diagnostics);

}  // namespace plumb::layout
