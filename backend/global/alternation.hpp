// SPDX-License-Identifier: Apache-2.0
#pragma once

// Algorithm 1 of Lee et al. (ICCV 2017): alternate layout estimation and layout-constrained
// global registration until both settle (reference §5.7).
//
//   T <- T0 (the pose graph's poses)
//   repeat (outer, at most max_outer_iterations; the paper converges within 20):
//       layout <- estimate_layout(T)                                  (layout step, §3.2)
//       T <- refinePoses(T, layout)  (correspondences C_i, C_ij at T;  (registration step, §3.3)
//                                     LM inner loop, E non-increasing for fixed C)
//       shrink the correspondence distances and support margins (annealing)
//       stop when the layout is unchanged (same planes, |Δn| < tol, |Δd| < tol) and either the
//       largest pose change of the outer iteration is below the pose tolerances or, once the
//       annealing is done, E fell by less than energy_tolerance of itself over the iteration.
//
// The layout step is a callback so that this module depends on common/ types only; the
// pipeline passes backend/layout's estimator. The energies of every outer and inner iteration
// are recorded, term by term, for the report.
//
// Thread-safety: alternate() keeps no state between calls; it calls the layout estimator on
// the calling thread.

#include <Eigen/Geometry>
#include <functional>
#include <string>
#include <vector>

#include "backend/global/global_registration.hpp"
#include "common/config/schema.hpp"
#include "common/core/progress_callback.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "common/layout/layout.hpp"

namespace plumb::global {

struct AlternationConfig {
    /// The registration step's configuration (its distances are the first outer iteration's).
    GlobalConfig global;
    /// Maximum outer iterations (layout re-estimations); the paper converges within 20.
    int max_outer_iterations = 20;
    /// Outer loop stops when no pose moved more than these in the last outer iteration (and the
    /// layout is unchanged).
    double pose_tolerance_rad = 1e-4;
    double pose_tolerance_m = 1e-4;
    /// Outer loop also stops (converged) when the layout is unchanged, the correspondence
    /// distances are those of the previous outer iteration (the annealing is done), and E_R at
    /// the end of this iteration is lower than at the end of the previous one by less than this
    /// fraction of it: the poses then creep along a direction E_R hardly constrains, a tenth of a
    /// millimetre an iteration, with no gain the energy can see. 0 = poses and layout only.
    double energy_tolerance = 1e-3;
    /// Layout unchanged: same number of planes of each kind and every plane within these.
    double layout_angle_tolerance_deg = 0.1;
    double layout_offset_tolerance_m = 0.001;
    /// Per outer iteration the correspondence distances and support margins are multiplied by
    /// this, down to the final values below (annealing, reference §5.7).
    double shrink_factor = 0.7;
    /// Final (smallest) fragment-fragment correspondence distance, metres.
    double final_frag_max_distance_m = 0.025;
    /// Final (smallest) point-to-layout distance, metres.
    double final_layout_max_distance_m = 0.05;
    /// Final (smallest) wall / floor support margins, metres.
    double final_margin_m = 0.05;
    /// Keep a re-estimated layout only when it does not raise E_R at the current poses (with
    /// the iteration's distances); otherwise stop with the previous layout. Layout estimation is
    /// not itself a minimiser of E_R (clustering, snapping to right angles, the occupancy
    /// boundary), and without this test Algorithm 1 can chase its own layout: on a 600-frame
    /// living_room scan E_layout rose eightfold over 20 outer iterations while the model tilted
    /// by 2.5 degrees.
    bool monotone_layout_steps = true;
};

void describe(config::Schema& s, AlternationConfig& c);

/// One outer iteration of Algorithm 1.
struct OuterIteration {
    int iteration = 0;
    Layout layout;                   ///< the layout estimated at the start of the iteration
    EnergyTerms before;              ///< E at the start of the registration step
    EnergyTerms after;               ///< E at its end
    int inner_iterations = 0;        ///< LM iterations run
    double max_pose_change_rad = 0;  ///< largest rotation change of a fragment pose
    double max_pose_change_m = 0;    ///< largest translation change of a fragment pose
    /// Change of the layout relative to the previous outer iteration (0 for the first):
    bool layout_same_structure = false;  ///< same number of planes of each kind
    double layout_change_deg = 0.0;      ///< largest normal change of matched planes
    double layout_change_m = 0.0;        ///< largest offset change of matched planes
    /// With monotone_layout_steps, from the second outer iteration: E_R at the start poses with
    /// the previous layout and with this one (same distances).
    double energy_previous_layout = 0.0;
    double energy_new_layout = 0.0;
    std::vector<GlobalIteration> inner;  ///< the registration step's iterations
};

struct AlternationResult {
    std::vector<Eigen::Isometry3d> T_W_F;  ///< final poses (T_W_F[0] unchanged)
    Layout layout;                         ///< the layout of the last outer iteration
    std::vector<OuterIteration> iterations;
    bool converged = false;
    /// "converged", "energy settled" (see AlternationConfig::energy_tolerance; also converged),
    /// "max_outer_iterations", or "layout step raised the energy" (the last
    /// layout was not kept; see AlternationConfig::monotone_layout_steps).
    std::string stop_reason;
};

/// Layout estimation at given fragment poses (the paper's §3.2 step).
using LayoutEstimator = std::function<Result<Layout>(const std::vector<Eigen::Isometry3d>&)>;

/// Runs Algorithm 1 from `initial_T_W_F`. `progress` (may be empty) is called once per outer
/// iteration. Errors: those of prepareClouds()/refinePoses() and of the layout callback (with
/// the outer iteration named).
Result<AlternationResult> alternate(const std::vector<Fragment>& fragments,
                                    const std::vector<Eigen::Isometry3d>& initial_T_W_F,
                                    const std::vector<PairPrior>& priors,
                                    const LayoutEstimator& estimate_layout,
                                    const AlternationConfig& config,
                                    const ProgressCallback& progress = {});

/// The same on prepared clouds (prepareClouds() with config.global).
Result<AlternationResult> alternate(const std::vector<GlobalCloud>& clouds,
                                    const std::vector<Eigen::Isometry3d>& initial_T_W_F,
                                    const std::vector<PairPrior>& priors,
                                    const LayoutEstimator& estimate_layout,
                                    const AlternationConfig& config,
                                    const ProgressCallback& progress = {});

/// Change between two layouts: planes matched per kind by closest world normal; false when the
/// number of planes of a kind differs. Largest normal angle (deg) and offset (m) change.
bool compareLayouts(const Layout& a, const Layout& b, double* max_angle_deg, double* max_offset_m);

}  // namespace plumb::global
