// SPDX-License-Identifier: Apache-2.0
#include "device/fusion/fragment_builder.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <utility>

#include "common/core/timing.hpp"
#include "common/geometry/lie.hpp"

namespace plumb::device {

Status FusionConfig::validate() const {
    if (raycast_interval < 1 || raycast_interval_rgbd < 1) {
        return invalidArgument(
            "fusion: raycast_interval and raycast_interval_rgbd must be >= 1, got " +
            std::to_string(raycast_interval) + " and " + std::to_string(raycast_interval_rgbd));
    }
    if (!(max_integration_hz >= 0.0)) {
        return invalidArgument("fusion: max_integration_hz must be >= 0, got " +
                               std::to_string(max_integration_hz));
    }
    if (min_model_width_px < 1) {
        return invalidArgument("fusion: min_model_width_px must be >= 1, got " +
                               std::to_string(min_model_width_px));
    }
    if (frames_per_fragment < 1) {
        return invalidArgument("fusion: frames_per_fragment must be >= 1, got " +
                               std::to_string(frames_per_fragment));
    }
    if (handover_frames < 0) {
        return invalidArgument("fusion: handover_frames must be >= 0, got " +
                               std::to_string(handover_frames));
    }
    PLUMB_RETURN_IF_ERROR(tsdf.validate());
    PLUMB_RETURN_IF_ERROR(preprocess.validate());
    PLUMB_RETURN_IF_ERROR(icp.validate());
    PLUMB_RETURN_IF_ERROR(tracking.validate());
    return Status::ok();
}

FragmentBuilder::FragmentBuilder(const PinholeCamera& camera, const FusionConfig& config)
    : camera_(camera), config_(config), volume_(config.tsdf), previous_volume_(config.tsdf) {
    const Status s = config_.validate();
    PLUMB_CHECK(s.isOk()) << s.toString();
}

void FragmentBuilder::openFragment(const Eigen::Isometry3d& T_W_F, bool handover) {
    handover_ = handover && have_model_ && config_.handover_frames > 0;
    if (handover_) {
        std::swap(volume_, previous_volume_);  // the closed fragment's model; volume_ cleared below
        T_P_M_ = T_W_M_.inverse() * T_W_F;
    } else {
        previous_volume_.clear();
    }
    current_.emplace();
    current_->id = next_id_++;
    current_->segment = segment_;
    current_->T_W_F = T_W_F;
    current_->voxel_size_m = config_.tsdf.voxel_size_m;
    volume_.clear();
    last_depth_ = DepthImage();
    model_.clear();  // cast the new model afresh
    T_W_M_ = T_W_F;
    T_M_last_ = Eigen::Isometry3d::Identity();
    T_M_fused_ = Eigen::Isometry3d::Identity();
    have_model_ = false;
    quality_sum_ = 0.0;
    quality_count_ = 0;
}

void FragmentBuilder::addFrame(const Frame& frame, const Eigen::Isometry3d& T_F_C, bool tracking_ok,
                               double quality) {
    FragmentFrame f;
    f.frame_index = frame.index;
    f.timestamp_s = frame.timestamp_s;
    f.T_F_C = T_F_C;
    f.tracking_ok = tracking_ok;
    current_->frames.push_back(f);
    if (tracking_ok) {
        quality_sum_ += quality;
        ++quality_count_;
    }
}

Fragment FragmentBuilder::closeFragment(FragmentEnd end, FrameTiming* timing) {
    Fragment fragment = std::move(*current_);
    current_.reset();
    fragment.end = end;
    const SteadyClock::time_point t0 = SteadyClock::now();
    fragment.points_F = tsdf::extractSurfacePoints(volume_, config_.surface);
    if (timing != nullptr) timing->extract_ms += msSince(t0);
    fragment.tracking_quality = quality_count_ > 0 ? quality_sum_ / quality_count_ : 0.0;
    return fragment;
}

bool FragmentBuilder::integrate(const FramePyramid& pyramid, const Eigen::Isometry3d& T_F_C,
                                FrameReport* report) {
    const SteadyClock::time_point t0 = SteadyClock::now();
    Result<tsdf::IntegrationStats> r = volume_.integrate(pyramid.depth, camera_, T_F_C, colour_);
    report->timing.integrate_ms += msSince(t0);
    if (!r.isOk()) {
        report->message += (report->message.empty() ? "" : "; ") + r.status().message();
        return false;
    }
    have_model_ = true;
    T_M_fused_ = T_F_C;
    last_fused_time_s_ = frame_time_s_;
    if (config_.raycast_from_last_depth) last_depth_ = pyramid.depth;
    return true;
}

namespace {

/// Ratios of intervals within this factor of 1 are timestamp jitter, not dropped frames.
constexpr double kJitter = 1.25;

}  // namespace

Eigen::Isometry3d FragmentBuilder::predictedPose() const {
    if (!config_.constant_velocity || lost_) return T_M_last_;
    const double since = frame_time_s_ - last_tracked_time_s_;
    const double scale = since / velocity_dt_s_;
    if (!(velocity_dt_s_ > 0.0) || !(since > 0.0) || !std::isfinite(scale) ||
        (scale < kJitter && scale > 1.0 / kJitter)) {
        return T_M_last_ * velocity_;
    }
    // The same velocity over `since` seconds instead of velocity_dt_s_.
    return T_M_last_ * lie::expSE3(scale * lie::logSE3(velocity_));
}

void FragmentBuilder::noteFrameTime(double timestamp_s) {
    frame_time_s_ = timestamp_s;
    if (const double dt = frame_time_s_ - previous_frame_time_s_; dt > 0.0 && std::isfinite(dt)) {
        intervals_s_[num_intervals_++ % kIntervals] = dt;
    }
    previous_frame_time_s_ = frame_time_s_;
}

void FragmentBuilder::noteTracked(const Eigen::Isometry3d& T_M_C) {
    velocity_ = lost_ ? Eigen::Isometry3d::Identity() : T_M_last_.inverse() * T_M_C;
    const double since = frame_time_s_ - last_tracked_time_s_;
    velocity_dt_s_ = !lost_ && since > 0.0 && std::isfinite(since) ? since : 0.0;
    last_tracked_time_s_ = frame_time_s_;
}

IcpConfig FragmentBuilder::icpConfigSinceTracked() const {
    // Frames dropped since the last tracked one: the camera had that much longer to move.
    IcpConfig icp = config_.icp;
    const double periods = periodsSinceTracked();
    icp.max_translation_m *= periods;
    icp.max_rotation_deg *= periods;
    return icp;
}

double FragmentBuilder::periodsSinceTracked() const {
    if (num_intervals_ == 0) return 1.0;
    std::array<double, kIntervals> seen = intervals_s_;
    const size_t n = std::min<size_t>(num_intervals_, kIntervals);
    std::nth_element(seen.begin(), seen.begin() + n / 2, seen.begin() + n);
    const double periods = (frame_time_s_ - last_tracked_time_s_) / seen[n / 2];
    return std::isfinite(periods) && periods >= kJitter ? periods : 1.0;
}

bool FragmentBuilder::integrationDue() const {
    if (!(config_.max_integration_hz > 0.0)) return true;
    const double dt = frame_time_s_ - last_fused_time_s_;
    return !(dt > 0.0) || dt >= 0.75 / config_.max_integration_hz;
}

void FragmentBuilder::setReference(const FramePyramid& pyramid,
                                   const std::vector<IntensityLevel>& intensity) {
    have_reference_ = !intensity.empty();
    if (!have_reference_) return;
    reference_ =
        selectReference(pyramid, intensity, config_.tracking, config_.preprocess.num_threads);
    T_W_R_ = T_W_C_;
}

void FragmentBuilder::updateModel(const tsdf::TsdfVolume& model_volume,
                                  const Eigen::Isometry3d& T_X_M, const FramePyramid& pyramid,
                                  bool rgbd, FrameTiming* timing) {
    const int interval = rgbd ? config_.raycast_interval_rgbd : config_.raycast_interval;
    if (model_.empty() || model_uses_ >= interval) {
        const SteadyClock::time_point t_raycast = SteadyClock::now();
        T_X_P_ = T_X_M * T_M_fused_;
        int level = rgbd ? config_.model_level_rgbd : config_.model_level;
        while (level > 0 && (camera_.width >> level) < config_.min_model_width_px) --level;
        model_ = predictModel(model_volume, pyramid, T_X_P_, config_.raycast, level,
                              last_depth_.empty() ? nullptr : &last_depth_);
        model_uses_ = 0;
        timing->raycast_ms = msSince(t_raycast);
    }
    ++model_uses_;
}

Result<FrameReport> FragmentBuilder::process(const Frame& frame) {
    const SteadyClock::time_point t0 = SteadyClock::now();
    Result<FrameReport> report = processImpl(frame);
    if (report.isOk()) report->timing.total_ms = msSince(t0);
    return report;
}

Result<FrameReport> FragmentBuilder::processImpl(const Frame& frame) {
    const SteadyClock::time_point t_pre = SteadyClock::now();
    Result<FramePyramid> pyr = preprocess(frame.depth, camera_, config_.preprocess);
    if (!pyr.isOk()) {
        return Status(pyr.status().code(),
                      "frame " + std::to_string(frame.index) + ": " + pyr.status().message());
    }
    const FramePyramid& pyramid = pyr.value();
    if (!frame.colour.empty() &&
        (frame.colour.width() != camera_.width || frame.colour.height() != camera_.height)) {
        return invalidArgument("frame " + std::to_string(frame.index) + ": colour is " +
                               std::to_string(frame.colour.width()) + "x" +
                               std::to_string(frame.colour.height()) + " but the camera is " +
                               camera_.toString());
    }
    std::vector<IntensityLevel> intensity;  // empty: track by depth only
    if (config_.tracking.enabled && !frame.colour.empty()) {
        intensity = buildIntensityPyramid(frame.colour, pyramid, config_.tracking,
                                          config_.preprocess.num_threads);
    }
    FrameReport report;
    report.frame_index = frame.index;
    noteFrameTime(frame.timestamp_s);
    report.timing.preprocess_ms = msSince(t_pre);
    colour_ = config_.fuse_colour && !frame.colour.empty() ? &frame.colour : nullptr;

    if (first_frame_ || !have_model_) {
        // Start of the stream, or nothing to track against: begin here at the best known pose.
        const bool restart = !first_frame_;
        first_frame_ = false;
        if (current_ && !current_->frames.empty()) {
            report.closed.push_back(closeFragment(FragmentEnd::kTrackingLost, &report.timing));
        }
        if (!current_) openFragment(T_W_C_);
        last_tracked_time_s_ = frame_time_s_;  // the camera starts (again) here
        velocity_dt_s_ = 0.0;
        report.tracked = !restart;
        report.integrated = integrate(pyramid, Eigen::Isometry3d::Identity(), &report);
        if (report.integrated) addFrame(frame, Eigen::Isometry3d::Identity(), true, 1.0);
        report.T_W_C = T_W_C_;
        setReference(pyramid, intensity);
        return report;
    }

    const SteadyClock::time_point t_track = SteadyClock::now();
    if (handover_ &&
        (!current_ || static_cast<int>(current_->frames.size()) >= config_.handover_frames)) {
        handover_ = false;  // the new fragment's own volume is the model from now on
        previous_volume_.clear();
        model_.clear();
    }
    // Model X: the open fragment's volume (X = M), or the previous one during a handover.
    const tsdf::TsdfVolume& model_volume = handover_ ? previous_volume_ : volume_;
    const Eigen::Isometry3d T_X_M = handover_ ? T_P_M_ : Eigen::Isometry3d::Identity();
    updateModel(model_volume, T_X_M, pyramid, /*rgbd=*/!intensity.empty(), &report.timing);
    // Start from a constant-velocity prediction: along directions the geometry leaves free
    // (solution remapping in the ICP) the camera keeps moving as it did.
    const Eigen::Isometry3d T_M_pred = predictedPose();
    const IcpConfig icp_config = icpConfigSinceTracked();
    PhotometricInput photometric;
    if (have_reference_ && !intensity.empty()) {
        photometric.current = &intensity;
        photometric.reference = &reference_;
        photometric.T_M_R = T_X_M * T_W_M_.inverse() * T_W_R_;  // in the tracking model's frame
        photometric.config = config_.tracking;
    }
    const Eigen::Isometry3d T_X_last = T_X_M * T_M_last_;
    report.icp =
        alignFrameToModel(pyramid, model_, T_X_P_, T_X_M * T_M_pred, icp_config,
                          photometric.current != nullptr ? &photometric : nullptr, &T_X_last);
    if (handover_) report.icp.T_M_C = T_P_M_.inverse() * report.icp.T_M_C;
    report.timing.track_ms = msSince(t_track);

    if (report.icp.ok) {
        const Eigen::Isometry3d T_M_C = report.icp.T_M_C;
        noteTracked(T_M_C);
        T_W_C_ = T_W_M_ * T_M_C;
        report.tracked = true;
        report.relocalised = lost_;
        lost_ = false;
        setReference(pyramid, intensity);
        if (current_ && !integrationDue()) {
            // Tracked only: too soon after the last frame fused (max_integration_hz).
            addFrame(frame, T_M_C, true, report.icp.inlier_fraction);
            T_M_last_ = T_M_C;
            report.tracked_only = true;
        } else if (current_) {
            // Normal tracking inside the open fragment (M = F).
            if (integrate(pyramid, T_M_C, &report)) {
                addFrame(frame, T_M_C, true, report.icp.inlier_fraction);
                T_M_last_ = T_M_C;
                report.integrated = true;
            } else {
                // Block budget: close early and start the next fragment with this frame.
                report.budget_reached = true;
                const bool in_closed_frame = !handover_;  // report.icp is relative to M
                report.closed.push_back(closeFragment(FragmentEnd::kBlockBudget, &report.timing));
                openFragment(T_W_C_);
                if (in_closed_frame) current_->odometry_information = report.icp.information;
                report.integrated = integrate(pyramid, Eigen::Isometry3d::Identity(), &report);
                if (report.integrated) addFrame(frame, Eigen::Isometry3d::Identity(), true, 1.0);
            }
        } else {
            // First frame after a cut (or a re-localisation): it begins the next fragment.
            openFragment(T_W_C_, /*handover=*/true);
            // This frame was aligned to the closed fragment's model: its system is the
            // certainty of the new fragment's pose relative to the closed one.
            current_->odometry_information = report.icp.information;
            report.integrated = integrate(pyramid, Eigen::Isometry3d::Identity(), &report);
            if (report.integrated) {
                addFrame(frame, Eigen::Isometry3d::Identity(), true, report.icp.inlier_fraction);
            }
            if (report.relocalised) report.message = "re-localised against the last fragment";
        }
    } else {
        report.message = "tracking failed: " + report.icp.failure;
        model_.clear();
        velocity_ = Eigen::Isometry3d::Identity();
        velocity_dt_s_ = 0.0;
        report.T_W_C = T_W_C_;
        if (current_) {
            addFrame(frame, T_M_last_, false, 0.0);
            report.closed.push_back(closeFragment(FragmentEnd::kTrackingLost, &report.timing));
            lost_ = true;  // keep volume_ and T_M_last_ for re-localisation
        } else if (lost_) {
            // Re-localisation failed as well: restart tracking in a new segment.
            ++segment_;
            lost_ = false;
            report.new_segment = true;
            report.message += "; re-localisation failed, new segment " + std::to_string(segment_);
            openFragment(T_W_C_);
            last_tracked_time_s_ = frame_time_s_;
            report.integrated = integrate(pyramid, Eigen::Isometry3d::Identity(), &report);
            if (report.integrated) addFrame(frame, Eigen::Isometry3d::Identity(), true, 1.0);
            setReference(pyramid, intensity);
        } else {
            lost_ = true;  // failed right after a cut: try the next frame against the same model
        }
    }
    report.T_W_C = T_W_C_;
    if (current_ && static_cast<int>(current_->frames.size()) >= config_.frames_per_fragment) {
        // Cut; volume_ stays alive to track the next frame.
        report.closed.push_back(closeFragment(FragmentEnd::kFrameCount, &report.timing));
    }
    return report;
}

std::optional<Fragment> FragmentBuilder::finish() {
    if (!current_ || current_->frames.empty()) return std::nullopt;
    return closeFragment(FragmentEnd::kEndOfStream);
}

}  // namespace plumb::device
