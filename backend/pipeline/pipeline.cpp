// SPDX-License-Identifier: Apache-2.0
#include "backend/pipeline/pipeline.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>

#include <ctime>
#include <fstream>
#include <limits>
#include <memory>
#include <numbers>
#include <sstream>

#include "backend/layout/estimate_layout.hpp"
#include "backend/layout/fragment_planes.hpp"
#include "backend/registration/prepared_fragment.hpp"
#include "backend/report/floorplan_svg.hpp"
#include "backend/report/registration_outputs.hpp"
#include "backend/report/report_html.hpp"
#include "backend/report/stage_timer.hpp"
#include "common/core/logging.hpp"
#include "common/core/parallel.hpp"
#include "common/core/progress.hpp"
#include "common/io/ply.hpp"
#include "common/io/text_file.hpp"
#include "common/io/trajectory.hpp"
#include "common/layout/layout_json.hpp"

namespace plumb::backend {

namespace fs = std::filesystem;

void describe(config::Schema& s, LayoutStageConfig& c) {
    s.section("planes", c.planes, "per-fragment planes: supervoxels, T-linkage, graph cuts");
    s.section("estimate", c.estimate, "dominant planes, base plane, walls, weak Manhattan");
    s.field("num_threads", c.num_threads,
            "fragments whose planes are extracted side by side (0 = all cores); results do not "
            "depend on it")
        .min(0);
}

void describe(config::Schema& s, PipelineConfig& c) {
    s.field("use_layout", c.use_layout,
            "run layout estimation and layout-constrained global registration (false = the "
            "Choi-style baseline, --no-layout)");
    s.field("compare_baseline", c.compare_baseline,
            "with use_layout, also produce the baseline in <out>/baseline for comparison");
    s.section("registration", c.registration, "initial registration (paper §3.1)");
    s.section("layout", c.layout, "layout estimation (paper §3.2)");
    s.section("alternation", c.alternation,
              "Algorithm 1 and layout-constrained global registration (paper §3.3)");
    s.section("final_model", c.final_model, "the final mesh");
}

namespace {

ProgressOptions progressOptions(bool show) {
    ProgressOptions o;
    if (!show) o.mode = ProgressOptions::Mode::kQuiet;
    return o;
}

/// The pose-graph edges that survived, as the priors E_pair of the global registration.
std::vector<global::PairPrior> pairPriors(const posegraph::PoseGraph& graph) {
    std::vector<global::PairPrior> priors;
    for (const auto& e : graph.edges) {
        if (!e.kept) continue;
        using Information = posegraph::PoseGraphEdge::Information;
        const bool choi = e.information_source == Information::kChoi;
        priors.push_back({e.source, e.target, e.T_source_target, e.information,
                          choi ? 0.0 : e.num_correspondences,
                          e.information_source == Information::kTracker});
    }
    return priors;
}

/// The final mesh of every variant of `T` (one set of fragment poses each), from one pass over
/// the raw frames or the fragment surfaces; *how says which (metrics.json's final_model).
Result<std::vector<TriangleMesh>> finalMeshes(const PipelineInput& input,
                                              const std::vector<std::vector<Eigen::Isometry3d>>& T,
                                              const FinalModelConfig& config,
                                              const std::string& what, bool show_progress,
                                              std::string* how) {
    Result<std::vector<FinalModel>> models = std::vector<FinalModel>{};
    if (input.open_raw_frames) {
        Result<std::unique_ptr<FrameSource>> source = input.open_raw_frames();
        if (!source.isOk()) return prefixed(source.status(), "reopening the raw frames");
        const std::optional<size_t> total = (*source)->size();
        Progress progress("re-integrating frames (" + what + ")", total.value_or(0),
                          progressOptions(show_progress));
        models = integrateRawFrames(**source, input.fragments, T, config, advanceOf(progress));
        progress.finish();
        *how = "raw frames re-integrated";
        if (models.isOk() && !models->empty() && models->front().colour_from_fragments) {
            log::info(
                "final model: the raw frames carry no colour; the mesh takes the colour of "
                "the fragments' points");
            *how += ", coloured from the fragment points";
        }
    } else {
        Progress progress("fusing fragment surfaces (" + what + ")", input.fragments.size(),
                          progressOptions(show_progress));
        models =
            fuseFragmentSurfaces(input.fragments, T, input.camera, config, advanceOf(progress));
        progress.finish();
        *how = "fragment surfaces fused";
    }
    if (!models.isOk()) return models.status();
    std::vector<TriangleMesh> meshes;
    for (FinalModel& m : *models) meshes.push_back(std::move(m.mesh));
    return meshes;
}

posegraph::PoseGraph withPoses(posegraph::PoseGraph graph,
                               const std::vector<Eigen::Isometry3d>& T) {
    graph.T_W_F = T;
    return graph;
}

nlohmann::json edgeSummary(const registration::RegistrationOutcome& outcome) {
    int odometry = 0, loops = 0, pruned = 0, rejected = 0;
    for (const auto& e : outcome.graph.edges) {
        if (e.kind == posegraph::PoseGraphEdge::Kind::kOdometry) {
            ++odometry;
        } else if (e.kept) {
            ++loops;
        } else if (e.reason.rfind("rejected", 0) == 0) {
            ++rejected;  // a candidate that failed a check before the pose graph
        } else {
            ++pruned;  // by the line process, or dropped by the refinement pass
        }
    }
    const registration::PairStats& s = outcome.stats;
    return {{"odometry_edges", odometry},
            {"loop_edges", loops},
            {"pruned_edges", pruned},
            {"rejected_edges", rejected},
            {"loop_pairs_tried", s.loop_pairs_tried},
            {"loop_pairs_skipped", s.loop_pairs_skipped},
            {"ransac_runs", s.ransac_runs},
            {"ransac_failed", s.ransac_failed},
            {"overlap_rejected", s.overlap_rejected},
            {"rotation_rejected", s.rotation_rejected},
            {"translation_rejected", s.translation_rejected},
            {"refinement_realigned", outcome.refinement_realigned},
            {"refinement_settled", outcome.refinement_settled},
            {"pose_graph_iterations", outcome.first.iterations + outcome.refined.iterations},
            {"line_process_mu", outcome.refined_ran ? outcome.refined.mu : outcome.first.mu},
            {"seconds",
             {{"index", outcome.index_seconds},
              {"pairs", outcome.pairs_seconds},
              {"refinement", outcome.refinement_seconds},
              {"pose_graph", outcome.optimise_seconds}}}};
}

/// Step 1 (§3.1): every fragment downsampled, with normals and FPFH.
Result<std::vector<registration::PreparedFragment>> prepareAll(
    const std::vector<Fragment>& fragments, const registration::PrepareConfig& config,
    bool show_progress) {
    std::vector<registration::PreparedFragment> prepared(fragments.size());
    std::vector<Status> status(fragments.size());
    Progress progress("preparing fragments", fragments.size(), progressOptions(show_progress));
    // Fragments side by side (each also parallel inside; results do not depend on either).
    parallelFor(config.num_threads, fragments.size(), [&](size_t i) {
        Result<registration::PreparedFragment> p =
            registration::prepareFragment(fragments[i], config);
        if (p.isOk()) {
            prepared[i] = std::move(*p);
        } else {
            status[i] = prefixed(p.status(), fmt::format("preparing fragment {}", i));
        }
        progress.advance();
    });
    progress.finish();
    for (const Status& s : status) PLUMB_RETURN_IF_ERROR(s);
    return prepared;
}

/// Step 3 (§3.2): every fragment's planes (supervoxels, T-linkage, graph cuts).
Result<std::vector<layout::FragmentPlanes>> extractAllPlanes(const std::vector<Fragment>& fragments,
                                                             const LayoutStageConfig& config,
                                                             bool show_progress) {
    std::vector<layout::FragmentPlanes> planes(fragments.size());
    std::vector<Status> status(fragments.size());
    Progress progress("extracting fragment planes", fragments.size(),
                      progressOptions(show_progress));
    parallelFor(config.num_threads, fragments.size(), [&](size_t i) {
        if (fragments[i].points_F.empty()) {
            // A fragment closed by lost tracking may hold no surface: it has no planes, and the
            // layout is estimated from the others.
            log::warn("fragment {} has no points; it contributes no planes to the layout",
                      fragments[i].id);
            planes[i].fragment_id = fragments[i].id;
        } else if (Result<layout::FragmentPlanes> p =
                       layout::extractFragmentPlanes(fragments[i], config.planes);
                   p.isOk()) {
            planes[i] = std::move(*p);
        } else {
            status[i] = prefixed(p.status(), fmt::format("planes of fragment {}", i));
        }
        progress.advance();
    });
    progress.finish();
    for (const Status& s : status) PLUMB_RETURN_IF_ERROR(s);
    return planes;
}

/// Every inner iteration of Algorithm 1 with its energy terms.
nlohmann::json energiesJson(const global::AlternationResult& a) {
    nlohmann::json energies = nlohmann::json::array();
    for (const auto& outer : a.iterations) {
        for (const auto& inner : outer.inner) {
            energies.push_back({{"outer", outer.iteration},
                                {"round", inner.round},
                                {"inner", inner.iteration},
                                {"accepted", inner.accepted},
                                {"energy", inner.energy.total},
                                {"layout", inner.energy.layout},
                                {"frag", inner.energy.frag},
                                {"pair", inner.energy.pair}});
        }
    }
    return energies;
}

/// One variant of the result (full method or baseline): its poses, layout and output folder.
struct Plan {
    std::string name;
    const std::vector<Eigen::Isometry3d>* T;
    const std::optional<Layout>* layout;
    fs::path dir;
};

/// "full and baseline": the plans' names, for the stage table.
std::string planNames(const std::vector<Plan>& plans) {
    std::string names;
    for (const Plan& plan : plans) names += (names.empty() ? "" : " and ") + plan.name;
    return names;
}

/// The final mesh of every plan, in order, from one pass (finalMeshes), timed as one stage.
Result<std::vector<TriangleMesh>> planMeshes(const PipelineInput& input,
                                             const std::vector<Plan>& plans,
                                             const FinalModelConfig& config, bool show_progress,
                                             StageTimer& timer, std::string* how) {
    std::vector<std::vector<Eigen::Isometry3d>> poses;
    for (const Plan& plan : plans) poses.push_back(*plan.T);
    const std::string names = planNames(plans);
    auto scope = timer.scope("final model (" + names + ")");
    Result<std::vector<TriangleMesh>> meshes =
        finalMeshes(input, poses, config, names, show_progress, how);
    if (!meshes.isOk()) return prefixed(meshes.status(), "final model (" + names + ")");
    return meshes;
}

/// A variant's files: registration outputs, mesh, and the layout with its floor plan.
Status writeVariantFiles(const fs::path& dir, const std::vector<Fragment>& fragments,
                         const posegraph::PoseGraph& graph,
                         const posegraph::PoseGraphReport& report, const TriangleMesh& mesh,
                         const std::optional<Layout>& layout) {
    Status s = registration::writeRegistrationOutputs(dir, fragments, graph, report);
    if (!s.isOk()) return prefixed(s, "writing " + dir.string());
    s = io::writeTriangleMesh(dir / "mesh.ply", mesh);
    if (!s.isOk()) return prefixed(s, "writing the mesh");
    if (layout) {
        s = io::writeLayoutJson(dir / "layout.json", *layout);
        if (!s.isOk()) return prefixed(s, "writing layout.json");
        s = layout::writeFloorplanSvg(dir / "floorplan.svg", *layout,
                                      layout::floorplanOverlays(fragments, graph.T_W_F, *layout));
        if (!s.isOk()) return prefixed(s, "writing floorplan.svg");
    }
    return Status::ok();
}

/// Writes variant `v`'s files (its poses, mesh and layout) into `dir` and evaluates it against
/// the input's ground truth (v->evaluation).
Status outputAndEvaluate(const fs::path& dir, const PipelineInput& input,
                         const registration::RegistrationOutcome& outcome,
                         const std::optional<Layout>& full_layout,
                         const eval::ClosestPoints* gt_points, VariantResult* v) {
    const posegraph::PoseGraph graph = withPoses(outcome.graph, v->T_W_F);
    PLUMB_RETURN_IF_ERROR(writeVariantFiles(dir, input.fragments, graph,
                                            outcome.refined_ran ? outcome.refined : outcome.first,
                                            v->mesh, v->layout));
    Result<io::Trajectory> trajectory = registration::frameTrajectory(input.fragments, graph);
    if (!trajectory.isOk()) return trajectory.status();
    v->trajectory = *trajectory;
    Result<VariantEvaluation> ev =
        evaluateVariant(v->name, *trajectory, v->mesh, v->layout, input.ground_truth, full_layout,
                        EvaluationConfig{}, gt_points);
    if (!ev.isOk()) return prefixed(ev.status(), "evaluating " + v->name);
    v->evaluation = std::move(*ev);
    return Status::ok();
}

/// What metrics.json says of the input before any figure: format, input, fragments and frames,
/// the ground truth, and where the final model came from.
nlohmann::json metricsHeader(const PipelineInput& input, const std::string& final_model) {
    size_t frames = 0;
    for (const Fragment& f : input.fragments) frames += f.frames.size();
    nlohmann::json metrics;
    metrics["format"] = "plumb-metrics-1";
    metrics["status"] = "complete";  // an interrupted `plumb reconstruct` writes "interrupted"
    metrics["input"] = input.description;
    metrics["fragments"] = input.fragments.size();
    metrics["frames"] = frames;
    metrics["ground_truth"] = input.ground_truth.description.empty()
                                  ? std::string("none")
                                  : input.ground_truth.description;
    metrics["final_model"] = final_model;
    return metrics;
}

/// Who made this output, when, and how long it took: plumb's version, the UTC date, the
/// command line, and the time of tracking and fusion (when the caller measured it) plus the
/// backend's.
nlohmann::json runJson(const PipelineInput& input, double backend_seconds) {
    nlohmann::json run;
    run["version"] = PLUMB_VERSION_STRING;
    const std::time_t now = std::time(nullptr);
    std::tm utc{};
    gmtime_r(&now, &utc);
    char date[32];
    std::strftime(date, sizeof(date), "%Y-%m-%dT%H:%M:%SZ", &utc);
    run["date_utc"] = date;
    if (!input.command_line.empty()) run["command_line"] = input.command_line;
    run["backend_seconds"] = backend_seconds;
    if (input.tracking_fusion_seconds >= 0.0) {
        run["tracking_fusion_seconds"] = input.tracking_fusion_seconds;
        run["total_seconds"] = input.tracking_fusion_seconds + backend_seconds;
    }
    return run;
}

nlohmann::json stagesJson(const StageTimer& timer) {
    nlohmann::json stages = nlohmann::json::array();
    for (const StageTime& st : timer.stages())
        stages.push_back({{"name", st.name}, {"seconds", st.seconds}});
    return stages;
}

/// The <svg> element of an SVG file, for inlining into the report; empty when there is none.
std::string inlineSvg(const fs::path& path) {
    if (!fs::exists(path)) return {};
    std::ifstream in(path);
    std::stringstream text;
    text << in.rdbuf();
    std::string svg = text.str();
    const size_t start = svg.find("<svg");
    if (start != std::string::npos) svg.erase(0, start);
    return svg;
}

/// The variant's camera path for the top view, with each pose's ATE error when it was scored.
TopViewTrajectory topViewTrajectory(const VariantResult& v) {
    TopViewTrajectory t;
    for (const io::StampedPose& p : v.trajectory) t.positions_W.push_back(p.T_W_C.translation());
    if (v.evaluation.trajectory) {
        const eval::TrajectoryEvaluation& te = *v.evaluation.trajectory;
        t.errors_m.assign(t.positions_W.size(), std::numeric_limits<double>::quiet_NaN());
        for (size_t k = 0; k < te.pairs.size() && k < te.ate.errors_m.size(); ++k)
            if (te.pairs[k].second < t.errors_m.size())
                t.errors_m[te.pairs[k].second] = te.ate.errors_m[k];
    }
    return t;
}

/// The main variant's walls for the report's table: id, normal and offset in the layout frame
/// (n.x + d = 0, z up, floor at 0), length along the floor, and whether the weak-Manhattan step
/// snapped it. Planarity and ground-truth errors are joined in by the report from "variants".
nlohmann::json layoutWallsJson(const Layout& layout) {
    nlohmann::json walls = nlohmann::json::array();
    for (const LayoutPlane* w : layout.walls())
        walls.push_back({{"id", w->id},
                         {"normal_L", {w->normal_L.x(), w->normal_L.y(), w->normal_L.z()}},
                         {"offset_m", w->d_L},
                         {"length_m", (w->end_L - w->start_L).norm()},
                         {"manhattan_snapped", w->manhattan_snapped}});
    return walls;
}

/// What tracking left behind in the fragments, for the report's warnings: frames it failed on,
/// fragments it closed early, and fragments whose odometry left a translation direction
/// (nearly) unobserved: smallest / largest eigenvalue of the translation block of
/// Fragment::odometry_information below `min_ratio` (a plain corridor, a single wall).
nlohmann::json trackingJson(const std::vector<Fragment>& fragments, double min_ratio = 1e-3) {
    size_t failed = 0;
    nlohmann::json lost = nlohmann::json::array();
    nlohmann::json weak = nlohmann::json::array();
    size_t weak_frames = 0;
    for (const Fragment& f : fragments) {
        for (const FragmentFrame& fr : f.frames) failed += fr.tracking_ok ? 0 : 1;
        if (f.end == FragmentEnd::kTrackingLost) lost.push_back(f.id);
        const Eigen::Matrix3d info_t = f.odometry_information.bottomRightCorner<3, 3>();
        if (info_t.isZero(0.0)) continue;  // unknown: first of a segment, older data
        const Eigen::Vector3d ev =
            Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(info_t).eigenvalues().cwiseMax(0.0);
        if (ev.maxCoeff() <= 0.0 || ev.minCoeff() < min_ratio * ev.maxCoeff()) {
            weak.push_back(f.id);
            weak_frames += f.frames.size();
        }
    }
    return {{"frames_tracking_failed", failed},
            {"fragments_closed_by_tracking_loss", lost},
            {"fragments_with_unobserved_directions", weak},
            {"frames_in_fragments_with_unobserved_directions", weak_frames},
            {"unobserved_direction_eigenvalue_ratio", min_ratio}};
}

/// Between stages: kCancelled when the caller asked to stop (`after`: the stage just done).
Status stopIfRequested(const PipelineInput& input, const char* after) {
    if (input.stop_requested && input.stop_requested())
        return cancelled(std::string("stopped on request after ") + after);
    return Status::ok();
}

/// metrics.json, report.html (with the floor plan inlined) and config.toml.
Status writeDocuments(const fs::path& out_dir, const PipelineInput& input,
                      const nlohmann::json& metrics, ReportFigures& figures) {
    figures.floorplan_svg = inlineSvg(out_dir / "floorplan.svg");
    PLUMB_RETURN_IF_ERROR(io::writeTextReplacing(out_dir / "metrics.json", metrics.dump(2) + "\n"));
    PLUMB_RETURN_IF_ERROR(
        io::writeTextReplacing(out_dir / "report.html", renderReportHtml(metrics, figures)));
    if (!input.config_toml.empty())
        PLUMB_RETURN_IF_ERROR(io::writeTextReplacing(out_dir / "config.toml", input.config_toml));
    return Status::ok();
}

/// metrics.json's tracking, layout-wall and run figures and the stage table, for the report.
void addRunFigures(const PipelineInput& input, const PipelineResult& result,
                   const StageTimer& timer, nlohmann::json* metrics) {
    nlohmann::json& m = *metrics;
    m["tracking"] = trackingJson(input.fragments);
    if (!result.variants.empty() && result.variants.front().layout) {
        const Layout& main_layout = *result.variants.front().layout;
        m["layout_walls"] = layoutWallsJson(main_layout);
        m["outline_on_walls"] = wallBoundedFraction(main_layout);
        // Whose walls "variants/*/walls" (planarity) are numbered by (evaluation.hpp).
        m["planarity_reference"] =
            input.ground_truth.layout ? "ground-truth layout" : "estimated layout";
    }
    m["stages"] = stagesJson(timer);
    m["total_seconds"] = timer.totalSeconds();  // the backend's stages
    m["run"] = runJson(input, timer.totalSeconds());
}

/// The fragments must be numbered 0..n-1 in order.
Status checkFragmentIds(const std::vector<Fragment>& fragments) {
    if (fragments.empty()) return invalidArgument("no fragments to reconstruct from");
    for (size_t i = 0; i < fragments.size(); ++i) {
        if (fragments[i].id != i)
            return invalidArgument(
                fmt::format("fragment ids must be 0..{} in order; position {} holds fragment {}",
                            fragments.size() - 1, i, fragments[i].id));
    }
    return Status::ok();
}

/// The report's pictures of the main variant: the model views and, with ground-truth points,
/// the reconstruction-error map (or why there is none).
void addMainVariantFigures(const VariantResult& v, const PipelineInput& input,
                           const std::optional<Layout>& full_layout, ReportFigures* figures) {
    figures->model_views = renderModelViews(v.mesh, v.layout ? v.layout : full_layout);
    if (input.ground_truth.points.empty()) return;
    // The evaluation measured every vertex already; the map draws those errors.
    Result<ReconErrorMap> map =
        v.evaluation.vertex_errors_m.empty()
            ? reconErrorMap(v.mesh, v.evaluation.T_gt_est, input.ground_truth.points, full_layout)
            : reconErrorMap(v.mesh, v.evaluation.vertex_errors_m, full_layout);
    if (map.isOk()) {
        figures->recon_error_svg = std::move(map->svg);
    } else {
        figures->recon_error_note = map.status().message();
    }
}

/// Every plan's files and evaluation, side by side (each is parallel inside; one variant's
/// serial writing overlaps the other's searches), against one ground-truth tree built for all.
/// `variants` receives them in plan order; the report's figures of the first go into `figures`.
Status outputAndEvaluateAll(const PipelineInput& input, const std::vector<Plan>& plans,
                            const registration::RegistrationOutcome& outcome,
                            const std::optional<Layout>& full_layout,
                            std::vector<TriangleMesh> meshes, std::vector<VariantResult>* variants,
                            ReportFigures* figures) {
    std::shared_ptr<const eval::ClosestPoints> gt_points;
    if (!input.ground_truth.points.empty()) {
        Result<std::shared_ptr<const eval::ClosestPoints>> built =
            eval::ClosestPoints::build(input.ground_truth.points);
        if (!built.isOk()) return prefixed(built.status(), "the ground-truth surface");
        gt_points = std::move(*built);
    }
    for (const Plan& plan : plans) {
        std::error_code ec;
        fs::create_directories(plan.dir, ec);
        if (ec)
            return ioError(fmt::format("{}: cannot create: {}", plan.dir.string(), ec.message()));
    }
    std::vector<Status> status(plans.size(), Status::ok());
    std::vector<std::string> top_views(plans.size());
    parallelFor(0, plans.size(), [&](size_t p) {
        VariantResult& v = (*variants)[p];
        v.name = plans[p].name;
        v.T_W_F = *plans[p].T;
        v.layout = *plans[p].layout;
        v.mesh = std::move(meshes[p]);
        status[p] =
            outputAndEvaluate(plans[p].dir, input, outcome, full_layout, gt_points.get(), &v);
        if (!status[p].isOk()) return;
        top_views[p] = topViewSvg(v.mesh, full_layout, topViewTrajectory(v));
        if (p == 0) addMainVariantFigures(v, input, full_layout, figures);
    });
    for (size_t p = 0; p < plans.size(); ++p) {
        PLUMB_RETURN_IF_ERROR(status[p]);
        figures->top_views[plans[p].name] = std::move(top_views[p]);
    }
    return Status::ok();
}

}  // namespace

Result<PipelineResult> runPipeline(const PipelineInput& input, const PipelineConfig& config,
                                   const fs::path& out_dir, bool show_progress) {
    PLUMB_RETURN_IF_ERROR(checkFragmentIds(input.fragments));
    std::error_code ec;
    fs::create_directories(out_dir, ec);
    if (ec) return ioError(fmt::format("{}: cannot create: {}", out_dir.string(), ec.message()));

    StageTimer timer;
    const std::vector<Fragment>& fragments = input.fragments;
    auto stop = [&input](const char* after) { return stopIfRequested(input, after); };

    // 1. Preparation (§3.1).
    std::vector<registration::PreparedFragment> prepared;
    {
        auto scope = timer.scope("prepare fragments (downsample, normals, FPFH)");
        Result<std::vector<registration::PreparedFragment>> p =
            prepareAll(fragments, config.registration.prepare, show_progress);
        if (!p.isOk()) return p.status();
        prepared = std::move(*p);
    }
    PLUMB_RETURN_IF_ERROR(stop("preparing the fragments"));

    // 2. Initial registration: the baseline (Choi et al. 2015).
    registration::RegistrationOutcome outcome;
    {
        auto scope = timer.scope("initial registration (pairs, loop closures, pose graph)");
        Progress progress("registering fragment pairs", 0, progressOptions(show_progress));
        Result<registration::RegistrationOutcome> r = registration::registerFragments(
            fragments, prepared, config.registration, advanceOf(progress));
        progress.finish();
        if (!r.isOk()) return prefixed(r.status(), "initial registration");
        outcome = std::move(*r);
    }
    PLUMB_RETURN_IF_ERROR(stop("the initial registration"));
    const std::vector<Eigen::Isometry3d> T_baseline = outcome.graph.T_W_F;

    // 3. Layout (§3.2) and Algorithm 1 (§3.3).
    std::vector<layout::FragmentPlanes> planes;
    {
        auto scope = timer.scope("per-fragment planes (supervoxels, T-linkage, graph cuts)");
        Result<std::vector<layout::FragmentPlanes>> p =
            extractAllPlanes(fragments, config.layout, show_progress);
        if (!p.isOk()) return p.status();
        planes = std::move(*p);
    }
    PLUMB_RETURN_IF_ERROR(stop("the per-fragment planes"));
    nlohmann::json layout_diagnostics;
    const global::LayoutEstimator estimator =
        [&](const std::vector<Eigen::Isometry3d>& T) -> Result<Layout> {
        Result<layout::LayoutEstimate> e =
            layout::estimateLayout(fragments, planes, T, config.layout.estimate);
        if (!e.isOk()) return e.status();
        layout_diagnostics = layout::toJson(e->diagnostics);
        return std::move(e->layout);
    };

    std::optional<Layout> baseline_layout;
    {
        auto scope = timer.scope("layout at the baseline poses");
        Result<Layout> l = estimator(T_baseline);
        if (l.isOk()) {
            baseline_layout = std::move(*l);
        } else {
            log::warn("no layout at the baseline poses: {}", l.status().toString());
        }
    }

    std::vector<Eigen::Isometry3d> T_full = T_baseline;
    std::optional<Layout> full_layout = baseline_layout;
    nlohmann::json energies = nlohmann::json::array();
    nlohmann::json alternation_summary;
    if (config.use_layout) {
        auto scope = timer.scope("Algorithm 1: layout <-> global registration");
        Progress progress("alternating layout and registration",
                          static_cast<uint64_t>(config.alternation.max_outer_iterations),
                          progressOptions(show_progress));
        Result<global::AlternationResult> a =
            global::alternate(fragments, T_baseline, pairPriors(outcome.graph), estimator,
                              config.alternation, advanceOf(progress));
        progress.finish();
        if (!a.isOk()) return prefixed(a.status(), "layout-constrained global registration");
        T_full = a->T_W_F;
        full_layout = a->layout;
        energies = energiesJson(*a);
        alternation_summary = {{"outer_iterations", a->iterations.size()},
                               {"converged", a->converged},
                               {"stop_reason", a->stop_reason}};
    }
    PLUMB_RETURN_IF_ERROR(stop("the layout and global registration"));

    // 4./5. Final models, outputs and evaluation per variant.
    std::vector<Plan> plans;
    if (config.use_layout) {
        plans.push_back({"full", &T_full, &full_layout, out_dir});
        if (config.compare_baseline)
            plans.push_back({"baseline", &T_baseline, &baseline_layout, out_dir / "baseline"});
    } else {
        plans.push_back({"baseline", &T_baseline, &baseline_layout, out_dir});
    }

    PipelineResult result;
    ReportFigures figures;
    nlohmann::json variants_json = nlohmann::json::object();
    std::string final_model;
    Result<std::vector<TriangleMesh>> meshes =
        planMeshes(input, plans, config.final_model, show_progress, timer, &final_model);
    if (!meshes.isOk()) return meshes.status();
    PLUMB_RETURN_IF_ERROR(stop("the final model"));
    std::vector<VariantResult> variants(plans.size());
    {
        auto scope = timer.scope("outputs and evaluation (" + planNames(plans) + ")");
        PLUMB_RETURN_IF_ERROR(outputAndEvaluateAll(input, plans, outcome, full_layout,
                                                   std::move(*meshes), &variants, &figures));
    }
    for (VariantResult& v : variants) {
        variants_json[v.name] = toJson(v.evaluation);
        result.variants.push_back(std::move(v));
    }

    nlohmann::json metrics = metricsHeader(input, final_model);
    metrics["variants"] = variants_json;
    metrics["registration"] = edgeSummary(outcome);
    if (!input.self_calibration.is_null()) metrics["self_calibration"] = input.self_calibration;
    if (!alternation_summary.is_null()) metrics["alternation"] = alternation_summary;
    metrics["energies"] = energies;
    if (!layout_diagnostics.is_null()) metrics["layout_diagnostics"] = layout_diagnostics;
    addRunFigures(input, result, timer, &metrics);
    PLUMB_RETURN_IF_ERROR(writeDocuments(out_dir, input, metrics, figures));
    result.metrics = std::move(metrics);
    return result;
}

std::string summarize(const PipelineResult& result) {
    std::ostringstream out;
    const nlohmann::json& m = result.metrics;
    out << fmt::format("{} fragments, {} frames; {}\n", m.value("fragments", 0),
                       m.value("frames", 0), m.value("final_model", std::string()));
    for (const VariantResult& v : result.variants) {
        const VariantEvaluation& e = v.evaluation;
        out << fmt::format("  {:<9}", v.name);
        if (e.trajectory) out << fmt::format(" ATE RMSE {:.2f} cm", e.trajectory->ate.rmse_m * 100);
        if (e.recon)
            out << fmt::format(", recon error mean {:.2f} cm median {:.2f} cm",
                               e.recon->accuracy.mean_m * 100, e.recon->accuracy.median_m * 100);
        if (!e.walls.empty()) out << fmt::format(", wall RMS {:.1f} mm", e.mean_wall_rms_m * 1000);
        if (e.layout)
            out << fmt::format(", walls {}/{} (angle err {:.2f} deg)", e.layout->walls.size(),
                               e.layout->num_gt_walls, e.layout->mean_wall_angle_error_deg);
        if (!e.trajectory && !e.recon) out << " (no ground truth to measure against)";
        out << "\n";
    }
    if (m.contains("total_seconds"))
        out << fmt::format("  backend time {:.1f} s\n", m["total_seconds"].get<double>());
    return out.str();
}

}  // namespace plumb::backend
