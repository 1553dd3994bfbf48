// SPDX-License-Identifier: Apache-2.0
#pragma once

// What the monitor shows: fragments as they arrive, the pose graph, the layout, the device's
// heartbeat and the coverage of the floor. Fed by the sources in tools/monitor/sources.hpp, read
// by the HTTP server as one JSON document (`GET /api/state`, and every server-sent event).
//
// Thread-safety: every public function may be called from any thread; a mutex guards the model
// and a condition variable wakes waiters (waitForChange) on every update.

#include <nlohmann/json.hpp>

#include <Eigen/Geometry>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/config/schema.hpp"
#include "common/fragment/fragment.hpp"
#include "common/layout/layout.hpp"
#include "messages/conversions.hpp"
#include "messages/fragment_assembler.hpp"
#include "tools/monitor/top_view.hpp"

namespace plumb::monitor {

struct MonitorStateConfig {
    /// Points kept per fragment for outlines and coverage (an even subsample of the surface).
    int sample_points_per_fragment = 4000;
    /// Coverage grid cell edge, metres.
    double coverage_cell_m = 0.25;
    /// Coverage is measured against the layout's room only when at least this fraction of the
    /// room outline lies on walls (a closed room); below it the outline is mostly the edge of the
    /// seen floor, against which any scan is complete, and the room's coverage is unknown.
    double closed_room_wall_fraction = kClosedRoomWallFraction;
    /// A heartbeat older than this marks the device stale, seconds.
    double device_stale_after_s = 3.0;
    /// Gap cells listed in the JSON at most (the counts are always complete).
    int max_gap_cells = 20000;
    /// Trajectory positions listed in the JSON at most (evenly thinned).
    int max_trajectory_points = 2000;
    /// Recent errors kept for the page.
    int max_errors = 20;
};
void describe(config::Schema& s, MonitorStateConfig& c);

/// One pose-graph edge as shown (pose_graph.json, or an odometry edge implied by two consecutive
/// fragments of one tracking segment before the backend has produced a graph).
struct EdgeView {
    uint32_t source = 0;
    uint32_t target = 0;
    std::string kind = "odometry";  ///< "odometry" | "loop"
    double line_process = 1.0;      ///< line-process weight l in [0, 1]
    bool kept = true;
    std::string reason;
    double overlap = 0.0;
    double inlier_rmse_m = 0.0;
    bool provisional = false;  ///< implied by fragment odometry, not yet from a pose graph
};

/// Nodes and edges of a pose graph (pose_graph.json).
struct PoseGraphView {
    std::vector<Eigen::Isometry3d> T_W_F;  ///< optimised fragment -> world, node i = fragment i
    std::vector<EdgeView> edges;
};

/// Parses the pose_graph.json document the registration stage writes (nodes[].T_W_F 4x4,
/// edges[] with source, target, kind, kept, reason, overlap, inlier_rmse_m, line_process).
/// Corrupt naming the field for malformed content; `source` names the document in errors.
Result<PoseGraphView> poseGraphFromJson(const nlohmann::json& json, const std::string& source);

class MonitorState {
  public:
    using Clock = std::chrono::steady_clock;

    explicit MonitorState(MonitorStateConfig config = {});

    /// Where the data comes from, shown on the page ("directory", "live", "replay").
    void setSource(const std::string& mode, const std::string& detail);
    /// A fragment arrived (decoded). A fragment already held (same session and id) is replaced.
    void addFragment(const Fragment& fragment, int64_t session_id, const std::string& origin);
    /// The backend acknowledged (persisted = true) or rejected a fragment.
    void setFragmentAck(int64_t session_id, uint32_t fragment_id, bool persisted);
    void setPoseGraph(std::optional<PoseGraphView> graph);
    void setLayout(std::optional<Layout> layout);
    /// Camera positions of the trajectory in W (trajectory.txt).
    void setTrajectory(std::vector<Eigen::Vector3d> positions_W);
    void setDevice(const messages::DeviceStatus& status, int64_t utime, int64_t seq);
    void setLinkStats(const messages::FragmentAssemblerStats& stats, uint64_t messages,
                      uint64_t malformed);
    /// Replay progress: messages dispatched so far; finished when the log ended.
    void setReplayProgress(uint64_t messages, bool finished);
    /// How the run that wrote the watched directory ended: metrics.json's "status" ("complete",
    /// "interrupted", ...), written once the run is over; nullopt while it is not there.
    void setRunStatus(std::optional<std::string> status);
    /// Records a problem for the page (the newest max_errors are kept).
    void addError(const std::string& message);

    /// Increases with every update.
    uint64_t version() const;
    /// Blocks until version() != seen or `timeout` passed; returns the version then.
    uint64_t waitForChange(uint64_t seen, std::chrono::milliseconds timeout) const;
    /// Wakes every waitForChange (used when shutting down).
    void notifyAll() const;

    /// The whole state as JSON, "format": "plumb-monitor-state-1", and its version. Keys: source
    /// (mode, detail, replay {messages, finished} for a log, run_status: metrics.json's status of
    /// the watched directory, null until the run has ended), view (frame, T_V_W), fragments[] (id,
    /// session, segment, end, frames [first, last], num_points, pose = current T_W_F, pose_source,
    /// position_V, outline_V, ack, ...), edges[] (source, target, kind, line_process, kept, reason,
    /// overlap, inlier_rmse_m, provisional), layout (layout.json content + room_polygon_V, walls_V;
    /// null), device (heartbeat; null), link (reassembly counters; null), trajectory_V, coverage
    /// (grid, fraction, gaps), errors.
    nlohmann::json toJson(uint64_t* version = nullptr) const;
    /// toJson() serialised compactly (one line), cached per version.
    std::string toJsonText(uint64_t* version = nullptr) const;

    size_t numFragments() const;

  private:
    struct FragmentEntry {
        int64_t session_id = 0;
        uint32_t id = 0;
        uint32_t segment = 0;
        FragmentEnd end = FragmentEnd::kFrameCount;
        int64_t first_frame = 0;
        int64_t last_frame = 0;
        int num_frames = 0;
        int64_t num_points = 0;
        double tracking_quality = 0.0;
        double voxel_size_m = 0.0;
        Eigen::Isometry3d T_W_F_odometry = Eigen::Isometry3d::Identity();
        std::vector<Eigen::Vector3f> sample_F;
        std::string origin;
        double received_unix_s = 0.0;
        int ack = 0;  ///< 0 none, 1 persisted, -1 rejected
    };
    void bumpLocked();
    nlohmann::json buildJsonLocked() const;
    // The parts of buildJsonLocked's state, with mutex_ held. `T_V_W` places the world in the
    // view; fragments of `newest_session` take the pose graph's poses.
    nlohmann::json fragmentsJsonLocked(const Eigen::Isometry3d& T_V_W, int64_t newest_session,
                                       std::vector<Eigen::Vector2d>* all_points_V) const;
    nlohmann::json edgesJsonLocked(int64_t newest_session) const;
    nlohmann::json layoutJsonLocked() const;
    nlohmann::json deviceJsonLocked() const;
    nlohmann::json linkJsonLocked() const;
    nlohmann::json trajectoryJsonLocked(const Eigen::Isometry3d& T_V_W) const;
    nlohmann::json coverageJsonLocked(const std::vector<Eigen::Vector2d>& all_points_V) const;

    MonitorStateConfig config_;
    mutable std::mutex mutex_;
    mutable std::condition_variable changed_;
    uint64_t version_ = 1;
    Clock::time_point start_;

    std::string source_mode_;
    std::string source_detail_;
    std::map<std::pair<int64_t, uint32_t>, FragmentEntry> fragments_;
    std::optional<PoseGraphView> pose_graph_;
    std::optional<Layout> layout_;
    std::vector<Eigen::Vector3d> trajectory_W_;
    std::optional<messages::DeviceStatus> device_;
    int64_t device_utime_ = 0;
    int64_t device_seq_ = 0;
    Clock::time_point device_received_;
    std::optional<messages::FragmentAssemblerStats> link_stats_;
    uint64_t link_messages_ = 0;
    uint64_t link_malformed_ = 0;
    std::optional<std::pair<uint64_t, bool>> replay_;
    std::optional<std::string> run_status_;
    std::vector<std::string> errors_;

    mutable uint64_t cached_version_ = 0;
    mutable std::string cached_text_;
};

}  // namespace plumb::monitor
