// SPDX-License-Identifier: Apache-2.0
#pragma once

// The backend pipeline from fragments to the output contract of DESIGN.md — the paper's whole
// method (Lee et al., ICCV 2017, Fig. 2) plus the Choi-style baseline it improves on:
//
//   1. prepare fragments (downsample, normals, FPFH)                     §3.1
//   2. initial registration: odometry ICP, loop closures, line-process
//      pose graph, refinement pass  -> the baseline poses T0             §3.1 (Choi et al. 2015)
//   3. per-fragment planes (cached), then Algorithm 1: layout estimation
//      alternated with layout-constrained global registration           §3.2, §3.3
//   4. final model: raw frames re-integrated with the optimised poses
//      (or the fragments' surfaces fused when only fragments exist)
//   5. outputs, evaluation against whatever ground truth came along, report.
//
// The baseline variant (`--no-layout`) stops after step 2; its layout is still estimated once at
// its poses (without feeding back) so every output directory has a floor plan. Unless told
// otherwise the pipeline produces both variants from the same fragments: the full method in the
// output directory, the baseline in <out>/baseline, both in metrics.json and report.html.
//
// Thread-safety: runPipeline keeps no state between calls; it runs on the calling thread and
// parallelises its stages internally.

#include <Eigen/Geometry>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "backend/global/alternation.hpp"
#include "backend/layout/estimate_layout.hpp"
#include "backend/layout/fragment_planes.hpp"
#include "backend/model/final_model.hpp"
#include "backend/registration/register_fragments.hpp"
#include "backend/report/evaluation.hpp"
#include "common/camera/pinhole.hpp"
#include "common/config/schema.hpp"
#include "common/fragment/fragment.hpp"
#include "common/frame/frame_source.hpp"
#include "common/layout/layout.hpp"

namespace plumb::backend {

/// Layout estimation: per-fragment planes (cached) and the room envelope in the world.
struct LayoutStageConfig {
    layout::FragmentPlaneConfig planes;
    layout::LayoutConfig estimate;
    /// Fragments whose planes are extracted side by side (0 = all cores). Each fragment's
    /// extraction is serial and independent of the others: results do not depend on it.
    int num_threads = 0;
};
void describe(config::Schema& s, LayoutStageConfig& c);

struct PipelineConfig {
    /// Run layout estimation and layout-constrained global registration (false = the Choi-style
    /// baseline only, `--no-layout`).
    bool use_layout = true;
    /// With use_layout, also produce the baseline variant for comparison (<out>/baseline).
    bool compare_baseline = true;
    /// Initial registration: preparation, pair registration, pose graph.
    registration::RegistrationConfig registration;
    /// Layout estimation (paper §3.2).
    LayoutStageConfig layout;
    /// Algorithm 1 and the layout-constrained registration step.
    global::AlternationConfig alternation;
    /// The final mesh.
    FinalModelConfig final_model;
};
void describe(config::Schema& s, PipelineConfig& c);

/// What the pipeline runs on.
struct PipelineInput {
    std::vector<Fragment> fragments;  ///< ids 0..n-1 in order
    PinholeCamera camera;             ///< the sensor the fragments were fused from
    /// Opens the raw frames again for re-integration (datasets, the simulator); empty when only
    /// fragments exist (live scans): their surfaces are fused instead.
    std::function<Result<std::unique_ptr<FrameSource>>()> open_raw_frames;
    GroundTruth ground_truth;  ///< may be empty
    std::string description;   ///< the input, for the report ("sim:living_room", a folder, ...)
    std::string config_toml;   ///< the effective configuration, written as config.toml
    /// The command that started the run, for the report ("plumb reconstruct sim:... --out r");
    /// empty when unknown.
    std::string command_line;
    /// Wall time the tracking and fusion that made the fragments took before the pipeline,
    /// seconds; negative when unknown (fragments from a store or a live device).
    double tracking_fusion_seconds = -1.0;
    /// What a self-calibration of the depth found before this run (`plumb reconstruct
    /// --self-calibrate`): written as metrics.json's "self_calibration" and shown in the report;
    /// null when the depth was not self-calibrated.
    nlohmann::json self_calibration;
    /// Asked between stages (and by the raw frames' source, when it is made to): when it returns
    /// true the pipeline returns kCancelled at once. Empty: never stop.
    std::function<bool()> stop_requested;
};

/// One variant's result.
struct VariantResult {
    std::string name;  ///< "full" or "baseline"
    std::vector<Eigen::Isometry3d> T_W_F;
    std::optional<Layout> layout;
    TriangleMesh mesh;
    io::Trajectory trajectory;  ///< per-frame camera -> world poses of this variant
    VariantEvaluation evaluation;
};

struct PipelineResult {
    std::vector<VariantResult> variants;  ///< the main variant first
    nlohmann::json metrics;               ///< the metrics.json document
};

/// Runs the pipeline and writes the output contract into `out_dir` (created when missing).
/// `show_progress` reports each long stage on stderr. Errors name the stage that failed.
Result<PipelineResult> runPipeline(const PipelineInput& input, const PipelineConfig& config,
                                   const std::filesystem::path& out_dir, bool show_progress);

/// A one-screen summary of a run for the terminal (accuracy of each variant when measured).
std::string summarize(const PipelineResult& result);

}  // namespace plumb::backend
