// SPDX-License-Identifier: Apache-2.0
// Runs the built `plumb` program (PLUMB_EXE) as a user would: `plumb sim ...` (issue 3). The same
// seed must give byte-identical folders, the folder must read back through drivers/dataset with
// its ground truth, and bad input must get a specific error and the documented exit code.

#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include "drivers/dataset/dataset.hpp"
#include "drivers/sim/sim_source.hpp"
#include "tests/testing/run_program.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

using testing::ProcessRun;
using testing::slurp;

/// Runs `plumb sim <args>` with stdout/stderr captured in `log_dir`.
ProcessRun plumbSim(const fs::path& log_dir, const std::vector<std::string>& args) {
    return testing::runProgram(std::string("'") + PLUMB_EXE + "' sim", log_dir, args);
}

// Small, shared-data-free settings: CI intrinsics, parametric distortion.
std::vector<std::string> smallArgs(const std::string& scene, const fs::path& out,
                                   const std::string& seed) {
    return {scene,     "--frames",   "10",           "--intrinsics", "ci",
            "--noise", "parametric", "--gt-spacing", "0.1",          "--seed",
            seed,      "--out",      out.string()};
}

TEST(PlumbSimCli, SameSeedGivesByteIdenticalFolders) {
    const fs::path logs = testing::freshTempDir("plumb_sim_cli_logs");
    const fs::path a = testing::freshTempDir("plumb_sim_cli_a");
    const fs::path b = testing::freshTempDir("plumb_sim_cli_b");
    const fs::path c = testing::freshTempDir("plumb_sim_cli_c");
    for (const auto& [dir, seed] : {std::pair{a, "4"}, std::pair{b, "4"}, std::pair{c, "5"}}) {
        const ProcessRun run = plumbSim(logs, smallArgs("weak_manhattan", dir, seed));
        ASSERT_EQ(run.exit_code, 0) << run.err;
    }
    size_t files = 0, differ_c = 0;
    for (const auto& entry : fs::recursive_directory_iterator(a)) {
        if (!entry.is_regular_file()) continue;
        const fs::path rel = fs::relative(entry.path(), a);
        ASSERT_TRUE(fs::exists(b / rel)) << rel;
        EXPECT_EQ(slurp(entry.path()), slurp(b / rel)) << rel << " differs for the same seed";
        differ_c += slurp(entry.path()) != slurp(c / rel);
        ++files;
    }
    // 10 x (depth, depth_clean, gray, rgb) + depth.txt, rgb.txt, groundtruth.txt,
    // trajectory.log, intrinsics.json, gt_points.ply, layout.json, sim.json.
    EXPECT_EQ(files, 10U * 4 + 8);
    // Another seed: other noise and hand shake, so nearly every file changes.
    EXPECT_GT(differ_c, 10U * 4);
}

TEST(PlumbSimCli, NoLoopTomlSceneReloadsWithGroundTruth) {
    const fs::path logs = testing::freshTempDir("plumb_sim_cli_toml_logs");
    const fs::path out = testing::freshTempDir("plumb_sim_cli_toml");
    const fs::path scene = logs / "office.toml";
    std::ofstream(scene) << "name = \"office\"\nheight_m = 2.7\n"
                            "polygon = [[0, 0], [6, 0], [6, 4], [3, 4], [3, 6.5], [0, 6.5]]\n"
                            "[[box]]\ncenter = [5.0, 1.0, 0.4]\nsize = [1.0, 0.6, 0.8]\n"
                            "yaw_deg = 20\n"
                            "[[cylinder]]\ncenter = [0.5, 5.8]\nradius_m = 0.25\nz_max_m = 1.0\n"
                            "[[opening]]\nwall = 1\noffset_m = 1.5\nwidth_m = 0.9\nz_max_m = 2.0\n";
    std::vector<std::string> args = smallArgs(scene.string(), out, "2");
    args.push_back("--no-loop");
    const ProcessRun run = plumbSim(logs, args);
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_NE(run.out.find("office"), std::string::npos) << run.out;
    EXPECT_NE(run.out.find("no-loop"), std::string::npos) << run.out;

    auto info = dataset::scanDataset(out);
    ASSERT_TRUE(info.isOk()) << info.status().toString();
    EXPECT_EQ(info->layout, dataset::Layout::kPlumb);
    ASSERT_EQ(info->frames.size(), 10U);
    EXPECT_EQ(info->framesWithGroundTruth(), 10U);
    // The reloaded frames are the frames the simulator makes for the same settings.
    sim::SimConfig config;
    config.scene = scene.string();
    config.camera = *cameraPreset("ci");
    config.trajectory.num_frames = 10;
    config.trajectory.loop = false;
    config.trajectory.seed = 2;
    config.noise.distortion = sim::DistortionKind::kParametric;
    config.seed = 2;
    auto source = sim::SimSource::create(config);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    for (size_t k = 0; k < 10; k += 3) {
        auto loaded = dataset::loadFrame(*info, k);
        auto expected = (*source)->render(k);
        ASSERT_TRUE(loaded.isOk() && expected.isOk());
        ASSERT_TRUE(loaded->T_W_C_gt.has_value());
        EXPECT_LT((loaded->T_W_C_gt->matrix() - expected->frame.T_W_C_gt->matrix()).norm(), 1e-9);
        size_t mismatched = 0;
        for (size_t i = 0; i < loaded->depth.size(); ++i) {
            const float z = loaded->depth.data()[i], e = expected->frame.depth.data()[i];
            mismatched += (z > 0.0F) != (e > 0.0F) || std::abs(z - e) > 0.0005F + 1e-6F;
        }
        EXPECT_EQ(mismatched, 0U) << "frame " << k;
    }
    // The GT layout has the six walls of the L-shaped polygon.
    EXPECT_NE(slurp(out / "layout.json").find("\"ceiling_height_m\": 2.7"), std::string::npos);
}

TEST(PlumbSimCli, ColourOptions) {
    const fs::path logs = testing::freshTempDir("plumb_sim_cli_colour_logs");
    const fs::path textured = testing::freshTempDir("plumb_sim_cli_textured");
    const fs::path plain = testing::freshTempDir("plumb_sim_cli_plain");
    const fs::path none = testing::freshTempDir("plumb_sim_cli_no_rgb");
    ProcessRun run = plumbSim(logs, smallArgs("living_room", textured, "3"));
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_NE(run.out.find("colour textured"), std::string::npos) << run.out;
    std::vector<std::string> args = smallArgs("living_room", plain, "3");
    for (const char* a : {"--texture", "plain", "--rgb-noise", "0", "--exposure-jump", "4:0.5",
                          "--exposure-std", "0.1", "--exposure-period", "30"}) {
        args.push_back(a);
    }
    run = plumbSim(logs, args);
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_NE(run.out.find("colour plain"), std::string::npos) << run.out;
    // The depth does not depend on the colour settings; the colour and sim.json do.
    EXPECT_EQ(slurp(textured / "depth/00005.png"), slurp(plain / "depth/00005.png"));
    EXPECT_NE(slurp(textured / "rgb/00005.png"), slurp(plain / "rgb/00005.png"));
    const std::string meta = slurp(plain / "sim.json");
    for (const char* key :
         {"\"texture\": \"plain\"", "\"noise_std_levels\": 0.0", "\"exposure_log_std\": 0.1",
          "\"exposure_period_frames\": 30.0", "\"frame\": 4", "\"factor\": 0.5"}) {
        EXPECT_NE(meta.find(key), std::string::npos) << key << " not in\n" << meta;
    }
    args = smallArgs("living_room", none, "3");
    args.push_back("--no-rgb");
    run = plumbSim(logs, args);
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_NE(run.out.find("colour off"), std::string::npos) << run.out;
    EXPECT_FALSE(fs::exists(none / "rgb"));
    EXPECT_FALSE(fs::exists(none / "rgb.txt"));
    EXPECT_EQ(slurp(textured / "depth/00005.png"), slurp(none / "depth/00005.png"));
    // Every colour option is in --help.
    run = plumbSim(logs, {"--help"});
    EXPECT_EQ(run.exit_code, 0);
    for (const char* option : {"--texture", "--rgb-noise", "--exposure-std", "--exposure-period",
                               "--exposure-jump", "--no-rgb", "rgb.txt"}) {
        EXPECT_NE(run.out.find(option), std::string::npos) << option;
    }
}

TEST(PlumbSimCli, BadInputGetsSpecificErrors) {
    const fs::path logs = testing::freshTempDir("plumb_sim_cli_bad");
    ProcessRun run = plumbSim(logs, {"no_such_room", "--out", (logs / "x").string()});
    EXPECT_EQ(run.exit_code, 2);  // a scene that does not exist is a bad command line
    EXPECT_NE(run.err.find("living_room"), std::string::npos) << run.err;
    run = plumbSim(logs, {"living_room", "--frames", "0", "--out", (logs / "x").string()});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("--frames"), std::string::npos) << run.err;
    run = plumbSim(logs, {"living_room", "--noise", "loud", "--out", (logs / "x").string()});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("loud"), std::string::npos) << run.err;
    run = plumbSim(logs, {"living_room"});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("--out"), std::string::npos) << run.err;
    run = plumbSim(logs, {"living_room", "--texture", "shiny", "--out", (logs / "x").string()});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("shiny"), std::string::npos) << run.err;
    for (const char* jump : {"5", "5:0", "x:2", "5:-1"}) {
        run = plumbSim(logs,
                       {"living_room", "--exposure-jump", jump, "--out", (logs / "x").string()});
        EXPECT_EQ(run.exit_code, 2) << jump;
        EXPECT_NE(run.err.find("--exposure-jump"), std::string::npos) << run.err;
    }
    run = plumbSim(logs, {"living_room", "--rgb-noise", "-1", "--out", (logs / "x").string()});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("--rgb-noise"), std::string::npos) << run.err;
    // A scene file with an unknown texture names the file, the line and the key.
    const fs::path scene = logs / "shiny.toml";
    std::ofstream(scene) << "height_m = 2.5\npolygon = [[0, 0], [4, 0], [4, 3], [0, 3]]\n"
                            "texture = \"shiny\"\n";
    run = plumbSim(logs, {scene.string(), "--out", (logs / "x").string()});
    EXPECT_EQ(run.exit_code, 1);
    EXPECT_NE(run.err.find("shiny.toml:3"), std::string::npos) << run.err;
    EXPECT_NE(run.err.find("'texture'"), std::string::npos) << run.err;
    // A trajectory that leaves the room names the pose.
    const fs::path traj = logs / "outside.txt";
    std::ofstream(traj) << "0 1 1 1.4 0 0 0 1\n0.033 50 1 1.4 0 0 0 1\n";
    run = plumbSim(logs, {"living_room", "--trajectory", traj.string(), "--out",
                          (logs / "x").string(), "--intrinsics", "ci", "--noise", "off"});
    EXPECT_EQ(run.exit_code, 1);
    EXPECT_NE(run.err.find("pose 1"), std::string::npos) << run.err;
}

}  // namespace
}  // namespace plumb
