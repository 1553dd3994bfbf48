// SPDX-License-Identifier: Apache-2.0
// Runs the built `plumb` program (PLUMB_EXE) as a user would: `plumb eval traj ...`.

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "common/geometry/lie.hpp"
#include "common/io/trajectory.hpp"
#include "tests/testing/run_program.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

using testing::ProcessRun;
using testing::slurp;

/// Runs `plumb eval traj <args>` with stdout/stderr captured in `dir`.
ProcessRun evalTraj(const fs::path& dir, const std::vector<std::string>& args) {
    return testing::runProgram(std::string("'") + PLUMB_EXE + "' eval traj", dir, args);
}

/// A random-walk ground truth at 30 Hz.
io::Trajectory groundTruth(size_t count) {
    std::mt19937_64 rng(21);
    std::normal_distribution<double> n(0.0, 1.0);
    io::Trajectory trajectory;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    for (size_t k = 0; k < count; ++k) {
        Vector6d xi;
        xi << 0.01 * n(rng), 0.01 * n(rng), 0.01 * n(rng), 0.02 * n(rng), 0.02 * n(rng),
            0.02 * n(rng);
        T = T * lie::expSE3(xi);
        trajectory.push_back({1341836537.0 + static_cast<double>(k) / 30.0, T});
    }
    return trajectory;
}

Eigen::Isometry3d otherWorld() {
    Vector6d xi;
    xi << 0.3, -0.2, 1.1, 2.0, -1.0, 0.5;
    return lie::expSE3(xi);
}

class EvalTraj : public ::testing::Test {
  protected:
    void SetUp() override {
        dir_ =
            testing::freshTempDir(::testing::UnitTest::GetInstance()->current_test_info()->name());
        gt_ = groundTruth(5000);
        ASSERT_TRUE(io::writeTumTrajectory(dir_ / "gt.txt", gt_).isOk());
    }
    fs::path dir_;
    io::Trajectory gt_;
};

TEST_F(EvalTraj, SelfAgainstSelfIsZero) {
    const ProcessRun run =
        evalTraj(dir_, {(dir_ / "gt.txt").string(), (dir_ / "gt.txt").string(), "--json"});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    const nlohmann::json j = nlohmann::json::parse(run.out);
    EXPECT_EQ(j["num_pairs"].get<int>(), 5000);
    EXPECT_LT(j["ate"]["rmse_m"].get<double>(), 1e-9);
    EXPECT_LT(j["rpe"]["trans_rmse_m"].get<double>(), 1e-9);
    EXPECT_LT(j["rpe"]["rot_rmse_rad"].get<double>(), 1e-6);
}

TEST_F(EvalTraj, NoisyEstimateInAnotherFrameGivesSqrt3Centimetres) {
    // 1 cm Gaussian noise per axis on the positions, expressed in another world frame.
    std::mt19937_64 rng(22);
    std::normal_distribution<double> noise(0.0, 0.01);
    io::Trajectory est = gt_;
    for (io::StampedPose& p : est) {
        p.T_W_C.translation() += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
        p.T_W_C = otherWorld() * p.T_W_C;
    }
    ASSERT_TRUE(io::writeTumTrajectory(dir_ / "est.txt", est).isOk());

    const ProcessRun json_run =
        evalTraj(dir_, {(dir_ / "est.txt").string(), (dir_ / "gt.txt").string(), "--json"});
    ASSERT_EQ(json_run.exit_code, 0) << json_run.err;
    const nlohmann::json j = nlohmann::json::parse(json_run.out);
    const double rmse_m = j["ate"]["rmse_m"].get<double>();
    EXPECT_NEAR(rmse_m, std::sqrt(3.0) * 0.01, 0.05 * std::sqrt(3.0) * 0.01);
    EXPECT_TRUE(j["ate"]["aligned"].get<bool>());
    EXPECT_EQ(j["estimate"]["format"], "tum");
    EXPECT_EQ(j["rpe"]["num_pairs"].get<int>(), 4999);
    // The reported alignment maps the estimate's world back onto the ground truth's.
    Eigen::Matrix4d T;
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) T(r, c) = j["ate"]["T_gt_est"][r][c].get<double>();
    }
    EXPECT_LT((T - otherWorld().inverse().matrix()).cwiseAbs().maxCoeff(), 2e-3);

    // Text output reports the same numbers in centimetres.
    const ProcessRun text_run =
        evalTraj(dir_, {(dir_ / "est.txt").string(), (dir_ / "gt.txt").string()});
    ASSERT_EQ(text_run.exit_code, 0) << text_run.err;
    char expected[64];
    std::snprintf(expected, sizeof(expected), "rmse %.3f cm", rmse_m * 100.0);
    EXPECT_NE(text_run.out.find(expected), std::string::npos) << text_run.out;
    EXPECT_NE(text_run.out.find("pairs:         5000"), std::string::npos) << text_run.out;

    // Without alignment the error is dominated by the change of world frame.
    const ProcessRun raw = evalTraj(
        dir_, {(dir_ / "est.txt").string(), (dir_ / "gt.txt").string(), "--no-align", "--json"});
    ASSERT_EQ(raw.exit_code, 0) << raw.err;
    EXPECT_GT(nlohmann::json::parse(raw.out)["ate"]["rmse_m"].get<double>(), 1.0);
}

TEST_F(EvalTraj, LogFilesOffsetsAndDeltas) {
    // The same poses as a .log (stamps = frame indices) against a TUM ground truth re-stamped
    // with frame indices plus 10000 s: --offset 10000 associates them exactly.
    ASSERT_TRUE(io::writeLogTrajectory(dir_ / "est.log", gt_).isOk());
    io::Trajectory shifted = gt_;
    for (size_t k = 0; k < shifted.size(); ++k)
        shifted[k].timestamp_s = 10000.0 + static_cast<double>(k);
    ASSERT_TRUE(io::writeTumTrajectory(dir_ / "shifted.txt", shifted).isOk());

    const ProcessRun none =
        evalTraj(dir_, {(dir_ / "est.log").string(), (dir_ / "shifted.txt").string()});
    EXPECT_EQ(none.exit_code, 1);
    EXPECT_NE(none.err.find("no estimated pose is within 0.02 s"), std::string::npos) << none.err;

    const ProcessRun run =
        evalTraj(dir_, {(dir_ / "est.log").string(), (dir_ / "shifted.txt").string(), "--offset",
                        "10000", "--delta=10", "--json"});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    const nlohmann::json j = nlohmann::json::parse(run.out);
    EXPECT_EQ(j["estimate"]["format"], "log");
    EXPECT_EQ(j["num_pairs"].get<int>(), 5000);
    EXPECT_LT(j["ate"]["rmse_m"].get<double>(), 1e-9);
    EXPECT_EQ(j["rpe"]["num_pairs"].get<int>(), 4990);
    EXPECT_EQ(j["rpe"]["delta_unit"], "frames");

    // --format overrides the extension.
    const ProcessRun forced = evalTraj(
        dir_, {(dir_ / "est.log").string(), (dir_ / "shifted.txt").string(), "--format", "tum"});
    EXPECT_EQ(forced.exit_code, 1);
    EXPECT_NE(forced.err.find("est.log:1: expected 8 columns"), std::string::npos) << forced.err;

    // A time delta of 1 s on 30 Hz stamps.
    const ProcessRun by_time = evalTraj(
        dir_, {(dir_ / "gt.txt").string(), (dir_ / "gt.txt").string(), "--delta-s", "1", "--json"});
    ASSERT_EQ(by_time.exit_code, 0) << by_time.err;
    const nlohmann::json t = nlohmann::json::parse(by_time.out);
    EXPECT_EQ(t["rpe"]["delta_unit"], "s");
    EXPECT_EQ(t["rpe"]["num_pairs"].get<int>(), 4970);
}

TEST_F(EvalTraj, BadDataExitsOneWithTheFileName) {
    const fs::path missing = dir_ / "does_not_exist.txt";
    const ProcessRun run = evalTraj(dir_, {missing.string(), (dir_ / "gt.txt").string()});
    EXPECT_EQ(run.exit_code, 1);
    EXPECT_NE(run.err.find("does_not_exist.txt"), std::string::npos) << run.err;
    EXPECT_TRUE(run.out.empty());

    std::ofstream(dir_ / "nan.txt") << "0 0 0 0 0 0 0 1\n1 nan 0 0 0 0 0 1\n";
    const ProcessRun nan =
        evalTraj(dir_, {(dir_ / "nan.txt").string(), (dir_ / "gt.txt").string()});
    EXPECT_EQ(nan.exit_code, 1);
    EXPECT_NE(nan.err.find("nan.txt:2: column 2 is not finite"), std::string::npos) << nan.err;
}

TEST_F(EvalTraj, UsageErrorsExitTwoAndHelpDocumentsEveryOption) {
    const std::string gt = (dir_ / "gt.txt").string();
    for (const std::vector<std::string>& args :
         std::vector<std::vector<std::string>>{{gt, gt, "--bogus"},
                                               {gt},
                                               {gt, gt, gt},
                                               {gt, gt, "--max-diff", "abc"},
                                               {gt, gt, "--max-diff"},
                                               {gt, gt, "--delta", "1.5"},
                                               {gt, gt, "--delta", "0"},
                                               {gt, gt, "--format", "csv"},
                                               {gt, gt, "--json=yes"}}) {
        const ProcessRun run = evalTraj(dir_, args);
        EXPECT_EQ(run.exit_code, 2) << args.back();
        EXPECT_NE(run.err.find("plumb eval traj:"), std::string::npos) << run.err;
    }
    EXPECT_NE(evalTraj(dir_, {gt, gt, "--bogus"}).err.find("'--bogus'"), std::string::npos);

    const ProcessRun help = evalTraj(dir_, {"--help"});
    EXPECT_EQ(help.exit_code, 0);
    for (const char* option : {"--max-diff", "--offset", "--no-align", "--delta", "--delta-s",
                               "--format", "--json", "--help"}) {
        EXPECT_NE(help.out.find(option), std::string::npos) << option;
    }
}

}  // namespace
}  // namespace plumb
