// SPDX-License-Identifier: Apache-2.0
// FragmentBuilder checkpoints: every member that carries over from one frame to the next.

#include <cstring>
#include <limits>

#include "common/io/state_archive.hpp"
#include "device/fusion/fragment_builder.hpp"

namespace plumb::device {
namespace {

constexpr uint32_t kStateMagic = 0x53424650u;  // "PFBS"
constexpr uint32_t kStateVersion = 3;
/// Version 2 lacks the timing of the prediction (velocity_dt_s_ and the timestamps after it):
/// restored without it, the next frame is predicted one frame period ahead.
constexpr uint32_t kStateVersionWithoutTiming = 2;

void saveFragment(io::StateWriter& out, const Fragment& f) {
    out.value(f.id);
    out.value(f.segment);
    out.value(f.end);
    out.pose(f.T_W_F);
    out.value(f.voxel_size_m);
    out.value(f.tracking_quality);
    out.matrix(f.odometry_information);
    out.value<uint64_t>(f.frames.size());
    for (const FragmentFrame& fr : f.frames) {
        out.value(fr.frame_index);
        out.value(fr.timestamp_s);
        out.pose(fr.T_F_C);
        out.value<uint8_t>(fr.tracking_ok ? 1 : 0);
    }
    out.array(f.points_F.points);
    out.array(f.points_F.normals);
    out.array(f.points_F.colors);
}

bool loadFragment(io::StateReader& in, Fragment* f) {
    uint64_t num_frames = 0;
    if (!in.value(&f->id) || !in.value(&f->segment) || !in.value(&f->end) || !in.pose(&f->T_W_F) ||
        !in.value(&f->voxel_size_m) || !in.value(&f->tracking_quality) ||
        !in.matrix(&f->odometry_information) || !in.value(&num_frames) ||
        num_frames > (uint64_t{1} << 24)) {
        return false;
    }
    f->frames.resize(num_frames);
    for (FragmentFrame& fr : f->frames) {
        uint8_t ok = 0;
        if (!in.value(&fr.frame_index) || !in.value(&fr.timestamp_s) || !in.pose(&fr.T_F_C) ||
            !in.value(&ok)) {
            return false;
        }
        fr.tracking_ok = ok != 0;
    }
    return in.array(&f->points_F.points) && in.array(&f->points_F.normals) &&
           in.array(&f->points_F.colors);
}

void saveModel(io::StateWriter& out, const std::vector<ModelLevel>& model) {
    out.value<uint64_t>(model.size());
    for (const ModelLevel& level : model) {
        out.value(level.camera);
        out.image(level.points_M);
        out.image(level.normals_M);
    }
}

bool loadModel(io::StateReader& in, std::vector<ModelLevel>* model) {
    uint64_t n = 0;
    if (!in.value(&n) || n > 64) return false;
    model->resize(n);
    for (ModelLevel& level : *model) {
        if (!in.value(&level.camera) || !in.image(&level.points_M) || !in.image(&level.normals_M)) {
            return false;
        }
    }
    return true;
}

void saveReference(io::StateWriter& out, const PhotometricReference& r) {
    out.value<uint64_t>(r.levels.size());
    for (const std::vector<ReferencePoint>& level : r.levels) out.array(level);
    out.array(r.level_scale);
    out.value<uint64_t>(r.num_selected);
}

bool loadReference(io::StateReader& in, PhotometricReference* r) {
    uint64_t n = 0, selected = 0;
    if (!in.value(&n) || n > 64) return false;
    r->levels.resize(n);
    for (std::vector<ReferencePoint>& level : r->levels) {
        if (!in.array(&level)) return false;
    }
    if (!in.array(&r->level_scale) || !in.value(&selected)) return false;
    r->num_selected = selected;
    return true;
}

bool sameCamera(const PinholeCamera& a, const PinholeCamera& b) {
    return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy &&
           a.cx == b.cx && a.cy == b.cy;
}

}  // namespace

std::vector<uint8_t> FragmentBuilder::saveState() const {
    io::StateWriter out;
    out.value(kStateMagic);
    out.value(kStateVersion);
    out.value(camera_);
    out.value(config_.frames_per_fragment);
    volume_.saveState(out);
    previous_volume_.saveState(out);
    out.value<uint8_t>(handover_);
    out.pose(T_P_M_);
    out.value<uint8_t>(current_.has_value());
    if (current_) saveFragment(out, *current_);
    out.value<uint8_t>(have_model_);
    out.value<uint8_t>(lost_);
    out.pose(T_W_M_);
    out.pose(T_M_last_);
    out.pose(T_M_fused_);
    out.image(last_depth_);
    out.value(last_fused_time_s_);
    saveModel(out, model_);
    out.pose(T_X_P_);
    out.value(model_uses_);
    out.pose(T_W_C_);
    out.pose(velocity_);
    saveReference(out, reference_);
    out.pose(T_W_R_);
    out.value<uint8_t>(have_reference_);
    out.value(next_id_);
    out.value(segment_);
    out.value(quality_sum_);
    out.value(quality_count_);
    out.value<uint8_t>(first_frame_);
    out.value(velocity_dt_s_);
    out.value(last_tracked_time_s_);
    out.value(previous_frame_time_s_);
    for (double dt : intervals_s_) out.value(dt);
    out.value(num_intervals_);
    return out.bytes();
}

Status FragmentBuilder::restoreState(std::span<const uint8_t> bytes) {
    io::StateReader in(bytes);
    uint32_t magic = 0, version = 0;
    PinholeCamera camera;
    int frames_per_fragment = 0;
    if (!in.value(&magic) || magic != kStateMagic || !in.value(&version) ||
        (version != kStateVersion && version != kStateVersionWithoutTiming)) {
        return corrupt("fusion state: not a plumb fusion checkpoint of this version");
    }
    if (!in.value(&camera) || !in.value(&frames_per_fragment)) {
        return corrupt("fusion state: truncated");
    }
    if (!sameCamera(camera, camera_) || frames_per_fragment != config_.frames_per_fragment) {
        return corrupt("fusion state: saved with another camera or configuration");
    }
    PLUMB_RETURN_IF_ERROR(volume_.loadState(in));
    PLUMB_RETURN_IF_ERROR(previous_volume_.loadState(in));
    uint8_t handover = 0, has_current = 0, have_model = 0, lost = 0, have_reference = 0,
            first_frame = 0;
    bool ok = in.value(&handover) && in.pose(&T_P_M_) && in.value(&has_current);
    current_.reset();
    if (ok && has_current) ok = loadFragment(in, &current_.emplace());
    ok = ok && in.value(&have_model) && in.value(&lost) && in.pose(&T_W_M_) &&
         in.pose(&T_M_last_) && in.pose(&T_M_fused_) && in.image(&last_depth_) &&
         in.value(&last_fused_time_s_) && loadModel(in, &model_) && in.pose(&T_X_P_) &&
         in.value(&model_uses_) && in.pose(&T_W_C_) && in.pose(&velocity_) &&
         loadReference(in, &reference_) && in.pose(&T_W_R_) && in.value(&have_reference) &&
         in.value(&next_id_) && in.value(&segment_) && in.value(&quality_sum_) &&
         in.value(&quality_count_) && in.value(&first_frame);
    velocity_dt_s_ = 0.0;
    last_tracked_time_s_ = previous_frame_time_s_ = std::numeric_limits<double>::quiet_NaN();
    intervals_s_.fill(0.0);
    num_intervals_ = 0;
    if (ok && version == kStateVersion) {
        ok = in.value(&velocity_dt_s_) && in.value(&last_tracked_time_s_) &&
             in.value(&previous_frame_time_s_);
        for (double& dt : intervals_s_) ok = ok && in.value(&dt);
        ok = ok && in.value(&num_intervals_);
    }
    if (!ok || !in.atEnd()) return corrupt("fusion state: truncated or damaged");
    handover_ = handover != 0;
    have_model_ = have_model != 0;
    lost_ = lost != 0;
    have_reference_ = have_reference != 0;
    first_frame_ = first_frame != 0;
    return Status::ok();
}

}  // namespace plumb::device
