// SPDX-License-Identifier: Apache-2.0
#pragma once

// `plumb reconstruct --self-calibrate`: the depth distortion table learned from the scan itself
// (reference §7c), then the reconstruction with it. The bend of the depth is first learned from
// each frame's planes (no poses); then each round reconstructs the scan with the latest table,
// estimates the table at that reconstruction's poses starting from it, and learns the bend left
// from the planes again. The reconstruction itself (tracking, fusion, the backend) is the
// caller's, passed in as a function, so that this module only orders the passes and records
// what each found.
//
// Thread-safety: selfCalibratedRun is not thread-safe (it writes into the output folder and
// logs); it may use worker threads inside.

#include <cstddef>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "backend/calibration/self_calibration.hpp"
#include "backend/pipeline/pipeline.hpp"
#include "common/config/config.hpp"
#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"
#include "drivers/source.hpp"

namespace plumb::tools {

/// `--self-calibrate`: how the depth distortion table is learned from the scan. The defaults
/// are measured in BENCHMARKS.md's "Self-calibration" sections.
struct SelfCalibrateConfig {
    /// First learn the bend of the depth from each frame's planes, without poses
    /// (estimate.planar), and make the first reconstruction with that table; off: the first
    /// reconstruction is from the raw depth, and the scan's planes are not required to
    /// determine the bend.
    bool planar = true;
    /// Every frame_step-th frame of the scan is compared with the model (each frame is held in
    /// memory twice, with up to 8 bytes per compared pixel).
    int frame_step = 1;
    /// ... but at most this many frames: a longer scan is compared at the smallest larger step
    /// that keeps it within (about 5 MB a 640x480 frame, 4.4 GB for 900; 0 = no limit).
    int max_frames = 900;
    /// Re-align every compared frame to each iteration's model by frame-to-model ICP before
    /// comparing it (about 5x the time of the estimate); off: the reconstruction's poses.
    bool refine_poses = false;
    /// The alternation starts from the table the first reconstruction was made with (the
    /// planar stage's, when it determined one) instead of the neutral table.
    bool warm_start = true;
    /// The first reconstruction's final mesh integrates every k-th raw frame only: the estimate
    /// uses its poses, and its mesh gives the "before" figure alone.
    int first_model_frame_stride = 4;
    /// Rounds of reconstruction and refinement before the final reconstruction. Round 1
    /// reconstructs with the planar table (self_calibration/first) and refines the table at its
    /// poses; each further round reconstructs with the last round's table (into
    /// self_calibration/roundK, like the first: no baseline, the coarser mesh) and refines the
    /// table at those poses, starting from it. A learned table tracks better than the planar
    /// one, and the table refined at better poses learns less of their error; each round costs
    /// about one reconstruction and an estimate more.
    int rounds = 1;
    /// The estimator and its alternation (as `plumb calibrate`).
    calibration::SelfCalibrationConfig estimate;
};

void describe(config::Schema& s, SelfCalibrateConfig& c);

/// One reconstruction of the scan: the frames of `source` (opened with `options`, which a
/// second read of the scan uses) tracked, fused and run through the backend with `pipeline`,
/// `input` giving the camera and the ground truth, the outputs written into `dir`. kCancelled
/// when Ctrl-C stopped it.
using ReconstructFn = std::function<Result<backend::PipelineResult>(
    FrameSource& source, const SourceOptions& options, const backend::PipelineConfig& pipeline,
    backend::PipelineInput input, const std::filesystem::path& dir)>;

/// What selfCalibratedRun needs besides the scan.
struct SelfCalibratedRunInput {
    /// The scan's source URI and the run's source options (their depth_calibration is replaced
    /// by each pass's table).
    std::string uri;
    SourceOptions source_options;
    /// The backend of the final reconstruction; the rounds' reconstructions use it without the
    /// baseline and with the coarser mesh (first_model_frame_stride).
    backend::PipelineConfig pipeline;
    /// Memory for keeping the raw frames for every pass (0: every pass reads the scan again).
    size_t keep_frames_bytes = 0;
    /// The output folder: the final reconstruction, depth_calibration.txt, and the passes'
    /// reconstructions and tables under self_calibration/.
    std::filesystem::path out;
};

/// `--self-calibrate` on `raw_source` (opened without depth calibration): reads the scan once,
/// learns the bend from the planes (self_calibration/planar_table.txt), runs `config.rounds`
/// rounds (reconstruction into self_calibration/first or roundK, the table refined at its
/// poses, the bend left learned from the planes), writes the last round's table to
/// out/depth_calibration.txt and reconstructs with it into `out`, the self-calibration's
/// figures in the result's metrics ("self_calibration"). When the planes do not determine the
/// bend, no table is learned and the raw depth is reconstructed once, with a warning
/// ("status": "not_determined"). Errors: those of the passes, prefixed with the pass.
Result<backend::PipelineResult> selfCalibratedRun(FrameSource& raw_source,
                                                  const SelfCalibrateConfig& config,
                                                  const SelfCalibratedRunInput& run,
                                                  const backend::PipelineInput& base,
                                                  const ReconstructFn& reconstruct);

/// The lines `plumb reconstruct` prints about a self-calibration: the table and the first
/// reconstruction's figures, one line per later round, or why no table was learned.
/// `self_calibration` is metrics.json's "self_calibration" object, `out` the output folder.
std::string selfCalibrationSummary(const nlohmann::json& self_calibration,
                                   const std::filesystem::path& out);

}  // namespace plumb::tools
