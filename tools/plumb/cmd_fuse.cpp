// SPDX-License-Identifier: Apache-2.0
// `plumb fuse`: the device's tracking and fusion over a dataset or the simulated scanner, writing
// every fragment (oriented surface points as PLY, metadata as JSON) for inspection, and measuring
// each fragment against whatever ground truth the source carries.

#include <fmt/format.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <numeric>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "common/config/config.hpp"
#include "common/core/logging.hpp"
#include "common/core/progress.hpp"
#include "common/eval/surface_distance.hpp"
#include "common/eval/trajectory_metrics.hpp"
#include "common/geometry/lie.hpp"
#include "common/io/ply.hpp"
#include "common/io/state_archive.hpp"
#include "common/io/text_file.hpp"
#include "common/io/trajectory.hpp"
#include "device/fusion/fragment_builder.hpp"
#include "device/fusion/fuse_frames.hpp"
#include "device/fusion/live_rate.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "messages/files.hpp"
#include "tools/plumb/command.hpp"
#include "tools/plumb/interrupt.hpp"
#include "tools/plumb/output_folder.hpp"
#include "tools/plumb/run_record.hpp"
#include "tools/plumb/scan_source.hpp"
#include "tools/plumb/source_arguments.hpp"

namespace plumb::tools {
namespace {

constexpr const char* kUsage =
    "usage: plumb fuse <source> --out DIR [options]\n"
    "       plumb fuse --resume DIR [--quiet] [--threads N]\n"
    "\n"
    "Runs the on-device pipeline (preprocessing, frame-to-model ICP tracking, voxel-hashed TSDF\n"
    "fusion, a fragment every N frames) over a recorded dataset or the simulated scanner and\n"
    "writes every fragment for inspection:\n"
    "  fragment_NNN.ply    oriented surface points in the fragment frame (coloured when the\n"
    "                      source has colour)\n"
    "  fragment_NNN.json   id, segment, why it was closed, T_W_F, frames (index, timestamp,\n"
    "                      T_F_C, tracking_ok, unconstrained_translations: how many\n"
    "                      translations the depth in view left free, along which the pose\n"
    "                      follows the constant-velocity prediction), frames_unconstrained\n"
    "                      (frames with any), depth_only (a frame with colour tracked by\n"
    "                      depth alone, and why: too little texture, or the photometric term\n"
    "                      rejected), frames_depth_only, tracking quality,\n"
    "                      odometry_information (the tracker's 6x6 J^T J of this fragment's\n"
    "                      pose relative to the previous one, rotation first; absent for a\n"
    "                      segment's first fragment), errors against ground truth\n"
    "  fragments.json      summary: status (complete or interrupted), source, timing,\n"
    "                      per-fragment figures, frames_photometric (tracked RGB-D),\n"
    "                      frames_depth_only and depth_only_reasons, frames_tracked_only\n"
    "                      (tracked, not fused: a camera faster than\n"
    "                      fusion.max_integration_hz), processed_fraction\n"
    "                      (frames fused of those read: --frame-step), live (sensor_hz from\n"
    "                      the timestamps, keeps_fraction: the share of the camera's frames a\n"
    "                      live device as fast as this run would process, each frame's time\n"
    "                      replayed through plumb-device's capture queue of queue_frames;\n"
    "                      longest_drop_run: most frames it would drop one after the other;\n"
    "                      max_latency_ms; frames_timed: the frames replayed, all fused ones\n"
    "                      unless resumed from an older checkpoint; keeps_fraction_by_mean:\n"
    "                      period / mean frame time)\n"
    "  trajectory.txt      odometry (TUM, camera->world = T_W_F * T_F_C of tracked frames)\n"
    "  config.toml         the effective configuration\n"
    "  resume/             what --resume continues from (removed when the run completes)\n"
    "With ground truth (simulator, TUM/ICL-NUIM groundtruth.txt) each fragment gets its ATE\n"
    "(Horn-aligned, over its tracked frames), its drift (error of the last frame relative to the\n"
    "first) and, for the simulator, the median distance of its surface to the true room.\n"
    "\n"
    "Ctrl-C (or SIGTERM) stops at the next frame: the fragments written so far, the trajectory\n"
    "tracked so far (trajectory.txt, the open fragment's frames included) and fragments.json\n"
    "with \"status\": \"interrupted\" and how far it got are kept, and `plumb fuse --resume DIR`\n"
    "continues the run, giving the same files byte for byte as a run never interrupted, but for\n"
    "the measured times in fragments.json (ms_per_frame and the live figures), which differ\n"
    "between any two runs, and its live.threads when --resume is given another --threads. A\n"
    "second Ctrl-C stops at once.\n"
    "\n"
    "source:\n"
    "  DIR | dataset:DIR  a TUM, ICL-NUIM, Redwood, 7-Scenes or plumb-sim folder (detected)\n"
    "  sim:SCENE          the simulated scanner (living_room, weak_manhattan, l_shape,\n"
    "                     corridor, or a scene .toml file)\n"
    "  store:DIR[?session=ID]  the raw frames plumb-backend kept of a live scan in its\n"
    "                     fragment store DIR (streamed with plumb-device --set\n"
    "                     stream.raw_frame_every=1; the newest session unless named)\n"
    "\n"
    "options:\n"
    "  --out DIR          output folder (required; created when missing). A folder that is\n"
    "                     not empty is refused, so that no earlier run's files mix in\n"
    "  --force            clear a non-empty --out folder of an earlier plumb run first\n"
    "                     (default: refuse it)\n"
    "  --resume DIR       continue the run interrupted in DIR, with its options; only --quiet\n"
    "                     and --threads may be given besides (default: a new run)\n"
    "  --frames N         use the first N frames only (default: all; the simulator 600)\n"
    "  --frame-step X     process only frames floor(j X), j = 0, 1, ... (X >= 1, may be\n"
    "                     fractional): what a live device that keeps up with 1/X of the sensor\n"
    "                     rate does when it drops the frames it has no time for (default 1)\n"
    "  --intrinsics X     camera preset or intrinsics file (default: detected)\n"
    "  --depth-scale S    depth units per metre (default: the dataset's)\n"
    "  --seed S           seed of the simulator (default 1)\n"
    "  --noise MODE       simulator noise: redwood (default), off, parametric, undistorted\n"
    "  --depth-calibration X  undistort depth: sensor (default: the sensor's own table), none,\n"
    "                     or a CLAMS/Redwood dist-model.txt\n"
    "  --no-colour        read depth only, even when the source has colour (default: colour\n"
    "                     when the source has it)\n"
    "  --threads N        worker threads (default: all); results do not depend on it\n"
    "  --config FILE      configuration file (see `plumb config doc fusion`; default: none,\n"
    "                     every key at its default)\n"
    "  --set KEY=VALUE    override one configuration key, e.g. frames_per_fragment=100\n"
    "                     (repeatable)\n"
    "  --quiet            no progress output (default: a progress line on stderr)\n"
    "  -h, --help         this text\n"
    "\n"
    "exit status: 0 done, 1 the input failed (the message says which), 2 bad command line,\n"
    "130 interrupted (the work so far kept; see --resume).\n";

constexpr const char* kCommand = "fuse";

/// The checkpoint of an interrupted run: DIR/resume/fuse_state.bin. Version 3 holds each fused
/// frame's time (FuseTally::frame_ms). Version-2 checkpoints were written both with them and,
/// earlier, without: both restore (without them, the live figures replay only the frames timed
/// after the resume).
constexpr uint32_t kCheckpointMagic = 0x46465250u;  // "PRFF"
constexpr uint32_t kCheckpointVersion = 3;
constexpr int64_t kMaxCheckpointBytes = int64_t{1} << 34;

struct FuseOptions {
    std::string source;
    std::filesystem::path out;
    SourceOptions source_options;
    int threads = 0;
    bool quiet = false;
    bool force = false;
    /// Process source frame floor(j * frame_step) for j = 0, 1, ... and drop the others.
    double frame_step = 1.0;
};

nlohmann::json poseJson(const Eigen::Isometry3d& T) {
    nlohmann::json rows = nlohmann::json::array();
    for (int r = 0; r < 4; ++r) {
        rows.push_back({T.matrix()(r, 0), T.matrix()(r, 1), T.matrix()(r, 2), T.matrix()(r, 3)});
    }
    return rows;
}

/// Ground truth known for the frames of the stream, by frame index.
struct FrameTruth {
    std::vector<std::optional<Eigen::Isometry3d>> T_W_C;  ///< by frame index
    std::optional<Eigen::Isometry3d> at(int64_t index) const {
        if (index < 0 || static_cast<size_t>(index) >= T_W_C.size()) return std::nullopt;
        return T_W_C[static_cast<size_t>(index)];
    }
};

/// Accuracy of one fragment against ground truth.
struct FragmentAccuracy {
    std::optional<eval::AteResult> ate;
    std::optional<double> drift_m, drift_deg;
    std::optional<double> surface_median_m;
};

FragmentAccuracy measureFragment(const Fragment& f, const FrameTruth& truth,
                                 const PointCloud* gt_surface_W) {
    FragmentAccuracy acc;
    std::vector<Eigen::Vector3d> est, gt;
    std::optional<Eigen::Isometry3d> first_gt;
    const FragmentFrame* last_ok = nullptr;
    std::optional<Eigen::Isometry3d> last_gt;
    for (const FragmentFrame& fr : f.frames) {
        const std::optional<Eigen::Isometry3d> T = truth.at(fr.frame_index);
        if (&fr == &f.frames.front()) first_gt = T;
        if (!fr.tracking_ok || !T) continue;
        est.push_back(fr.T_F_C.translation());
        gt.push_back(T->translation());
        last_ok = &fr;
        last_gt = T;
    }
    if (est.size() >= 3) {
        Result<eval::AteResult> ate = eval::computeAte(est, gt);
        if (ate.isOk()) acc.ate = std::move(*ate);
    }
    if (first_gt && last_ok != nullptr && last_gt) {
        // Frame 0 of a fragment is its origin: compare relative motions first -> last.
        const Eigen::Isometry3d rel_gt = first_gt->inverse() * *last_gt;
        const Eigen::Isometry3d err = rel_gt.inverse() * last_ok->T_F_C;
        acc.drift_m = err.translation().norm();
        acc.drift_deg = lie::rotationAngle(err) * 180.0 / std::numbers::pi;
    }
    if (gt_surface_W != nullptr && first_gt && !f.points_F.points.empty()) {
        // The surface placed with the true pose of the fragment's first frame.
        const Eigen::Isometry3f T_W_F = first_gt->cast<float>();
        std::vector<Eigen::Vector3f> points_W;
        points_W.reserve(f.points_F.points.size());
        for (const Eigen::Vector3f& p : f.points_F.points) points_W.push_back(T_W_F * p);
        Result<std::vector<double>> d =
            eval::pointToSurfaceDistances(points_W, *gt_surface_W, 0.05);
        if (d.isOk()) acc.surface_median_m = eval::median(std::move(*d));
    }
    return acc;
}

nlohmann::json fragmentJson(const Fragment& f, const FragmentAccuracy& acc) {
    nlohmann::json j;
    j["id"] = f.id;
    j["segment"] = f.segment;
    j["end"] = toString(f.end);
    j["T_W_F"] = poseJson(f.T_W_F);
    j["voxel_size_m"] = f.voxel_size_m;
    j["tracking_quality"] = f.tracking_quality;
    if (!f.odometry_information.isZero(0.0)) {
        nlohmann::json rows = nlohmann::json::array();
        for (int r = 0; r < 6; ++r) {
            nlohmann::json row = nlohmann::json::array();
            for (int c = 0; c < 6; ++c) row.push_back(f.odometry_information(r, c));
            rows.push_back(std::move(row));
        }
        j["odometry_information"] = std::move(rows);
    }
    j["num_points"] = f.points_F.size();
    j["points_file"] = fmt::format("fragment_{:03d}.ply", f.id);
    nlohmann::json frames = nlohmann::json::array();
    for (const FragmentFrame& fr : f.frames) {
        frames.push_back({{"frame_index", fr.frame_index},
                          {"timestamp_s", fr.timestamp_s},
                          {"tracking_ok", fr.tracking_ok},
                          {"T_F_C", poseJson(fr.T_F_C)}});
    }
    j["frames"] = std::move(frames);
    nlohmann::json gt = nlohmann::json::object();
    if (acc.ate) {
        gt["ate_rmse_m"] = acc.ate->rmse_m;
        gt["ate_median_m"] = acc.ate->median_m;
        gt["ate_max_m"] = acc.ate->max_m;
        gt["ate_pairs"] = acc.ate->num_pairs;
    }
    if (acc.drift_m) {
        gt["drift_m"] = *acc.drift_m;
        gt["drift_deg"] = *acc.drift_deg;
    }
    if (acc.surface_median_m) gt["surface_median_m"] = *acc.surface_median_m;
    if (!gt.empty()) j["ground_truth"] = std::move(gt);
    return j;
}

// Checkpoint pieces (io::StateWriter/Reader: this build on this machine only).
void saveString(io::StateWriter& w, const std::string& s) {
    w.array(std::vector<char>(s.begin(), s.end()));
}
bool loadString(io::StateReader& r, std::string* s) {
    std::vector<char> chars;
    if (!r.array(&chars)) return false;
    s->assign(chars.begin(), chars.end());
    return true;
}
void saveStampedPose(io::StateWriter& w, const io::StampedPose& p) {
    w.value(p.timestamp_s);
    w.pose(p.T_W_C);
}
bool loadStampedPose(io::StateReader& r, io::StampedPose* p) {
    return r.value(&p->timestamp_s) && r.pose(&p->T_W_C);
}
/// A count read back, bounded so that a damaged one fails instead of allocating.
bool loadCount(io::StateReader& r, uint64_t* n) { return r.value(n) && *n <= (uint64_t{1} << 32); }
void saveStamp(io::StateWriter& w, const std::optional<std::pair<uint64_t, double>>& s) {
    w.value<uint8_t>(s ? 1 : 0);
    w.value<uint64_t>(s ? s->first : 0);
    w.value<double>(s ? s->second : 0.0);
}
bool loadStamp(io::StateReader& r, std::optional<std::pair<uint64_t, double>>* s) {
    uint8_t has = 0;
    uint64_t position = 0;
    double t = 0.0;
    if (!r.value(&has) || !r.value(&position) || !r.value(&t)) return false;
    *s = has != 0 ? std::make_optional(std::make_pair(position, t)) : std::nullopt;
    return true;
}

/// Everything a run has gathered from the frames so far besides the builder's state: what a
/// checkpoint keeps with the builder's, so that --resume continues exactly.
struct FuseTally {
    FrameTruth truth;
    /// The tracked frames of the fragments written (T_W_F * T_F_C), in fragment order.
    io::Trajectory odometry;
    /// Tracked frames of no fragment written yet (the builder's T_W_C), by frame index: the
    /// trajectory of an interrupted run ends with them.
    std::map<int64_t, io::StampedPose> open_tracked;
    /// Each written fragment's JSON without its frames (fragments.json).
    nlohmann::json fragment_list = nlohmann::json::array();
    std::vector<double> ates, drifts_m, drifts_deg, medians;
    uint64_t positions = 0;  ///< source positions passed: frames read and frames skipped
    uint64_t read = 0;       ///< source frames read
    uint64_t kept = 0;       ///< of those, frames kept (--frame-step)
    uint64_t frames = 0, lost = 0, relocalised = 0, segments_started = 0, budget = 0;
    double process_s = 0.0;        ///< wall-clock time in the builder (of every session of the run)
    std::vector<double> frame_ms;  ///< the same per frame fused, milliseconds, in order
    /// (source position, timestamp) of the first and last frame fused: the sensor's period.
    std::optional<std::pair<uint64_t, double>> first_stamp, last_stamp;
    /// Tracked frames whose ICP left translations unconstrained (the geometry in view does not
    /// fix them; the pose follows the constant-velocity prediction along them), by frame index,
    /// until their fragment is written.
    std::map<int64_t, int> unconstrained;
    uint64_t frames_unconstrained = 0;
    /// Frames with colour tracked by depth only, and why (photometric fall-back), by frame index
    /// until their fragment is written; counts of the reasons' kinds (the text before ':').
    std::map<int64_t, std::string> depth_only;
    uint64_t frames_photometric = 0;
    std::map<std::string, uint64_t> depth_only_kinds;
    /// Frames tracked but not fused (fusion.max_integration_hz).
    uint64_t frames_tracked_only = 0;

    void save(io::StateWriter& w) const;
    bool load(io::StateReader& r, bool with_frame_ms);
};

void FuseTally::save(io::StateWriter& w) const {
    w.value<uint64_t>(truth.T_W_C.size());
    for (const std::optional<Eigen::Isometry3d>& T : truth.T_W_C) {
        w.value<uint8_t>(T ? 1 : 0);
        w.pose(T.value_or(Eigen::Isometry3d::Identity()));
    }
    w.value<uint64_t>(odometry.size());
    for (const io::StampedPose& p : odometry) saveStampedPose(w, p);
    w.value<uint64_t>(open_tracked.size());
    for (const auto& [index, p] : open_tracked) {
        w.value(index);
        saveStampedPose(w, p);
    }
    // CBOR keeps every number exactly as it was (a float64 stays one).
    w.array(nlohmann::json::to_cbor(fragment_list));
    for (const std::vector<double>* v : {&ates, &drifts_m, &drifts_deg, &medians, &frame_ms}) {
        w.array(*v);
    }
    for (uint64_t n : {positions, read, kept, frames, lost, relocalised, segments_started, budget,
                       frames_unconstrained, frames_photometric, frames_tracked_only}) {
        w.value(n);
    }
    w.value(process_s);
    saveStamp(w, first_stamp);
    saveStamp(w, last_stamp);
    w.value<uint64_t>(unconstrained.size());
    for (const auto& [index, n] : unconstrained) {
        w.value(index);
        w.value<int32_t>(n);
    }
    w.value<uint64_t>(depth_only.size());
    for (const auto& [index, why] : depth_only) {
        w.value(index);
        saveString(w, why);
    }
    w.value<uint64_t>(depth_only_kinds.size());
    for (const auto& [kind, n] : depth_only_kinds) {
        saveString(w, kind);
        w.value(n);
    }
}

bool FuseTally::load(io::StateReader& r, bool with_frame_ms) {
    uint64_t n = 0;
    if (!loadCount(r, &n)) return false;
    truth.T_W_C.assign(n, std::nullopt);
    for (std::optional<Eigen::Isometry3d>& T : truth.T_W_C) {
        uint8_t has = 0;
        Eigen::Isometry3d pose;
        if (!r.value(&has) || !r.pose(&pose)) return false;
        if (has != 0) T = pose;
    }
    if (!loadCount(r, &n)) return false;
    odometry.resize(n);
    for (io::StampedPose& p : odometry) {
        if (!loadStampedPose(r, &p)) return false;
    }
    if (!loadCount(r, &n)) return false;
    for (uint64_t i = 0; i < n; ++i) {
        int64_t index = 0;
        io::StampedPose p;
        if (!r.value(&index) || !loadStampedPose(r, &p)) return false;
        open_tracked[index] = p;
    }
    std::vector<uint8_t> cbor;
    if (!r.array(&cbor)) return false;
    fragment_list = nlohmann::json::from_cbor(cbor, true, false);
    if (!fragment_list.is_array()) return false;
    for (std::vector<double>* v : {&ates, &drifts_m, &drifts_deg, &medians}) {
        if (!r.array(v)) return false;
    }
    if (with_frame_ms && !r.array(&frame_ms)) return false;
    for (uint64_t* c :
         {&positions, &read, &kept, &frames, &lost, &relocalised, &segments_started, &budget,
          &frames_unconstrained, &frames_photometric, &frames_tracked_only}) {
        if (!r.value(c)) return false;
    }
    if (!r.value(&process_s) || !loadStamp(r, &first_stamp) || !loadStamp(r, &last_stamp)) {
        return false;
    }
    if (!loadCount(r, &n)) return false;
    for (uint64_t i = 0; i < n; ++i) {
        int64_t index = 0;
        int32_t count = 0;
        if (!r.value(&index) || !r.value(&count)) return false;
        unconstrained[index] = count;
    }
    if (!loadCount(r, &n)) return false;
    for (uint64_t i = 0; i < n; ++i) {
        int64_t index = 0;
        if (!r.value(&index) || !loadString(r, &depth_only[index])) return false;
    }
    if (!loadCount(r, &n)) return false;
    for (uint64_t i = 0; i < n; ++i) {
        std::string kind;
        uint64_t count = 0;
        if (!loadString(r, &kind) || !r.value(&count)) return false;
        depth_only_kinds[kind] = count;
    }
    return true;
}

/// One run of `plumb fuse` into o.out: the builder and the tally of the frames so far.
class FuseRun {
  public:
    /// `gt_surface_W`: the true surface, to measure fragments against (nullptr: none).
    FuseRun(const FuseOptions& o, const PinholeCamera& camera, const device::FusionConfig& cfg,
            const PointCloud* gt_surface_W)
        : o_(o),
          max_integration_hz_(cfg.max_integration_hz),
          builder_(camera, cfg),
          gt_surface_W_(gt_surface_W) {}

    /// Tracks and fuses the frames of `source` until it ends (true; the last fragment written)
    /// or `stop` returns true at a frame boundary (false). Fails for unusable input or a file
    /// that cannot be written.
    Result<bool> run(FrameSource& source, const std::function<bool()>& stop);

    /// Restores the checkpoint in o.out (kNotFound without one; kCorrupt for a damaged one or
    /// one of another camera, configuration or --frame-step) and moves `source`, opened as for
    /// the interrupted run, past the frames it had passed.
    Status resume(FrameSource& source);

    /// What an interrupted run keeps besides its fragments: the checkpoint, the trajectory
    /// tracked so far and fragments.json with "status": "interrupted".
    Status writeInterrupted(const std::string& source_description) const;

    /// The finished run's trajectory.txt and fragments.json; the summary line for the log.
    Result<std::string> writeComplete(const std::string& source_description) const;

    const FuseTally& tally() const { return t_; }

  private:
    /// A frame the pass fuses, before the builder sees it: its stamps and ground truth.
    void noteFused(const Frame& frame, uint64_t position);
    /// The builder's report of a fused frame: the tracking tallies and warnings.
    void noteReport(const device::FrameReport& report, const Frame& frame);
    /// Measures and writes one fragment (PLY and JSON) and adds it to the tally.
    Status emit(const Fragment& f);
    /// fragments.json of the frames so far, with its summary line.
    std::pair<nlohmann::json, std::string> summary(const std::string& source_description) const;
    std::filesystem::path checkpointPath() const { return o_.out / "resume" / "fuse_state.bin"; }

    const FuseOptions& o_;
    double max_integration_hz_;  ///< fusion.max_integration_hz, for the summary
    device::FragmentBuilder builder_;
    const PointCloud* gt_surface_W_;
    FuseTally t_;
    std::chrono::steady_clock::time_point process_start_;  ///< of the frame in the builder
};

Status FuseRun::emit(const Fragment& f) {
    const FragmentAccuracy acc = measureFragment(f, t_.truth, gt_surface_W_);
    if (acc.ate) t_.ates.push_back(acc.ate->rmse_m);
    if (acc.drift_m) {
        t_.drifts_m.push_back(*acc.drift_m);
        t_.drifts_deg.push_back(*acc.drift_deg);
    }
    if (acc.surface_median_m) t_.medians.push_back(*acc.surface_median_m);
    for (const FragmentFrame& fr : f.frames) {
        t_.open_tracked.erase(fr.frame_index);
        if (!fr.tracking_ok) continue;
        t_.odometry.push_back({fr.timestamp_s, f.T_W_F * fr.T_F_C});
    }
    const std::string stem = fmt::format("fragment_{:03d}", f.id);
    PLUMB_RETURN_IF_ERROR(io::writePointCloud(o_.out / (stem + ".ply"), f.points_F));
    nlohmann::json j = fragmentJson(f, acc);
    size_t num_unconstrained = 0, num_depth_only = 0;
    for (nlohmann::json& fr : j["frames"]) {
        const auto it = t_.unconstrained.find(fr["frame_index"].get<int64_t>());
        const int n = it == t_.unconstrained.end() ? 0 : it->second;
        if (it != t_.unconstrained.end()) t_.unconstrained.erase(it);
        fr["unconstrained_translations"] = n;
        num_unconstrained += n > 0 ? 1 : 0;
        if (const auto d = t_.depth_only.find(fr["frame_index"].get<int64_t>());
            d != t_.depth_only.end()) {
            fr["depth_only"] = d->second;
            ++num_depth_only;
            t_.depth_only.erase(d);
        }
    }
    j["frames_depth_only"] = num_depth_only;
    t_.frames_unconstrained += num_unconstrained;
    j["frames_unconstrained"] = num_unconstrained;
    PLUMB_RETURN_IF_ERROR(io::writeText(o_.out / (stem + ".json"), j.dump(2) + "\n"));
    j.erase("frames");
    j["num_frames"] = f.frames.size();
    t_.fragment_list.push_back(std::move(j));
    if (!o_.quiet || f.end != FragmentEnd::kFrameCount) {
        std::string gt_text;
        if (acc.ate) gt_text += fmt::format(", ATE {:.2f} cm", acc.ate->rmse_m * 100.0);
        if (acc.drift_m) {
            gt_text +=
                fmt::format(", drift {:.2f} cm {:.2f} deg", *acc.drift_m * 100.0, *acc.drift_deg);
        }
        if (acc.surface_median_m) {
            gt_text += fmt::format(", surface median {:.2f} mm", *acc.surface_median_m * 1e3);
        }
        if (num_unconstrained > 0) {
            gt_text +=
                fmt::format("; {} frames tracked with a translation the depth does not constrain",
                            num_unconstrained);
        }
        log::info("fragment {} (segment {}): {} frames, {} points, closed by {}{}", f.id, f.segment,
                  f.frames.size(), f.points_F.size(), toString(f.end), gt_text);
    }
    return Status::ok();
}

void FuseRun::noteFused(const Frame& frame, uint64_t position) {
    ++t_.kept;
    if (!t_.first_stamp) t_.first_stamp = std::make_pair(position, frame.timestamp_s);
    t_.last_stamp = std::make_pair(position, frame.timestamp_s);
    if (frame.index >= 0) {
        if (t_.truth.T_W_C.size() <= static_cast<size_t>(frame.index)) {
            t_.truth.T_W_C.resize(static_cast<size_t>(frame.index) + 1);
        }
        t_.truth.T_W_C[static_cast<size_t>(frame.index)] = frame.T_W_C_gt;
    }
}

void FuseRun::noteReport(const device::FrameReport& report, const Frame& frame) {
    ++t_.frames;
    t_.lost += report.tracked ? 0 : 1;
    t_.relocalised += report.relocalised ? 1 : 0;
    t_.segments_started += report.new_segment ? 1 : 0;
    t_.budget += report.budget_reached ? 1 : 0;
    if (report.tracked) {
        t_.open_tracked[report.frame_index] = {frame.timestamp_s, report.T_W_C};
    }
    if (report.tracked && report.icp.num_degenerate_directions > 0) {
        t_.unconstrained[report.frame_index] = report.icp.num_degenerate_directions;
    }
    if (report.tracked && report.icp.photometric.used) ++t_.frames_photometric;
    if (report.tracked_only) ++t_.frames_tracked_only;
    if (report.tracked && !report.icp.photometric.fallback.empty()) {
        const std::string& why = report.icp.photometric.fallback;
        t_.depth_only[report.frame_index] = why;
        ++t_.depth_only_kinds[why.substr(0, why.find(':'))];
    }
    if (!report.message.empty()) {
        log::warn("frame {}: {}", report.frame_index, report.message);
    }
}

Result<bool> FuseRun::run(FrameSource& source, const std::function<bool()>& stop) {
    ProgressOptions po;
    if (o_.quiet) po.mode = ProgressOptions::Mode::kQuiet;
    po.unit = "frames";
    Progress progress("tracking and fusing", source.size().value_or(0), po);
    progress.advance(t_.read);
    device::FuseHooks hooks;
    hooks.stop = stop;
    hooks.skip_error = [&](const Status& error) {
        if (!source.canSkipErrors()) return false;
        ++t_.positions;
        log::warn("skipping a frame: {}", error.toString());
        return true;
    };
    hooks.keep = [&](const Frame& frame) {
        ++t_.positions;
        const uint64_t position = t_.read++;
        if (position !=
            static_cast<uint64_t>(std::floor(static_cast<double>(t_.kept) * o_.frame_step))) {
            progress.advance();
            return false;  // dropped, as a device that has no time for it
        }
        noteFused(frame, position);
        process_start_ = std::chrono::steady_clock::now();
        return true;
    };
    hooks.on_frame = [&](const Frame& frame, const device::FrameReport& report) {
        const double took_s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - process_start_)
                .count();
        t_.process_s += took_s;
        t_.frame_ms.push_back(1e3 * took_s);
        noteReport(report, frame);
        progress.advance();
        return Status::ok();
    };
    hooks.on_fragment = [&](Fragment f) { return emit(f); };
    Result<bool> finished = device::fuseFrames(source, builder_, hooks);
    if (!finished.isOk() || !*finished) return finished;
    progress.finish();
    if (t_.frames == 0) return failedPrecondition("the source gave no frames");
    return true;
}

Status FuseRun::resume(FrameSource& source) {
    const std::string what = checkpointPath().string();
    Result<std::vector<uint8_t>> bytes = messages::readFile(checkpointPath(), kMaxCheckpointBytes);
    if (!bytes.isOk()) {
        if (bytes.status().code() != StatusCode::kNotFound) return bytes.status();
        return notFound(what +
                        ": no checkpoint (the run was stopped at once, by a second Ctrl-C or "
                        "a kill); run it again with --force");
    }
    double step = 0.0;
    std::vector<uint8_t> builder;
    // The whole checkpoint in one of the layouts its version may have.
    auto parse = [&](bool with_frame_ms) {
        io::StateReader r(*bytes);
        uint32_t magic = 0, version = 0;
        t_ = FuseTally{};
        if (!(r.value(&magic) && magic == kCheckpointMagic && r.value(&version))) return false;
        if (!(version == kCheckpointVersion && with_frame_ms) && version != 2) return false;
        return r.value(&step) && t_.load(r, with_frame_ms) && r.array(&builder) && r.atEnd();
    };
    if (!parse(true) && !parse(false)) {
        return corrupt(what + ": not a plumb fuse checkpoint, or damaged");
    }
    if (step != o_.frame_step) return corrupt(what + ": saved with another --frame-step");
    if (Status s = builder_.restoreState(builder); !s.isOk()) return prefixed(s, what);
    for (uint64_t i = 0; i < t_.positions; ++i) {
        const Status s = source.skip();
        if (s.isOk() || (s.code() != StatusCode::kOutOfRange && source.canSkipErrors())) continue;
        return prefixed(
            s, fmt::format("moving the source to frame {} of the interrupted run", t_.positions));
    }
    return Status::ok();
}

std::pair<nlohmann::json, std::string> FuseRun::summary(
    const std::string& source_description) const {
    nlohmann::json summary;
    summary["source"] = source_description;
    summary["frames"] = t_.frames;
    summary["frame_step"] = o_.frame_step;
    summary["frames_tracking_failed"] = t_.lost;
    summary["frames_unconstrained"] = t_.frames_unconstrained;
    summary["frames_photometric"] = t_.frames_photometric;
    summary["frames_tracked_only"] = t_.frames_tracked_only;
    uint64_t frames_depth_only = 0;
    for (const auto& [kind, n] : t_.depth_only_kinds) {
        summary["depth_only_reasons"][kind] = n;
        frames_depth_only += n;
    }
    summary["frames_depth_only"] = frames_depth_only;
    summary["relocalisations"] = t_.relocalised;
    summary["new_segments"] = t_.segments_started;
    summary["block_budget_closures"] = t_.budget;
    const double ms_per_frame =
        1e3 * t_.process_s / static_cast<double>(std::max<uint64_t>(t_.frames, 1));
    summary["ms_per_frame"] = ms_per_frame;
    summary["frames_read"] = t_.read;
    summary["processed_fraction"] =
        static_cast<double>(t_.frames) / static_cast<double>(std::max<uint64_t>(t_.read, 1));
    // What a live device as fast as this run would keep of the camera's frames (it drops the
    // frames it has no time for): all while a frame takes at most the sensor's frame period.
    std::string realtime_text;
    const auto& first = t_.first_stamp;
    const auto& last = t_.last_stamp;
    if (first && last && last->first > first->first && last->second > first->second) {
        const double period_ms =
            1e3 * (last->second - first->second) / static_cast<double>(last->first - first->first);
        const double by_mean = std::min(1.0, period_ms / std::max(ms_per_frame, 1e-9));
        // Through the device's capture queue, frame by frame: a frame that takes long drops
        // the frames after it in a row.
        const device::LiveRate queue =
            device::replayLiveCamera(t_.frame_ms, period_ms, device::kDefaultCaptureQueueFrames);
        summary["live"] = {
            {"sensor_hz", 1e3 / period_ms},
            {"keeps_fraction", queue.keptFraction()},
            {"keeps_fraction_by_mean", by_mean},
            {"queue_frames", device::kDefaultCaptureQueueFrames},
            {"frames_timed", t_.frame_ms.size()},
            {"longest_drop_run", queue.longest_drop_run},
            {"max_latency_ms", queue.max_latency_ms},
            {"threads",
             o_.threads > 0 ? o_.threads : static_cast<int>(std::thread::hardware_concurrency())}};
        realtime_text = fmt::format(
            " (a live device this fast keeps {:.0f} % of a {:.0f} Hz camera's frames through "
            "its {}-frame queue, at most {} dropped in a row; {:.0f} % by the mean time a "
            "frame)",
            100.0 * queue.keptFraction(), 1e3 / period_ms, device::kDefaultCaptureQueueFrames,
            queue.longest_drop_run, 100.0 * by_mean);
    }
    summary["fragments"] = t_.fragment_list;
    auto stats = [](const std::vector<double>& v) {
        nlohmann::json s;
        if (v.empty()) return s;
        s["mean"] = std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
        s["median"] = eval::median(v);
        s["max"] = *std::max_element(v.begin(), v.end());
        return s;
    };
    if (!t_.ates.empty()) summary["ate_rmse_m"] = stats(t_.ates);
    if (!t_.drifts_m.empty()) {
        summary["drift_m"] = stats(t_.drifts_m);
        summary["drift_deg"] = stats(t_.drifts_deg);
    }
    if (!t_.medians.empty()) summary["surface_median_m"] = stats(t_.medians);

    std::string gt_text;
    if (!t_.ates.empty()) {
        gt_text += fmt::format("; per-fragment ATE RMSE mean {:.2f} cm, max {:.2f} cm",
                               summary["ate_rmse_m"]["mean"].get<double>() * 100.0,
                               summary["ate_rmse_m"]["max"].get<double>() * 100.0);
    }
    if (!t_.drifts_m.empty()) {
        gt_text += fmt::format("; drift max {:.2f} cm {:.2f} deg",
                               summary["drift_m"]["max"].get<double>() * 100.0,
                               summary["drift_deg"]["max"].get<double>());
    }
    if (!t_.medians.empty()) {
        gt_text += fmt::format("; surface median max {:.2f} mm",
                               summary["surface_median_m"]["max"].get<double>() * 1e3);
    }
    if (t_.frames_photometric > 0 || frames_depth_only > 0) {
        std::string kinds;
        for (const auto& [kind, n] : t_.depth_only_kinds) {
            kinds += fmt::format("{}{} {}", kinds.empty() ? " (" : ", ", n, kind);
        }
        if (!kinds.empty()) kinds += ")";
        gt_text += fmt::format("; colour: {} frames tracked RGB-D, {} by depth only{}",
                               t_.frames_photometric, frames_depth_only, kinds);
    }
    if (t_.frames_tracked_only > 0) {
        gt_text += fmt::format(
            "; {} frame{} tracked but not fused (fused at most about {} times a second: "
            "fusion.max_integration_hz)",
            t_.frames_tracked_only, t_.frames_tracked_only == 1 ? "" : "s", max_integration_hz_);
    }
    std::string text =
        fmt::format("{} frames -> {} fragments in {}, {:.1f} ms/frame{}{}", t_.frames,
                    t_.fragment_list.size(), o_.out.string(), ms_per_frame, realtime_text, gt_text);
    return {std::move(summary), std::move(text)};
}

Status FuseRun::writeInterrupted(const std::string& source_description) const {
    io::StateWriter w;
    w.value(kCheckpointMagic);
    w.value(kCheckpointVersion);
    w.value(o_.frame_step);
    t_.save(w);
    w.array(builder_.saveState());
    std::error_code ec;
    std::filesystem::create_directories(o_.out / "resume", ec);
    if (ec) {
        return ioError(
            fmt::format("{}: cannot create: {}", (o_.out / "resume").string(), ec.message()));
    }
    PLUMB_RETURN_IF_ERROR(messages::writeFileAtomic(checkpointPath(), w.bytes()));

    io::Trajectory tracked = t_.odometry;
    for (const auto& [index, p] : t_.open_tracked) tracked.push_back(p);
    PLUMB_RETURN_IF_ERROR(io::writeTumTrajectory(o_.out / "trajectory.txt", tracked));
    nlohmann::json j = summary(source_description).first;
    j["status"] = "interrupted";
    j["fragments_written"] = t_.fragment_list.size();
    j["trajectory"] = fmt::format(
        "trajectory.txt: the odometry of the {} frames tracked so far ({} of them in the "
        "fragment still open, kept in the checkpoint)",
        tracked.size(), t_.open_tracked.size());
    j["resume"] = resumeCommand(kCommand, o_.out);
    return writeTextFileAtomic(o_.out / "fragments.json", j.dump(2) + "\n");
}

Result<std::string> FuseRun::writeComplete(const std::string& source_description) const {
    PLUMB_RETURN_IF_ERROR(io::writeTumTrajectory(o_.out / "trajectory.txt", t_.odometry));
    auto [j, text] = summary(source_description);
    j["status"] = "complete";
    PLUMB_RETURN_IF_ERROR(io::writeText(o_.out / "fragments.json", j.dump(2) + "\n"));
    return text;
}

/// Parses a command line (without --resume) into `*o`; nullopt to go on, else the exit status.
std::optional<int> parseOptions(const std::vector<std::string>& args, FuseOptions* o) {
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        bool source_option = false;
        if (std::optional<int> rc =
                parseSourceOption(kCommand, args, &i, &o->source_options, &source_option))
            return rc;
        if (source_option) {
            continue;
        }
        auto value = [&](std::string* v) {
            if (i + 1 >= args.size()) return false;
            *v = args[++i];
            return true;
        };
        std::string v;
        if (a == "-h" || a == "--help") {
            std::cout << kUsage;
            return kExitOk;
        } else if (a == "--out") {
            if (!value(&v) || v.empty()) return usageError(kCommand, "--out needs a folder");
            o->out = v;
        } else if (a == "--force") {
            o->force = true;
        } else if (a == "--resume") {
            return usageError(kCommand, "--resume DIR comes without a source and other options");
        } else if (a == "--frame-step") {
            if (!value(&v) || !parseNumber(v, &o->frame_step) || !(o->frame_step >= 1.0) ||
                !std::isfinite(o->frame_step))
                return usageError(kCommand, "--frame-step needs a number >= 1");
        } else if (a == "--threads") {
            if (!value(&v) || !parseNumber(v, &o->threads) || o->threads < 1)
                return usageError(kCommand, "--threads needs a positive integer");
        } else if (a == "--quiet") {
            o->quiet = true;
        } else if (!a.empty() && a[0] == '-') {
            return usageError(kCommand, "unknown option " + a);
        } else if (o->source.empty()) {
            o->source = a;
        } else {
            return usageError(kCommand, "more than one source given: " + o->source + " and " + a);
        }
    }
    if (o->source.empty()) return usageError(kCommand, "no source given");
    if (o->out.empty()) return usageError(kCommand, "--out is required");
    return std::nullopt;
}

int runFuse(const std::vector<std::string>& arguments) {
    std::vector<std::string> args = arguments;
    // --resume DIR: the interrupted run's own command line, in its working folder.
    ResumeArguments resumed;
    std::optional<RunRecord> record;
    if (std::find(args.begin(), args.end(), "--resume") != args.end()) {
        RunRecord r;
        if (std::optional<int> rc = beginResume(kCommand, kUsage, args, &resumed, &r)) return *rc;
        args = r.arguments;
        record = std::move(r);
    }
    Result<config::ConfigArgs> config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(kCommand, config_args.status().message());
    FuseOptions o;
    if (std::optional<int> rc = parseOptions(args, &o)) return *rc;
    if (record) {
        o.out = resumed.dir;
        o.quiet = o.quiet || resumed.quiet;
        if (resumed.threads > 0) o.threads = resumed.threads;
    }

    device::FusionConfig cfg;
    // A configuration that does not load is a bad command line: what was asked cannot be done.
    if (Status s = config::load(*config_args, cfg); !s.isOk()) {
        return usageError(kCommand, s.message());
    }
    if (Status s = cfg.validate(); !s.isOk()) return usageError(kCommand, s.message());
    std::optional<tbb::global_control> threads;
    if (o.threads > 0) {
        threads.emplace(tbb::global_control::max_allowed_parallelism,
                        static_cast<size_t>(o.threads));
    }
    log::setupLogging("plumb fuse");

    const std::string uri = normaliseScanUri(o.source);
    if (!o.source_options.sim_noise.empty() && uri.rfind("sim:", 0) != 0) {
        return usageError(kCommand, "--noise applies to sim: sources only");
    }
    if (Status s = checkScanSourceArguments(uri, o.source_options); !s.isOk()) {
        return usageError(kCommand, s.message());
    }
    const std::string config_toml = config::toToml(cfg, "plumb fuse (effective)");
    if (record && record->config_toml != config_toml) {
        return usageError(kCommand,
                          "--resume: the configuration differs from the interrupted run's (was "
                          "its --config file changed?)");
    }
    if (!record) {
        if (Status s = prepareOutputFolder(o.out, o.force); !s.isOk()) {
            return usageError(kCommand, s.message());
        }
        const RunRecord r{arguments, std::filesystem::current_path(), config_toml, {}};
        if (Status s = writeRunRecord(o.out, kCommand, r); !s.isOk()) return failure(kCommand, s);
    }
    InterruptScope interrupt("plumb fuse");
    Result<std::unique_ptr<FrameSource>> opened = openScanSource(uri, o.source_options);
    if (!opened.isOk()) return failure(kCommand, opened.status());
    std::unique_ptr<FrameSource> source = std::move(opened).value();
    if (Status s = io::writeText(o.out / "config.toml", config_toml); !s.isOk()) {
        return failure(kCommand, s);
    }
    log::info("fusing {} into {}", source->description(), o.out.string());

    // Ground-truth surface of the simulated room, in W.
    std::optional<PointCloud> gt_surface;
    if (const auto* sim = dynamic_cast<const sim::SimSource*>(&source->underlying())) {
        gt_surface = sim::sampleSurfaces(sim->scene(), 0.01);
    }
    FuseRun run(o, source->camera(), cfg, gt_surface ? &*gt_surface : nullptr);
    if (record) {
        if (Status s = run.resume(*source); !s.isOk()) return failure(kCommand, s, "--resume");
        log::info("resuming after frame {} (fragments written: {})", run.tally().read,
                  run.tally().fragment_list.size());
    }
    Result<bool> finished = run.run(*source, InterruptScope::requested);
    if (!finished.isOk()) return failure(kCommand, finished.status());
    if (!*finished) {
        if (Status s = run.writeInterrupted(source->description()); !s.isOk()) {
            return failure(kCommand, s, "interrupted, keeping the work");
        }
        const size_t written = run.tally().fragment_list.size();
        std::cerr << fmt::format(
            "plumb fuse: interrupted after {} frames, {} fragment{} written; the work so far is "
            "kept in {}; continue with: {}\n",
            run.tally().read, written, written == 1 ? "" : "s", o.out.string(),
            resumeCommand(kCommand, o.out));
        return kExitInterrupted;
    }
    Result<std::string> text = run.writeComplete(source->description());
    if (!text.isOk()) return failure(kCommand, text.status());
    removeResumeFolder(o.out);  // complete: nothing left to resume
    log::info("{}", *text);
    return kExitOk;
}

}  // namespace
}  // namespace plumb::tools

PLUMB_COMMAND(fuse, "fuse",
              "track and fuse a dataset or simulated scan into fragments (PLY + JSON) for "
              "inspection",
              plumb::tools::runFuse);
