// SPDX-License-Identifier: Apache-2.0
#pragma once

// Odometry-guided loop search: candidate alignments of two fragments of one tracking segment,
// found by translation voting under the odometry's rotation.
//
// FPFH features are ambiguous in a bare room: walls, floor and ceiling look alike everywhere and
// the room matches itself after a quarter or half turn, so RANSAC fails on most pairs or finds
// a symmetric match (reference §3.3 explains the rotation check that rejects those). Within a
// tracking segment the device odometry knows the relative rotation to a few degrees; only the
// translation has drifted. With the rotation fixed, every pair of points (p in the source, q in
// the target) whose normals agree votes for the translation offset d = p - T_odo q. Points of one
// plane vote for a slab of offsets (any slide along the plane fits), planes of three directions
// meet in one peak, and furniture sharpens it. The strongest peaks within `radius_m` of the
// odometry are returned; the caller refines each by ICP and keeps the best verified one.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <Eigen/Geometry>
#include <vector>

#include "backend/registration/pair_registration.hpp"
#include "common/config/schema.hpp"

namespace plumb::registration {

struct GuidedSearchConfig {
    /// Search pairs of one tracking segment this way too (besides FPFH + RANSAC).
    bool enabled = true;
    /// Largest translation drift searched, metres (per axis, around the odometry). The
    /// 600-frame simulated scans drift up to about 30 cm between fragments of one segment.
    double radius_m = 0.6;
    /// Expected translation drift of the odometry from one fragment to the next, metres. The
    /// odometry is a Gaussian prior on the offset with deviation drift_per_fragment_m x
    /// sqrt(fragments apart): it breaks the ties of a slide along a wall (which fits as well as
    /// the truth) in favour of the odometry, and discounts far matches of a symmetric room.
    double drift_per_fragment_m = 0.1;
    /// Loops of one segment whose translation differs from the odometry's by more than this many
    /// deviations of the prior are rejected, as the rotation check rejects quarter turns (0 = no
    /// check).
    double max_offset_sigmas = 5.0;
    /// A guided alignment that ICP turns further than this from the odometry is dropped (the
    /// votes assumed the odometry's rotation; the odometry turns by a degree or two between
    /// fragments of a segment), degrees.
    double max_rotation_deg = 5.0;
    /// Edge of a vote bin, metres (the prepared clouds' voxel: one source point per bin and
    /// surface); at least radius_m / 100.
    double bin_m = 0.05;
    /// Point pairs vote only when their normals agree within this, degrees.
    double max_normal_angle_deg = 20.0;
    /// At most this many vote peaks are returned (strongest first), each at least 3 bins from
    /// the others and with at least half the votes of the strongest.
    int max_peaks = 3;
};
void describe(config::Schema& s, GuidedSearchConfig& c);

/// One candidate: T_source_target and its share of the votes.
struct GuidedCandidate {
    Eigen::Isometry3d T_source_target = Eigen::Isometry3d::Identity();
    double votes = 0.0;  ///< smoothed vote count of the peak
};

/// The deviation of the odometry prior for fragments `apart` fragments apart, metres.
double odometryPriorSigma(const GuidedSearchConfig& config, uint32_t apart);

/// Candidates for T_source_target = Translation(d) * T_odo, strongest first (votes weighted by
/// the odometry prior of deviation `prior_sigma_m`). Empty when either prepared cloud is empty
/// or lacks normals. Deterministic.
std::vector<GuidedCandidate> guidedCandidates(const FragmentIndex& source,
                                              const FragmentIndex& target,
                                              const Eigen::Isometry3d& T_odo, double prior_sigma_m,
                                              const GuidedSearchConfig& config);

}  // namespace plumb::registration
