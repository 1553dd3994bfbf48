// SPDX-License-Identifier: Apache-2.0
#pragma once

// Continuous tracking and fusion into fragments (reference §2.7). Every frame is tracked against a
// raycast of the current fragment's TSDF; a fragment is cut every `frames_per_fragment` frames and
// its volume is kept just long enough to track the next frame, so odometry never restarts across
// cuts. Fragment F's frame is the camera frame of its first frame; T_W_F comes from odometry.
// Handover: a new fragment's volume holds one frame at first, too thin a model to track against
// (noisy depth far away, coarse voxels), so the first `handover_frames` frames after a cut are
// tracked against the previous fragment's volume, still in memory, while they are integrated into
// the new one. This costs a second volume on the device for those frames.
//
// Tracking loss: the fragment is closed early (FragmentEnd::kTrackingLost, the failed frame listed
// with tracking_ok = false). The next frame tries to re-localise against the closed fragment's
// volume from the last good pose; if that fails too, a new segment starts (Fragment::segment + 1)
// whose pose is only a guess (the last good pose) for the backend to correct.
//
// Dropped frames: a live device that falls behind its camera drops frames, often several in a
// row while one frame takes long. The constant-velocity prediction therefore scales the last
// motion to the time since the last tracked frame (the motion is the camera's velocity times the
// time the frames span, not a step per frame), and the implausible-motion tests
// (IcpConfig::max_translation_m, max_rotation_deg, per frame period) grow with the frame
// periods that time spans. The frame period is the median of the last nine intervals between
// consecutive frames. Timestamps within a quarter of a period of a regular stream (jitter) change
// neither; without usable timestamps (not increasing) every frame counts as one period.
//
// Block budget: when a frame would exceed TsdfConfig::max_blocks the fragment is closed early
// (FragmentEnd::kBlockBudget) and the frame starts the next fragment; the frame report says so.
//
// Not thread-safe; one caller feeds frames in order. No I/O: callers log the reports.

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/fragment/fragment.hpp"
#include "common/frame/frame_source.hpp"
#include "common/tsdf/raycast.hpp"
#include "common/tsdf/surface.hpp"
#include "common/tsdf/tsdf_volume.hpp"
#include "device/fusion/fusion_config.hpp"
#include "device/preprocess/preprocess.hpp"
#include "device/tracking/icp.hpp"

namespace plumb::device {

struct FusionConfig {
    /// Frames per fragment (paper: 50).
    int frames_per_fragment = 50;
    /// Start ICP from a constant-velocity prediction (else from the last pose).
    bool constant_velocity = true;
    /// Frames of a new fragment tracked against the previous fragment's volume after a cut
    /// (0 = track against the new fragment's own volume from its second frame).
    int handover_frames = 5;
    /// TSDF volume of each fragment (voxel size, truncation, block budget).
    tsdf::TsdfConfig tsdf;
    /// Model prediction for tracking.
    tsdf::RaycastConfig raycast;
    /// Pyramid level the model is raycast at for frames tracked by depth alone (0 = full
    /// resolution, 1 = half: 4x fewer rays); finer frame levels associate against it (the
    /// nearest coarse hit). By depth alone a half-resolution model tracks about 10 % worse.
    int model_level = 0;
    /// The same for frames tracked with colour: their photometric term works at full
    /// resolution, and a half-resolution model tracks as well as a full one (nine 600-frame
    /// scans, per-fragment ATE within 1 %).
    int model_level_rgbd = 1;
    /// The model is cast no coarser than the finest level at least this wide, pixels, whatever
    /// model_level and model_level_rgbd ask: 640x480 casts at 320x240, 320x240 at full
    /// resolution. A 320x240 camera tracked against a 160x120 model tracks 12 % worse (nine
    /// scans, geometric mean of the per-fragment ATE), and a 160x120 camera against an 80x60
    /// one loses frames.
    int min_model_width_px = 320;
    /// Rays of the model prediction march from the depth last fused from the same pose (a
    /// truncation in front of it) instead of from the nearest block: fewer samples per ray, the
    /// same hits unless the model holds a surface that frame saw as free space.
    bool raycast_from_last_depth = true;
    /// Frames tracked against one model raycast (1 = a raycast for every frame). With 2 the
    /// prediction cast after frame k is integrated also tracks frame k + 2: it lacks only frame
    /// k + 1's measurements, and projective association looks points up in the camera it was
    /// cast from, two frames' motion away. A new fragment's volume, a handover ending and a
    /// tracking failure always cast afresh. Frames tracked by depth alone.
    int raycast_interval = 1;
    /// The same for frames tracked with colour (the photometric term, `tracking`), whose
    /// intensity residuals against the reference frame do not depend on the prediction. Over nine
    /// 600-frame scans 2, 3 and 4 track as well as 1 with colour (per-fragment ATE within 1 %),
    /// and 2 a few per cent worse than 1 by depth alone.
    int raycast_interval_rgbd = 4;
    /// Frames that arrive faster than this are tracked but fused at about this rate: a frame is
    /// integrated when at least 0.75 / max_integration_hz seconds (by its timestamp) have passed
    /// since the last one fused, so a 60 Hz camera fuses every other frame, the same frames a
    /// second as a 30 Hz one, and a 30 Hz camera (or jittered timestamps near it) every frame.
    /// A fragment's first frame, and frames whose timestamps do not increase, are always fused.
    /// 0 = fuse every tracked frame.
    double max_integration_hz = 30.0;
    /// Surface points of a closed fragment.
    tsdf::SurfaceConfig surface;
    /// Frame preprocessing (filter, pyramid).
    PreprocessConfig preprocess;
    /// Frame-to-model ICP and its failure tests.
    IcpConfig icp;
    /// Fuse the frames' colour into the fragment volumes (coloured fragment points), when the
    /// frames have colour.
    bool fuse_colour = true;
    /// RGB-D tracking: the photometric term against the last tracked frame, used when the
    /// frame has colour (reference §7b.1).
    PhotometricConfig tracking;

    Status validate() const;
};

/// Wall-clock time spent in each stage of one frame, milliseconds (for status and benchmarks).
struct FrameTiming {
    double preprocess_ms = 0.0;  ///< filter, pyramid, vertex and normal maps
    double track_ms = 0.0;       ///< model raycast and ICP
    double raycast_ms = 0.0;     ///< of track_ms, the model raycast (0 when the last one is reused)
    double integrate_ms = 0.0;   ///< TSDF integration (all attempts)
    double extract_ms = 0.0;     ///< surface points of fragments closed on this frame
    double total_ms = 0.0;       ///< the whole process() call
};

/// What happened to one frame.
struct FrameReport {
    int64_t frame_index = 0;
    bool tracked = false;     ///< pose from ICP (or the first frame of a segment)
    bool integrated = false;  ///< fused into a fragment volume
    /// Tracked and kept in its fragment but not fused: it came sooner after the last frame
    /// fused than FusionConfig::max_integration_hz allows.
    bool tracked_only = false;
    bool relocalised = false;     ///< tracking recovered against the last closed fragment
    bool new_segment = false;     ///< tracking restarted: a new segment began at this frame
    bool budget_reached = false;  ///< the block budget closed a fragment on this frame
    IcpResult icp;                ///< the ICP result (default when no ICP ran)
    Eigen::Isometry3d T_W_C = Eigen::Isometry3d::Identity();  ///< pose estimate after the frame
    std::string message;           ///< explanation when something was not nominal
    std::vector<Fragment> closed;  ///< fragments completed while processing this frame
    FrameTiming timing;            ///< where the time went
};

class FragmentBuilder {
  public:
    /// `config` must validate (checked).
    FragmentBuilder(const PinholeCamera& camera, const FusionConfig& config);

    /// Tracks and fuses one frame. Fails only for unusable input (image size mismatch, bad
    /// configuration); tracking problems are reported in the FrameReport.
    Result<FrameReport> process(const Frame& frame);

    /// Closes the open fragment (FragmentEnd::kEndOfStream); nullopt when none holds frames.
    std::optional<Fragment> finish();

    /// The builder's whole state after the frames processed so far (the open fragment, both
    /// volumes, the tracking model and reference, the odometry), as bytes for a checkpoint.
    /// restoreState() on a builder made with the same camera and configuration continues
    /// exactly as this one would have: the same fragments, byte for byte, from the same next
    /// frames. The bytes are for this build on this machine only (io::StateWriter).
    std::vector<uint8_t> saveState() const;
    /// kCorrupt for damaged bytes or a state saved with another camera or configuration (the
    /// builder must then be discarded).
    Status restoreState(std::span<const uint8_t> bytes);

    /// Current camera pose estimate in the world (odometry) frame.
    const Eigen::Isometry3d& T_W_C() const { return T_W_C_; }
    /// The volume of the open (or last closed) fragment, in that fragment's frame.
    const tsdf::TsdfVolume& volume() const { return volume_; }

  private:
    /// `handover`: keep the current volume as the tracking model of the first handover_frames
    /// frames (after a cut or a successful re-localisation, when the pose is consistent with it).
    void openFragment(const Eigen::Isometry3d& T_W_F, bool handover = false);
    void addFrame(const Frame& frame, const Eigen::Isometry3d& T_F_C, bool tracking_ok,
                  double quality);
    Fragment closeFragment(FragmentEnd end, FrameTiming* timing = nullptr);
    Result<FrameReport> processImpl(const Frame& frame);
    bool integrate(const FramePyramid& pyramid, const Eigen::Isometry3d& T_F_C,
                   FrameReport* report);
    /// The model prediction the frame is tracked against: cast afresh from T_M_fused_ (into
    /// model volume X, at T_X_M) when there is none or it has served its raycast interval, at
    /// the model level of frames with colour (`rgbd`) or without.
    void updateModel(const tsdf::TsdfVolume& model_volume, const Eigen::Isometry3d& T_X_M,
                     const FramePyramid& pyramid, bool rgbd, FrameTiming* timing);
    /// False when the frame being processed came too soon after the last one fused
    /// (max_integration_hz): it is tracked only.
    bool integrationDue() const;
    /// The constant-velocity prediction of the camera in M for the frame being processed (the
    /// last motion scaled to the time since the last tracked frame), and the number of frame
    /// periods since that frame (at least 1) that scales the implausible-motion tests.
    Eigen::Isometry3d predictedPose() const;
    double periodsSinceTracked() const;
    /// config_.icp with its implausible-motion tests scaled by periodsSinceTracked().
    IcpConfig icpConfigSinceTracked() const;
    /// The frame being processed has this timestamp (its interval to the previous one joins
    /// the frame period's estimate).
    void noteFrameTime(double timestamp_s);
    /// The frame being processed tracked at T_M_C: the motion from the last tracked camera and
    /// its time become the velocity of the next prediction (none after a loss).
    void noteTracked(const Eigen::Isometry3d& T_M_C);
    /// The frame just tracked at T_W_C_ becomes the photometric reference of the next one (no
    /// reference when it has no colour).
    void setReference(const FramePyramid& pyramid, const std::vector<IntensityLevel>& intensity);

    PinholeCamera camera_;
    FusionConfig config_;
    const ColourImage* colour_ = nullptr;  ///< colour of the frame being processed, to fuse
    tsdf::TsdfVolume volume_;
    tsdf::TsdfVolume previous_volume_;  ///< the last fragment's volume during a handover
    bool handover_ = false;             ///< previous_volume_ is the tracking model
    Eigen::Isometry3d T_P_M_ = Eigen::Isometry3d::Identity();  ///< volume_ in previous_volume_
    std::optional<Fragment> current_;                          ///< the open fragment
    bool have_model_ = false;  ///< volume_ holds a model to track the next frame against
    bool lost_ = false;        ///< the last tracking attempt failed
    Eigen::Isometry3d T_W_M_ = Eigen::Isometry3d::Identity();     ///< frame of volume_
    Eigen::Isometry3d T_M_last_ = Eigen::Isometry3d::Identity();  ///< last good camera in M
    /// The camera of the frame last integrated into volume_ and its depth (every successful
    /// integration sets both; openFragment clears them): the model is cast from T_M_fused_,
    /// its rays starting from last_depth_. Empty when raycast_from_last_depth is off.
    Eigen::Isometry3d T_M_fused_ = Eigen::Isometry3d::Identity();
    DepthImage last_depth_;
    /// Timestamp of the frame being processed and of the last one fused (max_integration_hz).
    double frame_time_s_ = 0.0;
    double last_fused_time_s_ = -std::numeric_limits<double>::infinity();
    /// The last model prediction, cast from T_X_P_ in the frame X of the tracking volume, and
    /// how many frames have tracked against it (raycast_interval). Cleared whenever the
    /// tracking volume changes or tracking fails: the next frame casts afresh.
    std::vector<ModelLevel> model_;
    Eigen::Isometry3d T_X_P_ = Eigen::Isometry3d::Identity();
    int model_uses_ = 0;
    Eigen::Isometry3d T_W_C_ = Eigen::Isometry3d::Identity();
    /// Last frame-to-frame motion T_Cprev_C (identity after a loss), for the prediction, and the
    /// time it took (0: unknown, the motion counts as one frame period).
    Eigen::Isometry3d velocity_ = Eigen::Isometry3d::Identity();
    double velocity_dt_s_ = 0.0;
    /// Timestamp of the last frame tracked (the camera T_M_last_) and of the frame processed
    /// before this one, and the last kIntervals intervals between consecutive frames (0: none
    /// yet), whose median is the frame period. Dropped frames: see the file comment.
    static constexpr size_t kIntervals = 9;
    double last_tracked_time_s_ = std::numeric_limits<double>::quiet_NaN();
    double previous_frame_time_s_ = std::numeric_limits<double>::quiet_NaN();
    std::array<double, kIntervals> intervals_s_{};
    uint32_t num_intervals_ = 0;  ///< intervals seen (the next goes to % kIntervals)
    /// The photometric reference: the last tracked frame's textured points and intensities, and
    /// its camera pose in the world. Kept through tracking failures (re-localisation starts from
    /// that frame's pose); empty while frames have no colour.
    PhotometricReference reference_;
    Eigen::Isometry3d T_W_R_ = Eigen::Isometry3d::Identity();
    bool have_reference_ = false;
    uint32_t next_id_ = 0;
    uint32_t segment_ = 0;
    double quality_sum_ = 0.0;
    int quality_count_ = 0;
    bool first_frame_ = true;
};

}  // namespace plumb::device
