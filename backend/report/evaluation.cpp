// SPDX-License-Identifier: Apache-2.0
#include "backend/report/evaluation.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>

#include "common/io/ply.hpp"
#include "common/layout/layout_json.hpp"

namespace plumb::backend {

namespace fs = std::filesystem;

Result<GroundTruth> loadGroundTruth(const fs::path& dataset_dir) {
    GroundTruth gt;
    std::vector<std::string> parts;
    if (fs::exists(dataset_dir / "groundtruth.txt")) {
        Result<io::Trajectory> t = io::readTumTrajectory(dataset_dir / "groundtruth.txt");
        if (!t.isOk()) return t.status();
        gt.trajectory = std::move(*t);
        parts.push_back("groundtruth.txt");
    } else if (fs::exists(dataset_dir / "trajectory.log")) {
        Result<io::Trajectory> t = io::readLogTrajectory(dataset_dir / "trajectory.log");
        if (!t.isOk()) return t.status();
        gt.trajectory = std::move(*t);
        parts.push_back("trajectory.log");
    }
    if (fs::exists(dataset_dir / "gt_points.ply")) {
        Result<PointCloud> cloud = io::readPointCloud(dataset_dir / "gt_points.ply");
        if (!cloud.isOk()) return cloud.status();
        gt.points = std::move(cloud->points);
        parts.push_back("gt_points.ply");
    }
    if (fs::exists(dataset_dir / "layout.json")) {
        Result<Layout> layout = io::readLayoutJson(dataset_dir / "layout.json");
        if (!layout.isOk()) return layout.status();
        gt.layout = std::move(*layout);
        parts.push_back("layout.json");
    }
    gt.description = parts.empty()
                         ? std::string("none")
                         : fmt::format("{} ({})", dataset_dir.string(), fmt::join(parts, ", "));
    return gt;
}

namespace {

struct FittedPlane {
    Eigen::Vector3d normal;
    double rms_m = 0.0;
};

/// Least-squares plane through points (smallest eigenvector of the scatter), oriented like
/// `reference_normal`.
FittedPlane fitPlane(const std::vector<Eigen::Vector3d>& points,
                     const Eigen::Vector3d& reference_normal) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const auto& p : points) centroid += p;
    centroid /= static_cast<double>(points.size());
    Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
    for (const auto& p : points) scatter += (p - centroid) * (p - centroid).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
    FittedPlane fit;
    fit.normal = solver.eigenvectors().col(0).normalized();
    if (fit.normal.dot(reference_normal) < 0.0) fit.normal = -fit.normal;
    fit.rms_m =
        std::sqrt(std::max(0.0, solver.eigenvalues()(0)) / static_cast<double>(points.size()));
    return fit;
}

double angleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::acos(std::clamp(a.dot(b), -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

}  // namespace

Result<VariantEvaluation> evaluateVariant(const std::string& name, const io::Trajectory& trajectory,
                                          const TriangleMesh& mesh,
                                          const std::optional<Layout>& layout,
                                          const GroundTruth& ground_truth,
                                          const std::optional<Layout>& reference_layout,
                                          const EvaluationConfig& config,
                                          const eval::ClosestPoints* ground_truth_points) {
    VariantEvaluation ev;
    ev.name = name;
    bool aligned = false;
    if (ground_truth.trajectory && !trajectory.empty()) {
        Result<eval::TrajectoryEvaluation> t =
            eval::evaluateTrajectories(trajectory, *ground_truth.trajectory, config.trajectory);
        if (t.isOk()) {
            ev.T_gt_est = t->ate.T_gt_est;
            ev.trajectory = std::move(*t);
            aligned = true;
        } else {
            ev.notes.push_back("trajectory not evaluated: " + t.status().message());
        }
    } else {
        ev.notes.push_back("no ground-truth trajectory: ATE not measured");
    }

    if (!ground_truth.points.empty() && !mesh.vertices.empty()) {
        if (!aligned) ev.notes.push_back("reconstruction compared without trajectory alignment");
        std::vector<Eigen::Vector3f> mapped;
        mapped.reserve(mesh.vertices.size());
        const Eigen::Isometry3f T = ev.T_gt_est.cast<float>();
        for (const auto& v : mesh.vertices) mapped.push_back(T * v);
        std::shared_ptr<const eval::ClosestPoints> own;
        if (ground_truth_points == nullptr) {
            Result<std::shared_ptr<const eval::ClosestPoints>> built =
                eval::ClosestPoints::build(ground_truth.points);
            if (!built.isOk()) return built.status();
            own = std::move(*built);
            ground_truth_points = own.get();
        }
        Result<eval::ReconMetrics> r = eval::evaluateReconstruction(
            mapped, *ground_truth_points, config.recon, &ev.vertex_errors_m);
        if (!r.isOk()) return r.status();
        ev.recon = std::move(*r);
    } else if (ground_truth.points.empty()) {
        ev.notes.push_back("no ground-truth surface: reconstruction error not measured");
    }

    if (layout && ground_truth.layout) {
        Layout mapped = *layout;
        mapped.T_W_L = ev.T_gt_est * layout->T_W_L;
        Result<eval::LayoutMetrics> m =
            eval::evaluateLayout(mapped, *ground_truth.layout, config.layout);
        if (!m.isOk()) return m.status();
        ev.layout = std::move(*m);
    }

    // Reference walls in the estimate's world frame.
    std::optional<Layout> reference;
    if (ground_truth.layout && aligned) {
        reference = *ground_truth.layout;
        reference->T_W_L = ev.T_gt_est.inverse() * ground_truth.layout->T_W_L;
    } else if (reference_layout) {
        reference = reference_layout;
    }
    if (!reference) {
        ev.notes.push_back("no reference walls: planarity and wall angles not measured");
        return ev;
    }
    const Eigen::Isometry3d T_L_W = reference->T_W_L.inverse();
    std::vector<std::pair<const LayoutPlane*, FittedPlane>> fitted;
    for (const LayoutPlane* wall : reference->walls()) {
        const HessianPlane plane_L{wall->normal_L, wall->d_L};
        const Eigen::Vector2d a = wall->start_L, b = wall->end_L;
        const double length = (b - a).norm();
        if (length <= 2.0 * config.wall_end_margin_m) continue;
        const Eigen::Vector2d dir = (b - a) / length;
        std::vector<Eigen::Vector3d> slab;
        for (const auto& v : mesh.vertices) {
            const Eigen::Vector3d p_L = T_L_W * v.cast<double>();
            if (std::abs(plane_L.signedDistance(p_L)) > config.wall_band_m) continue;
            const double s = (p_L.head<2>() - a).dot(dir);
            if (s < config.wall_end_margin_m || s > length - config.wall_end_margin_m) continue;
            if (reference->ceiling_height_m > 0.0 &&
                (p_L.z() < config.wall_end_margin_m ||
                 p_L.z() > reference->ceiling_height_m - config.wall_end_margin_m))
                continue;
            slab.push_back(v.cast<double>());
        }
        if (slab.size() < config.min_wall_vertices) {
            ev.notes.push_back(fmt::format("wall {}: {} mesh vertices near it, too few to measure",
                                           wall->id, slab.size()));
            continue;
        }
        const Eigen::Vector3d normal_W = reference->T_W_L.linear() * wall->normal_L;
        FittedPlane fit = fitPlane(slab, normal_W);
        ev.walls.push_back({wall->id, slab.size(), fit.rms_m, fit.normal});
        fitted.emplace_back(wall, fit);
    }
    double rms_sum = 0.0;
    for (const WallFit& w : ev.walls) rms_sum += w.rms_m;
    if (!ev.walls.empty()) ev.mean_wall_rms_m = rms_sum / static_cast<double>(ev.walls.size());
    // Angles between walls that meet (consecutive segments sharing an endpoint).
    for (size_t i = 0; i < fitted.size(); ++i) {
        for (size_t j = i + 1; j < fitted.size(); ++j) {
            const LayoutPlane& wa = *fitted[i].first;
            const LayoutPlane& wb = *fitted[j].first;
            const double gap =
                std::min({(wa.end_L - wb.start_L).norm(), (wb.end_L - wa.start_L).norm()});
            if (gap > 0.05) continue;
            WallAngle angle;
            angle.id_a = wa.id;
            angle.id_b = wb.id;
            angle.reference_deg = angleDeg(wa.normal_L, wb.normal_L);
            angle.measured_deg = angleDeg(fitted[i].second.normal, fitted[j].second.normal);
            ev.max_wall_angle_error_deg = std::max(
                ev.max_wall_angle_error_deg, std::abs(angle.measured_deg - angle.reference_deg));
            ev.wall_angles.push_back(angle);
        }
    }
    return ev;
}

nlohmann::json toJson(const VariantEvaluation& ev) {
    nlohmann::json j;
    j["name"] = ev.name;
    if (ev.trajectory) {
        const eval::AteResult& ate = ev.trajectory->ate;
        j["ate"] = {{"rmse_m", ate.rmse_m},
                    {"mean_m", ate.mean_m},
                    {"median_m", ate.median_m},
                    {"max_m", ate.max_m},
                    {"poses", ev.trajectory->pairs.size()}};
        if (ev.trajectory->rpe) {
            j["rpe"] = {
                {"trans_rmse_m", ev.trajectory->rpe->trans_rmse_m},
                {"rot_rmse_deg", ev.trajectory->rpe->rot_rmse_rad * 180.0 / std::numbers::pi}};
        }
    }
    if (ev.recon) {
        const eval::DistanceStats& a = ev.recon->accuracy;
        j["recon"] = {{"mean_m", a.mean_m},
                      {"median_m", a.median_m},
                      {"rms_m", a.rms_m},
                      {"p90_m", a.p90_m},
                      {"completeness", ev.recon->completeness},
                      {"threshold_m", ev.recon->threshold_m},
                      {"vertices", ev.recon->num_reconstructed}};
    }
    if (ev.layout) {
        const eval::LayoutMetrics& m = *ev.layout;
        j["layout"] = {{"gt_walls", m.num_gt_walls},
                       {"estimated_walls", m.num_est_walls},
                       {"matched_walls", m.walls.size()},
                       {"mean_wall_angle_error_deg", m.mean_wall_angle_error_deg},
                       {"max_wall_angle_error_deg", m.max_wall_angle_error_deg},
                       {"mean_abs_wall_offset_error_m", m.mean_abs_wall_offset_error_m},
                       {"max_abs_wall_offset_error_m", m.max_abs_wall_offset_error_m}};
        if (m.floor) j["layout"]["floor_angle_error_deg"] = m.floor->angle_error_deg;
        if (m.ceiling_height_error_m)
            j["layout"]["ceiling_height_error_m"] = *m.ceiling_height_error_m;
        nlohmann::json matches = nlohmann::json::array();
        for (const eval::PlaneError& e : m.walls)
            matches.push_back({{"gt_wall", e.gt_id},
                               {"estimated_wall", e.est_id},
                               {"angle_error_deg", e.angle_error_deg},
                               {"offset_error_m", e.offset_error_m}});
        j["layout"]["walls"] = matches;
        j["layout"]["unmatched_gt_walls"] = m.unmatched_gt_walls;
        j["layout"]["unmatched_estimated_walls"] = m.unmatched_est_walls;
    }
    nlohmann::json walls = nlohmann::json::array();
    for (const WallFit& w : ev.walls)
        walls.push_back({{"wall", w.reference_id}, {"vertices", w.vertices}, {"rms_m", w.rms_m}});
    j["walls"] = walls;
    nlohmann::json angles = nlohmann::json::array();
    for (const WallAngle& a : ev.wall_angles)
        angles.push_back({{"walls", {a.id_a, a.id_b}},
                          {"reference_deg", a.reference_deg},
                          {"measured_deg", a.measured_deg}});
    j["wall_angles"] = angles;
    j["mean_wall_rms_m"] = ev.mean_wall_rms_m;
    j["max_wall_angle_error_deg"] = ev.max_wall_angle_error_deg;
    j["notes"] = ev.notes;
    return j;
}

}  // namespace plumb::backend
