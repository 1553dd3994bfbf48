// SPDX-License-Identifier: Apache-2.0
#pragma once

// Output files of the registration stage (DESIGN.md output contract, reference §6.3):
//  - pose_graph.json: nodes (T_W_F) and every edge with kind, overlap, inlier RMSE,
//    line-process weight, kept/pruned and why, plus the optimisation report;
//  - trajectory.txt (TUM) and trajectory.log (Redwood camera trajectory), one pose per frame:
//    T_W_C = T_W_F (optimised) * T_F_C (the frame's pose in its fragment);
//  - registration .log / .info (Redwood benchmark format): one entry "i j n" per kept edge with
//    T_i_j = T_source_target (maps fragment j into fragment i) and its information matrix.
// Writers produce byte-identical files for identical inputs.
//
// Thread-safety: the functions keep no state between calls; concurrent calls on different
// files are safe.

#include <filesystem>
#include <string>
#include <vector>

#include "backend/posegraph/pose_graph.hpp"
#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "common/io/trajectory.hpp"

namespace plumb::registration {

using posegraph::PoseGraph;

/// The pose graph as JSON text (2-space indented, keys in a fixed order).
std::string poseGraphJson(const PoseGraph& graph, const posegraph::PoseGraphReport& report);
Status writePoseGraphJson(const std::filesystem::path& path, const PoseGraph& graph,
                          const posegraph::PoseGraphReport& report);

/// Per-frame camera trajectory from the fragments' frames and the graph's fragment poses, in
/// frame order; frames with tracking_ok = false are skipped. Timestamps are the frames'.
/// Errors: a graph with fewer nodes than fragments.
Result<io::Trajectory> frameTrajectory(const std::vector<Fragment>& fragments,
                                       const PoseGraph& graph);

/// Writes the registration `.log` and `.info` of the kept edges (sorted by source, target).
Status writeRegistrationLogInfo(const std::filesystem::path& log_path,
                                const std::filesystem::path& info_path, const PoseGraph& graph);

/// Writes pose_graph.json, trajectory.txt, trajectory.log, registration.log and
/// registration.info into `dir` (created when missing).
Status writeRegistrationOutputs(const std::filesystem::path& dir,
                                const std::vector<Fragment>& fragments, const PoseGraph& graph,
                                const posegraph::PoseGraphReport& report);

}  // namespace plumb::registration
