// SPDX-License-Identifier: Apache-2.0
#pragma once

// Camera poses of a trajectory looked up per frame of a source: a TUM trajectory by timestamp
// (within 1 ms), a .log trajectory (whose stamps are frame indices) by frame index.

#include <Eigen/Geometry>
#include <filesystem>
#include <map>
#include <optional>
#include <vector>

#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"
#include "common/io/trajectory.hpp"

namespace plumb::tools {

class PoseLookup {
  public:
    enum class Key { kTimestamp, kFrameIndex };

    PoseLookup(const io::Trajectory& trajectory, Key key) : key_(key) {
        for (const io::StampedPose& p : trajectory) poses_.emplace(p.timestamp_s, p.T_W_C);
    }

    /// Reads a `.log` trajectory (by frame index) or any other file as TUM (by timestamp).
    static Result<PoseLookup> read(const std::filesystem::path& path) {
        const bool log = path.extension() == ".log";
        Result<io::Trajectory> t = log ? io::readLogTrajectory(path) : io::readTumTrajectory(path);
        if (!t.isOk()) return t.status();
        return PoseLookup(*t, log ? Key::kFrameIndex : Key::kTimestamp);
    }

    /// The pose of `frame`, or nullopt when the trajectory has none for it.
    std::optional<Eigen::Isometry3d> find(const Frame& frame) const {
        const bool by_index = key_ == Key::kFrameIndex;
        const double key = by_index ? static_cast<double>(frame.index) : frame.timestamp_s;
        const double tolerance = by_index ? 0.5 : kStampToleranceS;
        const auto it = poses_.lower_bound(key - tolerance);
        if (it == poses_.end() || it->first > key + tolerance) return std::nullopt;
        return it->second;
    }

    size_t size() const { return poses_.size(); }

  private:
    static constexpr double kStampToleranceS = 1e-3;
    Key key_;
    std::map<double, Eigen::Isometry3d> poses_;
};

/// Of the frames of `source` that have a pose in `poses`, every frame_step-th one (the first,
/// the frame_step + 1-th, ...), with its pose.
struct PosedDepth {
    std::vector<DepthImage> depth;
    std::vector<Eigen::Isometry3d> T_W_C;
    size_t without_pose = 0;  ///< frames whose pose the trajectory lacks (skipped)
};

/// Reads `source` to its end; a frame error other than the end of the stream is returned.
Result<PosedDepth> readPosedDepth(FrameSource& source, const PoseLookup& poses,
                                  int64_t frame_step = 1);

}  // namespace plumb::tools
