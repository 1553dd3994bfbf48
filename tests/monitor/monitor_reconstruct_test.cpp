// SPDX-License-Identifier: Apache-2.0
// The monitor's data path (DirectoryWatcher -> MonitorState) on the output folder of a real
// `plumb reconstruct` run of the simulated living room, its coverage figure checked against the
// simulator's ground-truth room.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/io/trajectory.hpp"
#include "common/layout/layout.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "messages/files.hpp"
#include "messages/fragment_codec.hpp"
#include "messages/fragment_files.hpp"
#include "tests/testing/run_program.hpp"
#include "tests/testing/shared_data.hpp"
#include "tools/monitor/monitor_state.hpp"
#include "tools/monitor/sources.hpp"

namespace plumb::monitor {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr int kFrames = 600;  // two thirds of one loop round the room: every wall, part of it
constexpr double kCellM = 0.25;

/// The fraction of the cells (kCellM, centres inside `room_S`) that at least one point falls in:
/// the coverage a perfect monitor would report, computed here without the monitor's code.
double trueCoverage(const std::vector<Eigen::Vector2d>& points_S,
                    const std::vector<Eigen::Vector2d>& room_S) {
    Eigen::Vector2d lo = room_S[0], hi = room_S[0];
    for (const auto& p : room_S) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    const int w = static_cast<int>(std::ceil((hi.x() - lo.x()) / kCellM));
    const int h = static_cast<int>(std::ceil((hi.y() - lo.y()) / kCellM));
    std::vector<char> hit(static_cast<size_t>(w) * h, 0);
    for (const auto& p : points_S) {
        const int ix = static_cast<int>(std::floor((p.x() - lo.x()) / kCellM));
        const int iy = static_cast<int>(std::floor((p.y() - lo.y()) / kCellM));
        if (ix >= 0 && iy >= 0 && ix < w && iy < h) hit[static_cast<size_t>(iy) * w + ix] = 1;
    }
    int inside = 0, covered = 0;
    for (int iy = 0; iy < h; ++iy) {
        for (int ix = 0; ix < w; ++ix) {
            if (!plumb::insidePolygon(room_S, lo + kCellM * Eigen::Vector2d(ix + 0.5, iy + 0.5)))
                continue;
            ++inside;
            covered += hit[static_cast<size_t>(iy) * w + ix];
        }
    }
    return inside > 0 ? static_cast<double>(covered) / inside : 0.0;
}

TEST(MonitorOnReconstructOutput, CoverageOfTheRoomMatchesTheSimulatorsGroundTruth) {
    // The simulator's default depth noise, as `make demo` and the README's scans use it.
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const fs::path work = plumb::testing::freshTempDir("monitor_reconstruct");
    const fs::path out = work / "out";
    const plumb::testing::ProcessRun help =
        plumb::testing::runProgram(std::string("'") + PLUMB_EXE + "'", work, {"--help"});
    if (help.out.find("  reconstruct ") == std::string::npos) {
        GTEST_SKIP() << "this build has no plumb reconstruct";
    }
    const plumb::testing::ProcessRun run = plumb::testing::runProgram(
        std::string("'") + PLUMB_EXE + "' reconstruct", work,
        {"sim:living_room", "--frames", std::to_string(kFrames), "--intrinsics", "ci",
         "--no-baseline", "--quiet", "--out", out.string()});
    ASSERT_EQ(run.exit_code, 0) << run.err;

    // The monitor reads the folder as `plumb monitor --dir` does.
    MonitorState state;
    DirectoryWatcher watcher(out, state);
    while (watcher.scanOnce() > 0) {
    }
    const json j = state.toJson();
    EXPECT_TRUE(j["errors"].empty()) << j["errors"].dump();

    // Every fragment file of the folder, placed by the pose graph.
    std::vector<fs::path> fragment_files;
    for (const auto& item : fs::directory_iterator(out / "fragments")) {
        int64_t session = 0;
        uint32_t id = 0;
        if (messages::parseFragmentFileName(item.path().filename().string(), session, id)) {
            fragment_files.push_back(item.path());
        }
    }
    ASSERT_GT(fragment_files.size(), 1u);
    ASSERT_EQ(j["fragments"].size(), fragment_files.size());
    for (const json& f : j["fragments"]) EXPECT_EQ(f["pose_source"], "pose_graph") << f["id"];
    ASSERT_FALSE(j["layout"].is_null());
    ASSERT_EQ(j["trajectory_V"].size(), static_cast<size_t>(kFrames));

    // The coverage is of the room the layout closed with walls, not of the seen area.
    const json& c = j["coverage"];
    ASSERT_EQ(c["room_closed"], true) << c.dump();
    EXPECT_EQ(c["region"], "room_polygon");
    ASSERT_TRUE(c["room_fraction"].is_number());
    const double monitor_fraction = c["room_fraction"].get<double>();

    // Ground truth: the simulator's room (scene frame S, floor z = 0) and trajectory in S.
    SourceOptions options;
    options.max_frames = kFrames;
    options.intrinsics = "ci";
    auto source = openFrameSource("sim:living_room", options);
    ASSERT_TRUE(source.isOk()) << source.status().message();
    const auto* sim = dynamic_cast<const sim::SimSource*>(&(*source)->underlying());
    ASSERT_NE(sim, nullptr);
    const std::vector<Eigen::Vector2d>& room_S = sim->scene().polygon;
    const io::Trajectory& gt = sim->trajectory();

    // T_S_W: the reconstruction's frame W onto S by the rigid fit of the camera paths (Horn).
    auto estimated = io::readTumTrajectory(out / "trajectory.txt");
    ASSERT_TRUE(estimated.isOk()) << estimated.status().message();
    ASSERT_EQ(estimated->size(), gt.size());
    Eigen::Matrix3Xd path_W(3, gt.size()), path_S(3, gt.size());
    for (size_t k = 0; k < gt.size(); ++k) {
        path_W.col(static_cast<Eigen::Index>(k)) = (*estimated)[k].T_W_C.translation();
        path_S.col(static_cast<Eigen::Index>(k)) = gt[k].T_W_C.translation();
    }
    const Eigen::Isometry3d T_S_W(Eigen::umeyama(path_W, path_S, false));
    const Eigen::Matrix3Xd fitted_S = T_S_W * path_W;
    const double path_rms_m = std::sqrt((fitted_S - path_S).colwise().squaredNorm().mean());
    ASSERT_LT(path_rms_m, 0.03) << "the reconstruction's path does not fit the simulator's";

    // Every point of every fragment (the monitor keeps a sample) on the true floor plan.
    auto graph_text = messages::readFile(out / "pose_graph.json", int64_t{1} << 28);
    ASSERT_TRUE(graph_text.isOk());
    auto graph = poseGraphFromJson(json::parse(graph_text->begin(), graph_text->end()), "graph");
    ASSERT_TRUE(graph.isOk()) << graph.status().message();
    std::vector<Eigen::Vector2d> points_S;
    for (const fs::path& file : fragment_files) {
        auto bytes = messages::readFile(file, int64_t{1} << 30);
        ASSERT_TRUE(bytes.isOk());
        auto fragment = messages::decodeFragment(*bytes);
        ASSERT_TRUE(fragment.isOk()) << fragment.status().message();
        ASSERT_LT(fragment->id, graph->T_W_F.size());
        const Eigen::Isometry3d T_S_F = T_S_W * graph->T_W_F[fragment->id];
        for (const Eigen::Vector3f& p_F : fragment->points_F.points) {
            points_S.push_back((T_S_F * p_F.cast<double>()).head<2>());
        }
    }
    const double true_fraction = trueCoverage(points_S, room_S);

    // The room the layout estimated is the true one (area within 5 %).
    std::vector<Eigen::Vector2d> polygon_V;
    for (const json& p : j["layout"]["room_polygon_V"]) {
        polygon_V.emplace_back(p[0].get<double>(), p[1].get<double>());
    }
    const double true_area = polygonArea(room_S);
    EXPECT_NEAR(polygonArea(polygon_V), true_area, 0.05 * true_area);

    std::printf("monitor: %.1f %% of the room (%d of %d cells, %d gaps); ground truth: %.1f %%\n",
                100.0 * monitor_fraction, c["covered_cells"].get<int>(),
                c["cells_of_interest"].get<int>(), c["num_gaps"].get<int>(), 100.0 * true_fraction);
    // A partial scan reads as partial, with the gaps listed, and as much as the truth says.
    EXPECT_LT(true_fraction, 0.9);
    EXPECT_NEAR(monitor_fraction, true_fraction, 0.05);
    EXPECT_EQ(c["num_gaps"].get<int64_t>(),
              c["cells_of_interest"].get<int64_t>() - c["covered_cells"].get<int64_t>());
    EXPECT_GT(c["num_gaps"].get<int64_t>(), 0);
    fs::remove_all(work);
}

}  // namespace
}  // namespace plumb::monitor
