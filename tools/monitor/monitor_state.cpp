// SPDX-License-Identifier: Apache-2.0
#include "tools/monitor/monitor_state.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "common/core/timing.hpp"
#include "common/geometry/polygon.hpp"
#include "common/layout/layout_json.hpp"

namespace plumb::monitor {

using nlohmann::json;

void describe(config::Schema& s, MonitorStateConfig& c) {
    s.field("sample_points_per_fragment", c.sample_points_per_fragment,
            "surface points kept per fragment for outlines and coverage", "points")
        .min(16);
    s.field("coverage_cell_m", c.coverage_cell_m, "coverage grid cell edge", "m")
        .positive()
        .max(10.0);
    s.field("closed_room_wall_fraction", c.closed_room_wall_fraction,
            "coverage is measured against the layout's room only when this fraction of its "
            "outline lies on walls; else the room's coverage is unknown")
        .min(0.0)
        .max(1.0);
    s.field("device_stale_after_s", c.device_stale_after_s,
            "a heartbeat older than this marks the device stale", "s")
        .positive();
    s.field("max_gap_cells", c.max_gap_cells, "gap cells listed in the state JSON at most", "cells")
        .min(0);
    s.field("max_trajectory_points", c.max_trajectory_points,
            "trajectory positions listed in the state JSON at most", "points")
        .min(0);
    s.field("max_errors", c.max_errors, "recent errors kept for the page").min(1);
}

namespace {

json matrixJson(const Eigen::Matrix4d& m) {
    json rows = json::array();
    for (int r = 0; r < 4; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
    return rows;
}

json pointJson(const Eigen::Vector2d& p) { return json::array({p.x(), p.y()}); }

const char* trackingName(messages::TrackingState s) {
    switch (s) {
        case messages::TrackingState::kInitializing:
            return "initializing";
        case messages::TrackingState::kOk:
            return "ok";
        case messages::TrackingState::kLost:
            return "lost";
        case messages::TrackingState::kStopped:
            return "stopped";
        case messages::TrackingState::kNoCamera:
            return "no camera";
    }
    return "unknown";
}

Result<Eigen::Isometry3d> poseFromJson(const json& j, const std::string& where) {
    if (!j.is_array() || (j.size() != 4 && j.size() != 3)) {
        return corrupt(where + ": expected a 4x4 (or 3x4) matrix");
    }
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    for (size_t r = 0; r < j.size(); ++r) {
        if (!j[r].is_array() || j[r].size() != 4) return corrupt(where + ": rows need 4 numbers");
        for (size_t c = 0; c < 4; ++c) {
            if (!j[r][c].is_number()) return corrupt(where + ": non-numeric entry");
            const double v = j[r][c].get<double>();
            if (!std::isfinite(v)) return corrupt(where + ": non-finite entry");
            m(static_cast<int>(r), static_cast<int>(c)) = v;
        }
    }
    const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
    if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-4 || R.determinant() < 0) {
        return corrupt(where + ": not a rotation");
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = R;
    T.translation() = m.topRightCorner<3, 1>();
    return T;
}

}  // namespace

Result<PoseGraphView> poseGraphFromJson(const json& j, const std::string& source) {
    if (!j.is_object()) return corrupt(source + ": not a JSON object");
    PoseGraphView g;
    const json* nodes = j.contains("nodes") ? &j["nodes"] : nullptr;
    if (nodes == nullptr || !nodes->is_array()) return corrupt(source + ": nodes: missing array");
    for (size_t i = 0; i < nodes->size(); ++i) {
        const json& n = (*nodes)[i];
        const std::string where = fmt::format("{}: nodes[{}]", source, i);
        if (!n.is_object() || !n.contains("T_W_F")) return corrupt(where + ": missing T_W_F");
        auto T = poseFromJson(n["T_W_F"], where + ".T_W_F");
        if (!T.isOk()) return T.status();
        g.T_W_F.push_back(*T);
    }
    const json* edges = j.contains("edges") ? &j["edges"] : nullptr;
    if (edges == nullptr || !edges->is_array()) return corrupt(source + ": edges: missing array");
    for (size_t i = 0; i < edges->size(); ++i) {
        const json& e = (*edges)[i];
        const std::string where = fmt::format("{}: edges[{}]", source, i);
        if (!e.is_object()) return corrupt(where + ": not an object");
        EdgeView v;
        auto index = [&](const char* key, uint32_t& out) -> Status {
            if (!e.contains(key) || !e[key].is_number_integer() || e[key].get<int64_t>() < 0 ||
                e[key].get<int64_t>() >= static_cast<int64_t>(g.T_W_F.size())) {
                return corrupt(fmt::format("{}.{}: missing or not a node index", where, key));
            }
            out = e[key].get<uint32_t>();
            return Status::ok();
        };
        PLUMB_RETURN_IF_ERROR(index("source", v.source));
        PLUMB_RETURN_IF_ERROR(index("target", v.target));
        if (!e.contains("kind") || !e["kind"].is_string()) {
            return corrupt(where + ".kind: missing string");
        }
        v.kind = e["kind"].get<std::string>();
        if (v.kind != "odometry" && v.kind != "loop") {
            return corrupt(where + ".kind: '" + v.kind + "' is neither odometry nor loop");
        }
        auto number = [&](const char* key, double& out, double lo, double hi) -> Status {
            if (!e.contains(key)) return Status::ok();  // optional: keeps the default
            if (!e[key].is_number()) return corrupt(fmt::format("{}.{}: not a number", where, key));
            out = e[key].get<double>();
            if (!std::isfinite(out) || out < lo || out > hi) {
                return corrupt(fmt::format("{}.{}: {} outside [{}, {}]", where, key, out, lo, hi));
            }
            return Status::ok();
        };
        PLUMB_RETURN_IF_ERROR(number("line_process", v.line_process, 0.0, 1.0));
        PLUMB_RETURN_IF_ERROR(number("overlap", v.overlap, 0.0, 1.0));
        PLUMB_RETURN_IF_ERROR(number("inlier_rmse_m", v.inlier_rmse_m, 0.0, 1e6));
        if (e.contains("kept")) {
            if (!e["kept"].is_boolean()) return corrupt(where + ".kept: not a boolean");
            v.kept = e["kept"].get<bool>();
        }
        if (e.contains("reason") && e["reason"].is_string()) v.reason = e["reason"];
        g.edges.push_back(std::move(v));
    }
    return g;
}

MonitorState::MonitorState(MonitorStateConfig config) : config_(config), start_(Clock::now()) {}

void MonitorState::bumpLocked() {
    ++version_;
    changed_.notify_all();
}

void MonitorState::setSource(const std::string& mode, const std::string& detail) {
    std::lock_guard lock(mutex_);
    source_mode_ = mode;
    source_detail_ = detail;
    bumpLocked();
}

void MonitorState::addFragment(const Fragment& fragment, int64_t session_id,
                               const std::string& origin) {
    FragmentEntry e;
    e.session_id = session_id;
    e.id = fragment.id;
    e.segment = fragment.segment;
    e.end = fragment.end;
    e.num_frames = static_cast<int>(fragment.frames.size());
    if (!fragment.frames.empty()) {
        e.first_frame = fragment.frames.front().frame_index;
        e.last_frame = fragment.frames.back().frame_index;
    }
    e.num_points = static_cast<int64_t>(fragment.points_F.size());
    e.tracking_quality = fragment.tracking_quality;
    e.voxel_size_m = fragment.voxel_size_m;
    e.T_W_F_odometry = fragment.T_W_F;
    e.origin = origin;
    e.received_unix_s = wallClockSeconds();
    // An even subsample (every k-th point) keeps the spatial spread of the surface.
    const size_t n = fragment.points_F.size();
    const size_t keep =
        std::min<size_t>(n, static_cast<size_t>(config_.sample_points_per_fragment));
    e.sample_F.reserve(keep);
    for (size_t i = 0; i < keep; ++i) {
        e.sample_F.push_back(fragment.points_F.points[i * n / keep]);
    }
    std::lock_guard lock(mutex_);
    auto key = std::make_pair(session_id, fragment.id);
    auto it = fragments_.find(key);
    if (it != fragments_.end()) e.ack = it->second.ack;
    fragments_[key] = std::move(e);
    bumpLocked();
}

void MonitorState::setFragmentAck(int64_t session_id, uint32_t fragment_id, bool persisted) {
    std::lock_guard lock(mutex_);
    auto it = fragments_.find({session_id, fragment_id});
    if (it == fragments_.end()) return;
    const int ack = persisted ? 1 : -1;
    if (it->second.ack == ack) return;
    it->second.ack = ack;
    bumpLocked();
}

void MonitorState::setPoseGraph(std::optional<PoseGraphView> graph) {
    std::lock_guard lock(mutex_);
    pose_graph_ = std::move(graph);
    bumpLocked();
}

void MonitorState::setLayout(std::optional<Layout> layout) {
    std::lock_guard lock(mutex_);
    layout_ = std::move(layout);
    bumpLocked();
}

void MonitorState::setTrajectory(std::vector<Eigen::Vector3d> positions_W) {
    std::lock_guard lock(mutex_);
    trajectory_W_ = std::move(positions_W);
    bumpLocked();
}

void MonitorState::setDevice(const messages::DeviceStatus& status, int64_t utime, int64_t seq) {
    std::lock_guard lock(mutex_);
    device_ = status;
    device_utime_ = utime;
    device_seq_ = seq;
    device_received_ = Clock::now();
    bumpLocked();
}

void MonitorState::setLinkStats(const messages::FragmentAssemblerStats& stats, uint64_t messages,
                                uint64_t malformed) {
    std::lock_guard lock(mutex_);
    link_stats_ = stats;
    link_messages_ = messages;
    link_malformed_ = malformed;
    bumpLocked();
}

void MonitorState::setReplayProgress(uint64_t messages, bool finished) {
    std::lock_guard lock(mutex_);
    replay_ = std::make_pair(messages, finished);
    bumpLocked();
}

void MonitorState::setRunStatus(std::optional<std::string> status) {
    std::lock_guard lock(mutex_);
    if (run_status_ == status) return;
    run_status_ = std::move(status);
    bumpLocked();
}

void MonitorState::addError(const std::string& message) {
    std::lock_guard lock(mutex_);
    errors_.push_back(message);
    if (errors_.size() > static_cast<size_t>(config_.max_errors)) errors_.erase(errors_.begin());
    bumpLocked();
}

uint64_t MonitorState::version() const {
    std::lock_guard lock(mutex_);
    return version_;
}

uint64_t MonitorState::waitForChange(uint64_t seen, std::chrono::milliseconds timeout) const {
    std::unique_lock lock(mutex_);
    changed_.wait_for(lock, timeout, [&] { return version_ != seen; });
    return version_;
}

void MonitorState::notifyAll() const { changed_.notify_all(); }

size_t MonitorState::numFragments() const {
    std::lock_guard lock(mutex_);
    return fragments_.size();
}

json MonitorState::toJson(uint64_t* version) const {
    std::lock_guard lock(mutex_);
    if (version != nullptr) *version = version_;
    return buildJsonLocked();
}

std::string MonitorState::toJsonText(uint64_t* version) const {
    std::lock_guard lock(mutex_);
    if (version != nullptr) *version = version_;
    if (cached_version_ != version_) {
        cached_text_ = buildJsonLocked().dump();
        cached_version_ = version_;
    }
    return cached_text_;
}

json MonitorState::buildJsonLocked() const {
    json j;
    j["format"] = "plumb-monitor-state-1";
    j["version"] = version_;
    j["source"] = {{"mode", source_mode_}, {"detail", source_detail_}};
    if (replay_) {
        j["source"]["replay"] = {{"messages", replay_->first}, {"finished", replay_->second}};
    }
    j["source"]["run_status"] = run_status_ ? json(*run_status_) : json(nullptr);

    const Eigen::Isometry3d T_V_W = viewFromWorld(layout_ ? &*layout_ : nullptr);
    j["view"] = {{"frame", layout_ ? "layout" : "first-camera"},
                 {"T_V_W", matrixJson(T_V_W.matrix())}};

    // The newest session is the one a pose graph describes (node i = fragment i).
    const int64_t newest_session = fragments_.empty() ? 0 : fragments_.rbegin()->first.first;
    std::vector<Eigen::Vector2d> all_points_V;
    j["fragments"] = fragmentsJsonLocked(T_V_W, newest_session, &all_points_V);
    j["edges"] = edgesJsonLocked(newest_session);
    j["layout"] = layoutJsonLocked();
    j["device"] = deviceJsonLocked();
    j["link"] = linkJsonLocked();
    j["trajectory_V"] = trajectoryJsonLocked(T_V_W);
    j["coverage"] = coverageJsonLocked(all_points_V);
    j["errors"] = errors_;
    j["uptime_s"] = std::chrono::duration<double>(Clock::now() - start_).count();
    return j;
}

json MonitorState::fragmentsJsonLocked(const Eigen::Isometry3d& T_V_W, int64_t newest_session,
                                       std::vector<Eigen::Vector2d>* all_points_V) const {
    json fragments = json::array();
    for (const auto& [key, f] : fragments_) {
        const bool from_graph =
            pose_graph_ && f.session_id == newest_session && f.id < pose_graph_->T_W_F.size();
        const Eigen::Isometry3d T_W_F = from_graph ? pose_graph_->T_W_F[f.id] : f.T_W_F_odometry;
        const Eigen::Isometry3d T_V_F = T_V_W * T_W_F;
        std::vector<Eigen::Vector2d> pts;
        pts.reserve(f.sample_F.size());
        for (const Eigen::Vector3f& p : f.sample_F) {
            pts.push_back((T_V_F * p.cast<double>()).head<2>());
        }
        all_points_V->insert(all_points_V->end(), pts.begin(), pts.end());
        json outline = json::array();
        for (const auto& q : convexHull(pts)) outline.push_back(pointJson(q));
        json o;
        o["id"] = f.id;
        o["session"] = f.session_id;
        o["segment"] = f.segment;
        o["end"] = toString(f.end);
        o["frames"] = {f.first_frame, f.last_frame};
        o["num_frames"] = f.num_frames;
        o["num_points"] = f.num_points;
        o["tracking_quality"] = f.tracking_quality;
        o["voxel_size_m"] = f.voxel_size_m;
        o["pose"] = matrixJson(T_W_F.matrix());
        o["pose_source"] = from_graph ? "pose_graph" : "odometry";
        o["position_V"] = pointJson(T_V_F.translation().head<2>());
        o["outline_V"] = std::move(outline);
        o["origin"] = f.origin;
        o["received_unix_s"] = f.received_unix_s;
        o["ack"] = f.ack == 1 ? "persisted" : (f.ack == -1 ? "rejected" : "none");
        fragments.push_back(std::move(o));
    }
    return fragments;
}

json MonitorState::edgesJsonLocked(int64_t newest_session) const {
    // Edges: the pose graph's, plus odometry edges implied by consecutive fragments of one
    // segment that the graph does not cover yet.
    json edges = json::array();
    auto edgeJson = [](const EdgeView& e) {
        return json{{"source", e.source},
                    {"target", e.target},
                    {"kind", e.kind},
                    {"line_process", e.line_process},
                    {"kept", e.kept},
                    {"reason", e.reason},
                    {"overlap", e.overlap},
                    {"inlier_rmse_m", e.inlier_rmse_m},
                    {"provisional", e.provisional}};
    };
    const size_t graph_nodes = pose_graph_ ? pose_graph_->T_W_F.size() : 0;
    if (pose_graph_) {
        for (const EdgeView& e : pose_graph_->edges) edges.push_back(edgeJson(e));
    }
    for (auto it = fragments_.begin(); it != fragments_.end(); ++it) {
        auto next = std::next(it);
        if (next == fragments_.end()) break;
        const FragmentEntry& a = it->second;
        const FragmentEntry& b = next->second;
        if (a.session_id != b.session_id || b.id != a.id + 1 || a.segment != b.segment) continue;
        if (a.session_id == newest_session && b.id < graph_nodes) continue;  // the graph has it
        EdgeView e;
        e.source = a.id;
        e.target = b.id;
        e.provisional = true;
        e.reason = "fragment odometry";
        edges.push_back(edgeJson(e));
    }
    return edges;
}

json MonitorState::layoutJsonLocked() const {
    if (!layout_) return nullptr;
    json l = io::layoutToJson(*layout_);
    // V = L when a layout is known, so the floor plan is the room polygon as it is.
    json polygon = json::array();
    for (const auto& p : layout_->room_polygon_L) polygon.push_back(pointJson(p));
    l["room_polygon_V"] = std::move(polygon);
    json walls = json::array();
    for (const LayoutPlane* w : layout_->walls()) {
        walls.push_back({{"id", w->id},
                         {"start_V", pointJson(w->start_L)},
                         {"end_V", pointJson(w->end_L)},
                         {"manhattan_snapped", w->manhattan_snapped}});
    }
    l["walls_V"] = std::move(walls);
    return l;
}

json MonitorState::deviceJsonLocked() const {
    if (!device_) return nullptr;
    const messages::DeviceStatus& d = *device_;
    const double age_s = std::chrono::duration<double>(Clock::now() - device_received_).count();
    return {
        {"session_id", d.session_id},
        {"fps", d.fps},
        {"tracking", trackingName(d.tracking)},
        {"frames_processed", d.frames_processed},
        {"frames_dropped", d.frames_dropped},
        {"processed_fraction", messages::processedFraction(d.frames_processed, d.frames_dropped)},
        {"fragments_cut", d.fragments_cut},
        {"fragments_acked", d.fragments_acked},
        {"spool_fragments", d.spool_fragments},
        {"spool_bytes", d.spool_bytes},
        {"memory_bytes", d.memory_bytes},
        {"utime", device_utime_},
        {"seq", device_seq_},
        {"received_unix_s", wallClockSeconds() - age_s},
        {"stale_after_s", config_.device_stale_after_s}};
}

json MonitorState::linkJsonLocked() const {
    if (!link_stats_) return nullptr;
    const auto& s = *link_stats_;
    return {{"messages", link_messages_},
            {"malformed", link_malformed_ + s.malformed_messages},
            {"chunks_received", s.chunks_received},
            {"duplicate_chunks", s.duplicate_chunks},
            {"chunk_crc_failures", s.chunk_crc_failures},
            {"fragment_crc_failures", s.fragment_crc_failures},
            {"fragments_completed", s.fragments_completed},
            {"partial_fragments_evicted", s.fragments_evicted}};
}

json MonitorState::trajectoryJsonLocked(const Eigen::Isometry3d& T_V_W) const {
    json traj = json::array();
    const size_t n = trajectory_W_.size();
    const size_t keep = std::min<size_t>(n, static_cast<size_t>(config_.max_trajectory_points));
    for (size_t i = 0; i < keep; ++i) {
        const size_t k = keep > 1 ? i * (n - 1) / (keep - 1) : 0;
        traj.push_back(pointJson((T_V_W * trajectory_W_[k]).head<2>()));
    }
    return traj;
}

json MonitorState::coverageJsonLocked(const std::vector<Eigen::Vector2d>& all_points_V) const {
    CoverageConfig cc;
    cc.cell_m = config_.coverage_cell_m;
    // Against the room only when the layout has closed it with walls: an outline that is the
    // seen floor's own edge would call any scan complete.
    const double wall_fraction = layout_ ? wallBoundedFraction(*layout_) : 0.0;
    const bool room_closed = layout_ && wall_fraction >= config_.closed_room_wall_fraction;
    const CoverageGrid grid = computeCoverage(
        all_points_V, room_closed ? layout_->room_polygon_L : std::vector<Eigen::Vector2d>{}, cc);
    json gaps = json::array();
    for (size_t i = 0; i < grid.gaps.size() && i < static_cast<size_t>(config_.max_gap_cells);
         ++i) {
        gaps.push_back({grid.gaps[i].x(), grid.gaps[i].y()});
    }
    return {{"cell_m", grid.cell_m},
            {"origin_V", pointJson(grid.origin_V)},
            {"width", grid.width},
            {"height", grid.height},
            {"region", grid.room_polygon ? "room_polygon" : "convex_hull"},
            {"room_closed", room_closed},
            {"wall_bounded_fraction", layout_ ? json(wall_fraction) : json(nullptr)},
            {"cells_of_interest", grid.cells_of_interest},
            {"covered_cells", grid.covered_of_interest},
            {"fraction", grid.coverageFraction()},
            {"room_fraction", room_closed ? json(grid.coverageFraction()) : json(nullptr)},
            {"num_gaps", grid.gaps.size()},
            {"gaps", std::move(gaps)}};
}

}  // namespace plumb::monitor
