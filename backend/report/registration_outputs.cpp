// SPDX-License-Identifier: Apache-2.0
#include "backend/report/registration_outputs.hpp"

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>
#include <system_error>

#include "common/io/text_file.hpp"

namespace plumb::registration {

namespace {

using Json = nlohmann::ordered_json;

Json matrixJson(const Eigen::MatrixXd& m) {
    Json rows = Json::array();
    for (Eigen::Index r = 0; r < m.rows(); ++r) {
        Json row = Json::array();
        for (Eigen::Index c = 0; c < m.cols(); ++c) row.push_back(m(r, c));
        rows.push_back(std::move(row));
    }
    return rows;
}

}  // namespace

std::string poseGraphJson(const PoseGraph& graph, const posegraph::PoseGraphReport& report) {
    Json j;
    j["convention"] =
        "T_source_target maps target-fragment points into the source frame: "
        "T_W_target = T_W_source * T_source_target; T_W_F maps fragment to world";
    Json nodes = Json::array();
    for (size_t i = 0; i < graph.T_W_F.size(); ++i) {
        Json n;
        n["id"] = i;
        n["T_W_F"] = matrixJson(graph.T_W_F[i].matrix());
        nodes.push_back(std::move(n));
    }
    j["nodes"] = std::move(nodes);
    Json edges = Json::array();
    for (const posegraph::PoseGraphEdge& e : graph.edges) {
        Json o;
        o["source"] = e.source;
        o["target"] = e.target;
        o["kind"] = posegraph::toString(e.kind);
        o["kept"] = e.kept;
        o["reason"] = e.reason;
        o["overlap"] = e.overlap;
        o["inlier_rmse_m"] = e.inlier_rmse_m;
        o["line_process"] = e.line_process;
        const bool choi = e.information_source == posegraph::PoseGraphEdge::Information::kChoi;
        o["num_correspondences"] = choi ? e.information(5, 5) : e.num_correspondences;
        o["information_source"] = posegraph::toString(e.information_source);
        o["T_source_target"] = matrixJson(e.T_source_target.matrix());
        o["information"] = matrixJson(e.information);
        edges.push_back(std::move(o));
    }
    j["edges"] = std::move(edges);
    Json r;
    r["iterations"] = report.iterations;
    r["rounds"] = report.rounds;
    r["initial_cost"] = report.initial_cost;
    r["final_cost"] = report.final_cost;
    r["mu"] = report.mu;
    r["num_loop_edges"] = report.num_loop_edges;
    r["num_pruned"] = report.num_pruned;
    r["converged"] = report.converged;
    j["optimisation"] = std::move(r);
    return j.dump(2) + "\n";
}

Status writePoseGraphJson(const std::filesystem::path& path, const PoseGraph& graph,
                          const posegraph::PoseGraphReport& report) {
    return io::writeText(path, poseGraphJson(graph, report));
}

Result<io::Trajectory> frameTrajectory(const std::vector<Fragment>& fragments,
                                       const PoseGraph& graph) {
    io::Trajectory out;
    for (const Fragment& f : fragments) {
        if (f.id >= graph.T_W_F.size()) {
            return invalidArgument("trajectory: fragment " + std::to_string(f.id) +
                                   " has no node in the pose graph (" +
                                   std::to_string(graph.T_W_F.size()) + " nodes)");
        }
        for (const FragmentFrame& fr : f.frames) {
            if (!fr.tracking_ok) continue;
            io::StampedPose p;
            p.timestamp_s = fr.timestamp_s;
            p.T_W_C = graph.T_W_F[f.id] * fr.T_F_C;
            out.push_back(p);
        }
    }
    return out;
}

Status writeRegistrationLogInfo(const std::filesystem::path& log_path,
                                const std::filesystem::path& info_path, const PoseGraph& graph) {
    std::vector<const posegraph::PoseGraphEdge*> kept;
    for (const auto& e : graph.edges) {
        if (e.kept) kept.push_back(&e);
    }
    std::stable_sort(kept.begin(), kept.end(), [](const auto* a, const auto* b) {
        return a->source != b->source ? a->source < b->source : a->target < b->target;
    });
    const int n = static_cast<int>(graph.T_W_F.size());
    std::vector<io::RegistrationEntry> log;
    std::vector<io::InformationEntry> info;
    for (const auto* e : kept) {
        io::RegistrationEntry r;
        r.i = static_cast<int>(e->source);
        r.j = static_cast<int>(e->target);
        r.num_fragments = n;
        r.T_i_j = e->T_source_target;
        log.push_back(r);
        io::InformationEntry in;
        in.i = r.i;
        in.j = r.j;
        in.num_fragments = n;
        in.information = e->information;
        info.push_back(in);
    }
    PLUMB_RETURN_IF_ERROR(io::writeRegistrationLog(log_path, log));
    return io::writeInformationFile(info_path, info);
}

Status writeRegistrationOutputs(const std::filesystem::path& dir,
                                const std::vector<Fragment>& fragments, const PoseGraph& graph,
                                const posegraph::PoseGraphReport& report) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return ioError(dir.string() + ": " + ec.message());
    PLUMB_RETURN_IF_ERROR(writePoseGraphJson(dir / "pose_graph.json", graph, report));
    Result<io::Trajectory> traj = frameTrajectory(fragments, graph);
    if (!traj.isOk()) return traj.status();
    PLUMB_RETURN_IF_ERROR(io::writeTumTrajectory(dir / "trajectory.txt", *traj));
    PLUMB_RETURN_IF_ERROR(io::writeLogTrajectory(dir / "trajectory.log", *traj));
    return writeRegistrationLogInfo(dir / "registration.log", dir / "registration.info", graph);
}

}  // namespace plumb::registration
