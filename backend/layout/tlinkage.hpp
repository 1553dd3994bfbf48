// SPDX-License-Identifier: Apache-2.0
#pragma once

// T-linkage (Magri & Fusiello, CVPR 2014): agglomerative clustering of data items in the
// conceptual space of their preferences for model hypotheses. The paper (§3.2) uses it twice:
// over supervoxels inside each fragment and over labelled point groups in the world (reference
// §4.4, §4.6).
//
//   preference   phi_k(l) = exp(-C(pi_l, S_k) / tau) if C < cutoff * tau, else 0
//   distance     Tanimoto d_T(p, q) = 1 - <p,q> / (|p|^2 + |q|^2 - <p,q>), in [0, 1]
//   merge        the two clusters at the smallest d_T; the merged preference is the element-wise
//                minimum (Magri's tlnk.m); stop when every remaining distance is 1.
//
// Optionally only clusters adjacent in a given graph may merge (the adjacency of a merged cluster
// is the union), which keeps coplanar but disconnected surfaces apart and is much faster.
// Deterministic: ties break by the smaller cluster ids.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <functional>
#include <utility>
#include <vector>

namespace plumb::layout {

/// Sparse preference vector: (hypothesis index, phi > 0), sorted by hypothesis index.
using PreferenceVector = std::vector<std::pair<int, float>>;

/// Preferences of one item from its residuals: residual(l) for l in [0, num_hypotheses) returns
/// C(pi_l, item) or a negative value for "not computed, treat as beyond the cutoff".
PreferenceVector preferencesFromResiduals(int num_hypotheses,
                                          const std::function<double(int)>& residual, double tau,
                                          double cutoff_factor);

/// Tanimoto distance of two sparse preference vectors (1 when either is empty).
double tanimotoDistance(const PreferenceVector& a, const PreferenceVector& b);

struct TLinkageResult {
    std::vector<int> cluster_of_item;  ///< cluster index in [0, num_clusters) per item
    int num_clusters = 0;              ///< clusters are numbered by their smallest item
    int num_merges = 0;
    /// Items of each cluster, ascending.
    std::vector<std::vector<int>> members;
};

/// Clusters the items. `adjacency` (optional, symmetric, one list per item) restricts merges to
/// adjacent clusters; empty = any two clusters that share a preferred hypothesis may merge.
TLinkageResult tLinkage(const std::vector<PreferenceVector>& preferences,
                        const std::vector<std::vector<int>>& adjacency = {});

}  // namespace plumb::layout
