// SPDX-License-Identifier: Apache-2.0
// Runs the built `plumb` program (PLUMB_EXE) as a user would: `plumb fuse ...` (issue 4).
// --frame-step must keep exactly source frames floor(j X) (what a live device that keeps up with
// 1/X of the sensor rate fuses), still track them, and refuse bad values with exit code 2; frames
// tracked with translations the depth leaves free are counted per frame and per fragment.

#include <gtest/gtest.h>
#include <algorithm>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/testing/run_program.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

using testing::ProcessRun;
using testing::slurp;

/// Runs `plumb fuse <args>` with stdout/stderr captured in `log_dir`.
ProcessRun plumbFuse(const fs::path& log_dir, const std::vector<std::string>& args) {
    return testing::runProgram(std::string("'") + PLUMB_EXE + "' fuse", log_dir, args);
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
    EXPECT_EQ(summary.at("frames_read").get<int>(), 23);
    EXPECT_DOUBLE_EQ(summary.at("processed_fraction").get<double>(), 10.0 / 23.0);
    // The simulator's 30 Hz, from the timestamps of frames 0 and 22; what a live device as fast
    // as this run keeps of them follows from the measured time a frame (by the mean), and from
    // each frame's time through the device's capture queue.
    const nlohmann::json& live = summary.at("live");
    EXPECT_NEAR(live.at("sensor_hz").get<double>(), 30.0, 1e-6);
    const double period_ms = 1e3 / 30.0;
    EXPECT_NEAR(live.at("keeps_fraction_by_mean").get<double>(),
                std::min(1.0, period_ms / summary.at("ms_per_frame").get<double>()), 1e-9);
    EXPECT_EQ(live.at("queue_frames").get<int>(), 4);
    const double keeps = live.at("keeps_fraction").get<double>();
    const int longest_drop_run = live.at("longest_drop_run").get<int>();
    EXPECT_GT(keeps, 0.0);
    EXPECT_LE(keeps, 1.0);
    EXPECT_EQ(keeps == 1.0, longest_drop_run == 0) << keeps << " kept, " << longest_drop_run;
    // Every kept frame ends at least its own time after it arrived.
    EXPECT_GE(live.at("max_latency_ms").get<double>(), 0.0);

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

/// Runs plumb fuse on the first 100 frames of the l_shape scan at 160x120 (with `extra` options)
/// and returns the frames marked with free translations per fragment, checking that the per-frame,
/// per-fragment and summary counts agree; `summary` receives fragments.json.
std::vector<int> unconstrainedPerFragment(const std::string& name,
                                          const std::vector<std::string>& extra,
                                          nlohmann::json* summary) {
    const fs::path logs = testing::freshTempDir(name + "_logs");
    const fs::path out = testing::freshTempDir(name);
    std::vector<std::string> args = {"sim:l_shape", "--frames",  "100",        "--intrinsics",
                                     "ci",          "--noise",   "parametric", "--quiet",
                                     "--out",       out.string()};
    args.insert(args.end(), extra.begin(), extra.end());
    const ProcessRun run = plumbFuse(logs, args);
    EXPECT_EQ(run.exit_code, 0) << run.err;
    if (run.exit_code != 0) return {};
    *summary = nlohmann::json::parse(slurp(out / "fragments.json"));
    EXPECT_EQ(summary->at("fragments").size(), 2u);
    std::vector<int> per_fragment;
    int total = 0;
    for (int id = 0; id < 2; ++id) {
        const nlohmann::json fragment =
            nlohmann::json::parse(slurp(out / ("fragment_00" + std::to_string(id) + ".json")));
        int marked = 0;
        for (const nlohmann::json& f : fragment.at("frames")) {
            const int n = f.at("unconstrained_translations").get<int>();
            EXPECT_GE(n, 0);
            EXPECT_LE(n, 2);  // more than 2 free translations is a tracking failure
            marked += n > 0 ? 1 : 0;
        }
        EXPECT_EQ(fragment.at("frames_unconstrained").get<int>(), marked);
        EXPECT_EQ(summary->at("fragments").at(static_cast<size_t>(id)).at("frames_unconstrained"),
                  marked);
        per_fragment.push_back(marked);
        total += marked;
    }
    EXPECT_EQ(summary->at("frames_unconstrained").get<int>(), total);
    return per_fragment;
}

TEST(PlumbFuseCli, FramesWithTranslationsTheDepthLeavesFreeAreCounted) {
    // l_shape: the first 50 frames see geometry that fixes every translation; in the next 50 the
    // camera walks down the corridor of the L with the far wall out of range, and the walls, floor
    // and ceiling in view all run along the walk. Tracked by depth alone, those frames must be
    // marked, per frame and per fragment, and the counts must agree. With colour the textured
    // walls pin the walk: the photometric term tracks the frames and leaves (almost) none free.
    nlohmann::json depth_summary, colour_summary;
    const std::vector<int> depth =
        unconstrainedPerFragment("plumb_fuse_cli_free", {"--no-colour"}, &depth_summary);
    ASSERT_EQ(depth.size(), 2u);
    EXPECT_EQ(depth[0], 0) << "the first fragment's views fix every translation";
    EXPECT_GE(depth[1], 8) << "the corridor leaves the walk free";
    EXPECT_EQ(depth_summary.at("frames_photometric").get<int>(), 0);
    const std::vector<int> colour =
        unconstrainedPerFragment("plumb_fuse_cli_free_rgbd", {}, &colour_summary);
    ASSERT_EQ(colour.size(), 2u);
    EXPECT_EQ(colour[0], 0);
    EXPECT_LE(colour[1], depth[1] / 4) << "colour observes the walk";
    EXPECT_GE(colour_summary.at("frames_photometric").get<int>(), 95);
    EXPECT_EQ(colour_summary.at("frames_depth_only").get<int>(), 0);
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
