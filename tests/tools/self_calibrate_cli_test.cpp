// SPDX-License-Identifier: Apache-2.0
// Runs the built `plumb` program (PLUMB_EXE) as a user would (issue 28): `plumb reconstruct
// --self-calibrate` learns a depth distortion table from the raw depth of a scan, reconstructs
// with it and reports what it learned; the table it writes undistorts later scans on the device
// (`plumb fuse --depth-calibration`); `plumb calibrate --poses` learns from a reconstruction's
// trajectory and `--reference` measures a learned table against a known one.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "common/calibration/distortion_table.hpp"
#include "tests/testing/run_program.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

using testing::ProcessRun;

ProcessRun plumb(const std::string& command, const fs::path& log_dir,
                 const std::vector<std::string>& args) {
    return testing::runProgram(std::string("'") + PLUMB_EXE + "' " + command, log_dir, args);
}

/// Median over the cells the learned table moved off 1 in `bin` of |learned / scale - true| and
/// of |1 - true|, with the scale the median ratio learned / true there (the gauge is arbitrary).
std::pair<double, double> binError(const DistortionTable& learned, const DistortionTable& truth,
                                   int bin) {
    std::vector<double> ratios;
    for (int y = 0; y < 80; ++y) {
        for (int x = 0; x < 80; ++x) {
            const double l = learned.cell(x, y)[bin], t = truth.cell(x, y)[bin];
            if (l != 1.0 && t != 0.0) ratios.push_back(l / t);
        }
    }
    if (ratios.empty()) return {1.0, 0.0};
    std::sort(ratios.begin(), ratios.end());
    const double scale = ratios[ratios.size() / 2];
    std::vector<double> errors, none;
    for (int y = 0; y < 80; ++y) {
        for (int x = 0; x < 80; ++x) {
            const double l = learned.cell(x, y)[bin], t = truth.cell(x, y)[bin];
            if (l == 1.0 || t == 0.0) continue;
            errors.push_back(std::abs(l / scale - t));
            none.push_back(std::abs(1.0 - t));
        }
    }
    std::sort(errors.begin(), errors.end());
    std::sort(none.begin(), none.end());
    return {errors[errors.size() / 2], none[none.size() / 2]};
}

/// `plumb reconstruct --self-calibrate` of 150 frames of the simulated living room at a quarter
/// of the resolution, three iterations and 100 frames compared per estimate, plus `extra`.
ProcessRun selfCalibrateLivingRoom(const fs::path& logs, const fs::path& out,
                                   const std::vector<std::string>& extra) {
    std::vector<std::string> args = {"sim:living_room",
                                     "--intrinsics",
                                     "ci",
                                     "--frames",
                                     "600",
                                     "--frame-step",
                                     "4",
                                     "--self-calibrate",
                                     "--no-baseline",
                                     "--set",
                                     "self_calibration.estimate.max_iterations=3",
                                     "--set",
                                     "self_calibration.max_frames=100",
                                     "--out",
                                     out.string()};
    args.insert(args.end(), extra.begin(), extra.end());
    return plumb("reconstruct", logs, args);
}

TEST(PlumbReconstructCli, SelfCalibrateLearnsTheTableFromTheRawDepthAndReportsBeforeAndAfter) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const fs::path logs = testing::freshTempDir("plumb_self_calibrate_cli_logs");
    const fs::path out = testing::freshTempDir("plumb_self_calibrate_cli");
    const ProcessRun run = selfCalibrateLivingRoom(logs, out, {"--quiet"});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    std::printf("%s", run.out.c_str());
    EXPECT_NE(run.out.find("self-calibration: table"), std::string::npos) << run.out;

    // The table: closer to the sensor's true table at 3 m than no calibration at all.
    auto learned = DistortionTable::load(out / "depth_calibration.txt");
    ASSERT_TRUE(learned.isOk()) << learned.status().toString();
    auto truth = DistortionTable::load(path);
    ASSERT_TRUE(truth.isOk());
    const auto [error, uncalibrated] = binError(*learned, *truth, 1);
    std::printf("3 m bin: median |learned - true| %.3f %%, uncalibrated %.3f %%\n", 100 * error,
                100 * uncalibrated);
    EXPECT_LT(error, uncalibrated);
    // Issue 28's figure, from the scan itself: within 0.3 % of the truth at 1 m and 3 m.
    EXPECT_LE(error, 0.003);
    const auto [near_error, near_uncalibrated] = binError(*learned, *truth, 0);
    std::printf("1 m bin: median |learned - true| %.3f %%, uncalibrated %.3f %%\n",
                100 * near_error, 100 * near_uncalibrated);
    EXPECT_LE(near_error, 0.003);

    // metrics.json and the report say what was learned and what it changed.
    const nlohmann::json m = nlohmann::json::parse(testing::slurp(out / "metrics.json"));
    ASSERT_TRUE(m.contains("self_calibration")) << m.dump();
    const nlohmann::json& sc = m["self_calibration"];
    EXPECT_EQ(sc.at("table"), "depth_calibration.txt");
    // 150 frames tracked, at most 100 compared: every second one.
    EXPECT_EQ(sc.at("frame_step").get<int>(), 2);
    EXPECT_GT(sc.at("frames").get<int>(), 70);
    EXPECT_LE(sc.at("frames").get<int>(), 75);
    EXPECT_GE(sc.at("iterations").size(), 1U);
    EXPECT_LE(sc.at("iterations").size(), 3U);
    EXPECT_GT(sc.at("covered_cells").at(1).get<int>(), 1000);
    EXPECT_GT(sc.at("before").at("ate_rmse_m").get<double>(), 0.0);
    EXPECT_GT(sc.at("before").at("recon_mean_m").get<double>(), 0.0);
    EXPECT_TRUE(fs::exists(out / "self_calibration" / "first" / "metrics.json"));
    EXPECT_TRUE(fs::exists(out / "self_calibration" / "first" / "trajectory.txt"));
    // The first reconstruction used the bend learned from the frames' planes.
    EXPECT_EQ(sc.at("first_table"), "self_calibration/planar_table.txt");
    // The alternation started from the planar table, not from the neutral one.
    EXPECT_TRUE(sc.at("warm_start").get<bool>());
    EXPECT_TRUE(DistortionTable::load(out / "self_calibration" / "planar_table.txt").isOk());
    EXPECT_GE(sc.at("planar").at("iterations").size(), 1U);
    EXPECT_EQ(sc.at("planar").at("frames").get<int>(), 600);
    EXPECT_LE(sc.at("planar").at("split_disagreement").get<double>(), 0.005);
    // The simulated sensor has no depth in a border of the image: the scale growing with depth
    // is set to 0 over the cells where it has, and both planar stages say what they removed.
    for (const char* stage : {"planar", "final_planar"}) {
        const nlohmann::json& p = sc.at(stage);
        EXPECT_GT(p.at("cells_with_data").get<int>(), 5000) << stage;
        EXPECT_LT(p.at("cells_with_data").get<int>(), 6400) << stage;
        EXPECT_LT(std::abs(p.at("removed_depth_scale_per_m").get<double>()), 0.002) << stage;
    }
    const std::string report = testing::slurp(out / "report.html");
    EXPECT_NE(report.find("Depth self-calibration"), std::string::npos);
    EXPECT_NE(report.find("set to 0 over the " +
                          std::to_string(sc.at("planar").at("cells_with_data").get<int>()) +
                          " cells where the sensor has depth"),
              std::string::npos);

    // The learned table undistorts a later scan on the device pipeline as a measured one does.
    const fs::path fused = testing::freshTempDir("plumb_self_calibrate_cli_fuse");
    const ProcessRun fuse =
        plumb("fuse", logs,
              {"sim:living_room", "--intrinsics", "ci", "--frames", "30", "--depth-calibration",
               (out / "depth_calibration.txt").string(), "--out", fused.string(), "--quiet"});
    ASSERT_EQ(fuse.exit_code, 0) << fuse.err;
    EXPECT_TRUE(fs::exists(fused / "fragment_000.ply"));
}

TEST(PlumbReconstructCli, ASecondRoundRefinesTheTableAtThePosesOfAReconstructionWithTheFirst) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const fs::path logs = testing::freshTempDir("plumb_self_calibrate_rounds_logs");
    const fs::path out = testing::freshTempDir("plumb_self_calibrate_rounds");
    const ProcessRun run =
        selfCalibrateLivingRoom(logs, out, {"--set", "self_calibration.rounds=2"});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    std::printf("%s", run.out.c_str());
    EXPECT_NE(run.err.find("reading the scan once for its 8 passes"), std::string::npos) << run.err;
    EXPECT_NE(run.err.find("reconstructing with round 1's table into"), std::string::npos)
        << run.err;
    EXPECT_NE(run.err.find("starting from round 1's table"), std::string::npos) << run.err;
    EXPECT_NE(run.out.find("round 2 reconstructed with round 1's table"), std::string::npos)
        << run.out;

    const nlohmann::json m = nlohmann::json::parse(testing::slurp(out / "metrics.json"));
    const nlohmann::json& sc = m.at("self_calibration");
    EXPECT_EQ(sc.at("rounds").get<int>(), 2);
    const nlohmann::json& rounds = sc.at("round_results");
    ASSERT_EQ(rounds.size(), 2U) << sc.dump();
    EXPECT_EQ(rounds[0].at("reconstruction"), "self_calibration/first");
    EXPECT_EQ(rounds[0].at("table"), "self_calibration/round1_table.txt");
    EXPECT_EQ(rounds[1].at("reconstruction"), "self_calibration/round2");
    EXPECT_EQ(rounds[1].at("refined_table"), "self_calibration/round2_refined_table.txt");
    EXPECT_EQ(rounds[1].at("table"), "depth_calibration.txt");
    EXPECT_EQ(sc.at("refined_table"), "self_calibration/round2_refined_table.txt");
    for (const nlohmann::json& r : rounds) {
        EXPECT_TRUE(fs::exists(out / r.at("reconstruction").get<std::string>() / "trajectory.txt"));
        EXPECT_TRUE(DistortionTable::load(out / r.at("table").get<std::string>()).isOk());
        EXPECT_GE(r.at("iterations").get<int>(), 1);
        EXPECT_GT(r.at("seconds").get<double>(), 0.0);
    }
    // The second round's reconstruction, made with the first round's table, is far better than
    // the first, made with the bend from the planes alone: its poses are what round 2 refines at.
    const double first_ate = rounds[0].at("reconstruction_figures").at("ate_rmse_m");
    const double second_ate = rounds[1].at("reconstruction_figures").at("ate_rmse_m");
    std::printf("reconstruction ATE: with the planar table %.2f cm, with round 1's table %.2f cm\n",
                100 * first_ate, 100 * second_ate);
    EXPECT_LT(second_ate, 0.6 * first_ate);
    // The table of the last round is the result and meets issue 28's figure.
    auto learned = DistortionTable::load(out / "depth_calibration.txt");
    ASSERT_TRUE(learned.isOk()) << learned.status().toString();
    auto first_round = DistortionTable::load(out / "self_calibration" / "round1_table.txt");
    ASSERT_TRUE(first_round.isOk());
    auto truth = DistortionTable::load(path);
    ASSERT_TRUE(truth.isOk());
    for (int bin : {0, 1}) {
        const double error = binError(*learned, *truth, bin).first;
        const double round1 = binError(*first_round, *truth, bin).first;
        std::printf("%d m bin: median |learned - true| %.3f %% after round 2, %.3f %% after 1\n",
                    2 * bin + 1, 100 * error, 100 * round1);
        EXPECT_LE(error, 0.003) << bin;
    }
    EXPECT_NE(testing::slurp(out / "report.html").find("in 2 rounds"), std::string::npos);
}

TEST(PlumbReconstructCli, SelfCalibrateReadsTheScanOnceAndLearnsWhatReadingItAgainLearns) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const fs::path logs = testing::freshTempDir("plumb_self_calibrate_once_logs");
    auto run = [&](const std::string& name, const std::string& keep_frames_mb) {
        const fs::path out = testing::freshTempDir(name);
        const ProcessRun r = plumb("reconstruct", logs,
                                   {"sim:living_room", "--intrinsics", "ci", "--frames", "600",
                                    "--frame-step", "4", "--self-calibrate", "--no-baseline",
                                    "--set", "self_calibration.estimate.max_iterations=1", "--set",
                                    "self_calibration.max_frames=50", "--set",
                                    "keep_frames_mb=" + keep_frames_mb, "--out", out.string()});
        EXPECT_EQ(r.exit_code, 0) << r.err;
        return std::make_pair(r, out);
    };
    const auto [kept, kept_out] = run("plumb_self_calibrate_once_kept", "4096");
    const auto [read, read_out] = run("plumb_self_calibrate_once_read", "0");
    EXPECT_NE(kept.err.find("raw frames are kept for every pass"), std::string::npos) << kept.err;
    EXPECT_NE(kept.err.find("starting from the planar table"), std::string::npos) << kept.err;
    EXPECT_NE(read.err.find("every pass reads the scan again"), std::string::npos) << read.err;
    // The passes saw the same frames: the same planar, refined and final tables, trajectory.
    for (const char* file :
         {"self_calibration/planar_table.txt", "self_calibration/refined_table.txt",
          "depth_calibration.txt", "trajectory.txt"}) {
        const std::string a = testing::slurp(kept_out / file);
        EXPECT_FALSE(a.empty()) << file;
        EXPECT_EQ(a, testing::slurp(read_out / file)) << file;
    }
}

TEST(PlumbReconstructCli, ScanWhosePlanesDoNotDetermineTheBendIsReconstructedFromTheRawDepth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const fs::path logs = testing::freshTempDir("plumb_self_calibrate_cli_short_logs");
    const fs::path out = testing::freshTempDir("plumb_self_calibrate_cli_short");
    const ProcessRun run =
        plumb("reconstruct", logs,
              {"sim:living_room", "--intrinsics", "ci", "--frames", "30", "--self-calibrate",
               "--no-baseline", "--set", "self_calibration.estimate.max_iterations=1", "--out",
               out.string()});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_NE(run.err.find("no table is learned, the reconstruction uses the raw depth"),
              std::string::npos)
        << run.err;
    EXPECT_NE(run.out.find("self-calibration: no table learned"), std::string::npos) << run.out;
    const nlohmann::json m = nlohmann::json::parse(testing::slurp(out / "metrics.json"));
    const nlohmann::json& sc = m.at("self_calibration");
    EXPECT_EQ(sc.at("status"), "not_determined");
    EXPECT_NE(sc.at("reason").get<std::string>().find("planar distortion"), std::string::npos);
    EXPECT_TRUE(sc.at("table").is_null());
    EXPECT_FALSE(fs::exists(out / "self_calibration" / "planar_table.txt"));
    EXPECT_FALSE(fs::exists(out / "self_calibration" / "first"));
    EXPECT_FALSE(fs::exists(out / "depth_calibration.txt"));
    // The reconstruction is that of the raw depth: the trajectory of a plain run.
    const fs::path plain = testing::freshTempDir("plumb_self_calibrate_cli_short_plain");
    const ProcessRun raw =
        plumb("reconstruct", logs,
              {"sim:living_room", "--intrinsics", "ci", "--frames", "30", "--no-baseline",
               "--depth-calibration", "none", "--out", plain.string()});
    ASSERT_EQ(raw.exit_code, 0) << raw.err;
    EXPECT_EQ(testing::slurp(out / "trajectory.txt"), testing::slurp(plain / "trajectory.txt"));
    EXPECT_NE(testing::slurp(out / "report.html").find("No table was learned"), std::string::npos);
}

TEST(PlumbReconstructCli, SelfCalibrateExcludesAGivenDepthCalibration) {
    const fs::path out = testing::freshTempDir("plumb_self_calibrate_cli_bad");
    const ProcessRun run = plumb("reconstruct", out,
                                 {"sim:living_room", "--self-calibrate", "--depth-calibration",
                                  "none", "--out", out.string()});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("--self-calibrate learns the depth calibration"), std::string::npos)
        << run.err;
}

TEST(PlumbCalibrateCli, LearnsFromAReconstructionsTrajectoryAndComparesWithAReference) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const fs::path dir = testing::freshTempDir("plumb_calibrate_cli_poses");
    const std::vector<std::string> scan = {"sim:living_room", "--intrinsics", "ci", "--frames",
                                           "60"};
    std::vector<std::string> args = scan;
    for (const char* a : {"--no-baseline", "--no-gt", "--quiet", "--out"}) args.push_back(a);
    args.push_back((dir / "raw").string());
    args.push_back("--depth-calibration");
    args.push_back("none");
    const ProcessRun reconstruct = plumb("reconstruct", dir, args);
    ASSERT_EQ(reconstruct.exit_code, 0) << reconstruct.err;

    for (const char* trajectory : {"trajectory.txt", "trajectory.log"}) {
        args = scan;
        for (const std::string& a :
             {std::string("--iterations"), std::string("2"), std::string("--poses"),
              (dir / "raw" / trajectory).string(), std::string("--reference"), path.string(),
              std::string("--out"), (dir / "table.txt").string()}) {
            args.push_back(a);
        }
        const bool refine = std::string(trajectory) == "trajectory.log";
        if (refine) args.push_back("--refine-poses");
        const ProcessRun run = plumb("calibrate", dir, args);
        ASSERT_EQ(run.exit_code, 0) << trajectory << ": " << run.err;
        EXPECT_EQ(
            run.out.find("poses refined against every iteration's model") != std::string::npos,
            refine)
            << run.out;
        std::printf("%s", run.out.c_str());
        // Every frame of the scan was tracked, and each found its pose in the trajectory.
        EXPECT_NE(run.out.find("calibrating from 60 frames"), std::string::npos) << run.out;
        EXPECT_NE(run.out.find("poses from " + (dir / "raw" / trajectory).string()),
                  std::string::npos);
        EXPECT_NE(run.out.find("median |learned - reference| 1 m"), std::string::npos);
        EXPECT_NE(run.out.find("3 m: "), std::string::npos) << run.out;
        EXPECT_TRUE(DistortionTable::load(dir / "table.txt").isOk());
    }

    args = scan;
    for (const std::string& a : {std::string("--poses"), (dir / "missing.txt").string(),
                                 std::string("--out"), (dir / "t.txt").string()}) {
        args.push_back(a);
    }
    const ProcessRun missing = plumb("calibrate", dir, args);
    EXPECT_EQ(missing.exit_code, 1);
    EXPECT_NE(missing.err.find("missing.txt"), std::string::npos) << missing.err;
}

}  // namespace
}  // namespace plumb
