// SPDX-License-Identifier: Apache-2.0
// Runs the built `plumb` program (PLUMB_EXE) as a user would: `plumb calibrate ...` (issue 28)
// writes a distortion table that --depth-calibration reads back, prints every iteration, documents
// every option, and bad input gets a specific error and the documented exit code.

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "common/calibration/distortion_table.hpp"
#include "tests/testing/run_program.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

using testing::ProcessRun;

ProcessRun plumbCalibrate(const fs::path& log_dir, const std::vector<std::string>& args) {
    return testing::runProgram(std::string("'") + PLUMB_EXE + "' calibrate", log_dir, args);
}

TEST(PlumbCalibrateCli, WritesATableThatReadsBack) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const fs::path dir = testing::freshTempDir("plumb_calibrate_cli");
    const fs::path table = dir / "table.txt";
    const ProcessRun run =
        plumbCalibrate(dir, {"sim:living_room", "--intrinsics", "ci", "--frames", "60",
                             "--iterations", "2", "--out", table.string()});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    std::printf("%s", run.out.c_str());
    EXPECT_NE(run.out.find("iteration 1: change median"), std::string::npos) << run.out;
    EXPECT_NE(run.out.find("iteration 2: change median"), std::string::npos) << run.out;
    EXPECT_NE(run.out.find("cells covered per bin"), std::string::npos) << run.out;
    auto learnt = DistortionTable::load(table);
    ASSERT_TRUE(learnt.isOk()) << learnt.status().toString();
    // The Redwood table bends the simulated sensor by up to per cents at 3 m: the learnt table is
    // not neutral there, and stays within the table's few per cent of 1.
    double max_dev = 0.0;
    for (int y = 0; y < 80; ++y) {
        for (int x = 0; x < 80; ++x) {
            max_dev = std::max(max_dev, std::abs(learnt->cell(x, y)[1] - 1.0));
        }
    }
    EXPECT_GT(max_dev, 0.005);
    EXPECT_LT(max_dev, 0.1);
}

TEST(PlumbCalibrateCli, PlanarOnlyLearnsTheBendWithoutPoses) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const fs::path dir = testing::freshTempDir("plumb_calibrate_cli_planar");
    const fs::path table = dir / "table.txt";
    const ProcessRun run = plumbCalibrate(
        dir, {"sim:living_room", "--intrinsics", "ci", "--frames", "600", "--planar-only",
              "--reference", path.string(), "--out", table.string()});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    std::printf("%s", run.out.c_str());
    EXPECT_NE(run.out.find("planes, iteration 1:"), std::string::npos) << run.out;
    EXPECT_NE(run.out.find("the bend from the planes of 600 frames"), std::string::npos) << run.out;
    EXPECT_NE(run.out.find("beyond a projective part"), std::string::npos) << run.out;
    EXPECT_EQ(run.out.find("iteration 1: change median"), std::string::npos) << run.out;
    auto learnt = DistortionTable::load(table);
    ASSERT_TRUE(learnt.isOk()) << learnt.status().toString();
    // The bend at 3 m: per cents between the image's centre and its corners.
    EXPECT_GT(std::abs(learnt->cell(0, 0)[1] - learnt->cell(40, 40)[1]), 0.005);

    // With the right angles asked for: at this resolution no frame holds a wall and the floor
    // as planes large enough, so the step says so and the planar table stands, byte for byte.
    const fs::path with_angles = dir / "with_angles.txt";
    const ProcessRun angles = plumbCalibrate(
        dir, {"sim:living_room", "--intrinsics", "ci", "--frames", "600", "--planar-only", "--set",
              "right_angles.enabled=true", "--out", with_angles.string()});
    ASSERT_EQ(angles.exit_code, 0) << angles.err;
    EXPECT_NE(angles.err.find("right angles: 0 pairs of perpendicular planes"), std::string::npos)
        << angles.err;
    EXPECT_NE(angles.err.find("the planar table is kept"), std::string::npos) << angles.err;
    EXPECT_EQ(testing::slurp(with_angles), testing::slurp(table));
}

TEST(PlumbCalibrateCli, PlanarOnlyRefusesAScanWhosePlanesDoNotDetermineTheBend) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    const fs::path dir = testing::freshTempDir("plumb_calibrate_cli_planar_short");
    // The first 60 frames see one corner of the room: the halves of the scan disagree.
    const ProcessRun run = plumbCalibrate(
        dir,
        {"sim:living_room", "--frames", "60", "--planar-only", "--out", (dir / "t.txt").string()});
    EXPECT_EQ(run.exit_code, 1) << run.err;
    EXPECT_NE(run.err.find("the scan's planes do not determine the bend"), std::string::npos)
        << run.err;
    EXPECT_FALSE(fs::exists(dir / "t.txt"));
}

TEST(PlumbCalibrateCli, HelpDocumentsEveryOption) {
    const fs::path dir = testing::freshTempDir("plumb_calibrate_cli_help");
    const ProcessRun run = plumbCalibrate(dir, {"--help"});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    for (const char* option :
         {"--out", "--frames", "--iterations", "--intrinsics", "--depth-scale", "--seed", "--noise",
          "--threads", "--config", "--set", "--quiet", "--poses", "--refine-poses", "--reference",
          "--initial", "--planar-only", "--no-planar"}) {
        EXPECT_NE(run.out.find(option), std::string::npos) << option;
    }
}

TEST(PlumbCalibrateCli, BadInputGetsASpecificErrorAndExitCode) {
    const fs::path dir = testing::freshTempDir("plumb_calibrate_cli_bad");
    struct Case {
        std::vector<std::string> args;
        int exit_code;
        std::string message;
    };
    const std::string out = (dir / "t.txt").string();
    for (const Case& c : {
             Case{{"--out", out}, 2, "no source given"},
             Case{{"sim:living_room"}, 2, "--out is required"},
             Case{{"sim:living_room", "--out", out, "--frames", "0"}, 2, "--frames needs"},
             Case{{"sim:living_room", "--out", out, "--iterations", "x"}, 2, "--iterations needs"},
             Case{{"sim:living_room", "--out", out, "--bogus"}, 2, "unknown option --bogus"},
             Case{{"sim:living_room", "--out", out, "--set", "relaxation=3"}, 2, "relaxation"},
             Case{{"sim:no_such_room", "--out", out}, 2, "no_such_room"},
             Case{{"sim:living_room", "--out", out, "--planar-only", "--no-planar"},
                  2,
                  "exclude each other"},
             Case{{"sim:living_room", "--out", out, "--planar-only", "--poses", "x.txt"},
                  2,
                  "--planar-only uses no poses"},
             Case{{"sim:living_room", "--out", out, "--initial", "/nonexistent/t.txt"},
                  1,
                  "/nonexistent/t.txt"},
             Case{{"/nonexistent/dataset", "--out", out}, 1, "/nonexistent/dataset"},
         }) {
        const ProcessRun run = plumbCalibrate(dir, c.args);
        EXPECT_EQ(run.exit_code, c.exit_code) << c.message << ": " << run.err;
        EXPECT_NE(run.err.find(c.message), std::string::npos) << run.err;
    }
}

}  // namespace
}  // namespace plumb
