// SPDX-License-Identifier: Apache-2.0
// Runs the built `plumb` program (PLUMB_EXE) as a user would: `plumb fuse ...` (issue 4).
// --frame-step must keep exactly source frames floor(j X) (what a live device that keeps up with
// 1/X of the sensor rate fuses), still track them, and refuse bad values with exit code 2.

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

struct ProcessRun {
    int exit_code = -1;
    std::string err;
};

std::string slurp(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// Runs `plumb fuse <args>` with stdout/stderr captured in `log_dir`.
ProcessRun plumbFuse(const fs::path& log_dir, const std::vector<std::string>& args) {
    std::string command = std::string("'") + PLUMB_EXE + "' fuse";
    for (const std::string& a : args) command += " '" + a + "'";
    command += " > '" + (log_dir / "stdout.txt").string() + "' 2> '" +
               (log_dir / "stderr.txt").string() + "'";
    const int status = std::system(command.c_str());
    ProcessRun run;
    run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    run.err = slurp(log_dir / "stderr.txt");
    return run;
}

TEST(PlumbFuseCli, FrameStepFusesFramesFloorOfJTimesStepAndTracksThem) {
    const fs::path logs = testing::freshTempDir("plumb_fuse_cli_logs");
    const fs::path out = testing::freshTempDir("plumb_fuse_cli_step");
    // Small and shared-data-free: CI intrinsics, parametric distortion.
    const ProcessRun run =
        plumbFuse(logs, {"sim:living_room", "--frames", "23", "--frame-step", "2.5", "--intrinsics",
                         "ci", "--noise", "parametric", "--quiet", "--out", out.string()});
    ASSERT_EQ(run.exit_code, 0) << run.err;

    const nlohmann::json summary = nlohmann::json::parse(slurp(out / "fragments.json"));
    EXPECT_EQ(summary.at("frames").get<int>(), 10);  // floor(2.5 j) < 23: j = 0..9
    EXPECT_DOUBLE_EQ(summary.at("frame_step").get<double>(), 2.5);
    EXPECT_EQ(summary.at("frames_tracking_failed").get<int>(), 0);

    const nlohmann::json fragment = nlohmann::json::parse(slurp(out / "fragment_000.json"));
    std::vector<int64_t> indices;
    for (const nlohmann::json& f : fragment.at("frames")) {
        indices.push_back(f.at("frame_index").get<int64_t>());
        EXPECT_TRUE(f.at("tracking_ok").get<bool>());
    }
    EXPECT_EQ(indices, (std::vector<int64_t>{0, 2, 5, 7, 10, 12, 15, 17, 20, 22}));
    // The kept frames are 2.5 sensor frames apart and still track to the ground truth.
    EXPECT_LT(fragment.at("ground_truth").at("ate_rmse_m").get<double>(), 0.01);
}

TEST(PlumbFuseCli, FrameStepBelowOneOrNotANumberIsRefused) {
    const fs::path logs = testing::freshTempDir("plumb_fuse_cli_bad_logs");
    const fs::path out = testing::freshTempDir("plumb_fuse_cli_bad");
    for (const std::string bad : {"0.5", "0", "-2", "nan", "inf", "two"}) {
        const ProcessRun run = plumbFuse(
            logs, {"sim:living_room", "--frames", "5", "--frame-step", bad, "--out", out.string()});
        EXPECT_EQ(run.exit_code, 2) << bad;
        EXPECT_NE(run.err.find("--frame-step needs a number >= 1"), std::string::npos)
            << bad << ": " << run.err;
    }
}

}  // namespace
}  // namespace plumb
