// SPDX-License-Identifier: Apache-2.0
#pragma once

// Trajectory and registration files (reference §6.3):
//  - TUM: `timestamp tx ty tz qx qy qz qw` per line, camera->world, quaternion scalar last, '#'
//    comments.
//  - Redwood / ICL-NUIM `.log`: 5 lines per entry: `i j n` then the 4 rows of a 4x4 matrix. For a
//    camera trajectory `frame frame frame+1` and T = camera->world; for registration results
//    `i j n_fragments` and T aligns fragment j to fragment i (p_i = T p_j).
//  - `.info`: 7 lines per entry: `i j n` then the 6 rows of a 6x6 information matrix (rotation
//    first, as Open3D).
//
// Thread-safety: the functions keep no state between calls; concurrent calls on different
// files are safe.

#include <Eigen/Geometry>
#include <filesystem>
#include <optional>
#include <utility>
#include <vector>

#include "common/core/status.hpp"
#include "common/geometry/lie.hpp"

namespace plumb::io {

struct StampedPose {
    double timestamp_s = 0.0;                                 ///< seconds (or frame index)
    Eigen::Isometry3d T_W_C = Eigen::Isometry3d::Identity();  ///< camera -> world
};
using Trajectory = std::vector<StampedPose>;

/// Reads a TUM trajectory, poses in file order. Columns may be separated by spaces, tabs or
/// commas. Errors name the file and line (wrong column count, non-number, non-finite value,
/// quaternion norm off 1 by more than 1e-3); a missing file is kNotFound, a file without poses
/// kCorrupt. Quaternions are normalised.
Result<Trajectory> readTumTrajectory(const std::filesystem::path& path);
/// Writes a TUM trajectory with full double precision (round trip exact to 1e-9).
Status writeTumTrajectory(const std::filesystem::path& path, const Trajectory& trajectory);

/// Reads a Redwood `.log` camera trajectory; timestamps are the frame indices of line 1.
/// Blank lines are ignored. Errors name the file and line: metadata that is not 3 integers, a
/// row that is not 4 finite numbers, a truncated final entry, a matrix that is not rigid
/// (rotation off orthonormal by more than 1e-3). Rotations are re-orthonormalised.
Result<Trajectory> readLogTrajectory(const std::filesystem::path& path);
/// Writes a `.log` camera trajectory; entry k gets metadata `k k k+1`.
Status writeLogTrajectory(const std::filesystem::path& path, const Trajectory& trajectory);

/// One entry of a registration `.log`: T aligns fragment j to fragment i (p_i = T_i_j p_j).
struct RegistrationEntry {
    int i = 0;
    int j = 0;
    int num_fragments = 0;
    Eigen::Isometry3d T_i_j = Eigen::Isometry3d::Identity();
};
/// Reads a registration `.log` (same checks as readLogTrajectory; an empty file is valid: no
/// accepted pairs). The writers use the shortest exact decimal form of every double.
Result<std::vector<RegistrationEntry>> readRegistrationLog(const std::filesystem::path& path);
Status writeRegistrationLog(const std::filesystem::path& path,
                            const std::vector<RegistrationEntry>& entries);

/// One entry of a `.info` file.
struct InformationEntry {
    int i = 0;
    int j = 0;
    int num_fragments = 0;
    Matrix6d information = Matrix6d::Identity();
};
/// Reads a `.info` file: groups of 1 metadata line + 6 rows of 6 finite numbers.
Result<std::vector<InformationEntry>> readInformationFile(const std::filesystem::path& path);
Status writeInformationFile(const std::filesystem::path& path,
                            const std::vector<InformationEntry>& entries);

/// TUM `associate.py`: pairs (index into a, index into b) with |a - (b + offset_s)| strictly
/// less than `max_difference_s` (as associate.py); greedy, closest pairs first (ties by smaller
/// stamp of a, then of b), each index used at most once; result sorted by a's index.
/// Neither input needs to be sorted. For ATE/RPE pass ground truth as a and the estimate as b.
std::vector<std::pair<size_t, size_t>> associate(const std::vector<double>& stamps_a,
                                                 const std::vector<double>& stamps_b,
                                                 double max_difference_s = 0.02,
                                                 double offset_s = 0.0);

/// Pose at time t by geodesic interpolation between the two neighbouring samples of a
/// time-sorted trajectory; nullopt if t is outside it or the neighbours are more than
/// `max_gap_s` apart.
std::optional<Eigen::Isometry3d> poseAt(const Trajectory& sorted, double t, double max_gap_s);

}  // namespace plumb::io
