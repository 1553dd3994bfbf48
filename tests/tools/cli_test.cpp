// SPDX-License-Identifier: Apache-2.0
// Runs the built `plumb` program (PLUMB_EXE) as a user would and checks what every command has in
// common (issue 30): a bad command line or configuration exits 2 with a one-line hint before any
// work, help is complete and exits 0, --log-level works before and after the command, and a
// damaged image gets plumb's message only (no raw "libpng error" line).

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <Eigen/Core>
#include <algorithm>
#include <cctype>
#include <fstream>
#include <string>
#include <vector>

#include "common/io/trajectory.hpp"
#include "tests/testing/run_program.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

using testing::ProcessRun;
using testing::slurp;

/// Runs `plumb <words> <args>`; `words` are unquoted ("fuse", "--log-level error fuse").
ProcessRun plumb(const fs::path& log_dir, const std::string& words,
                 const std::vector<std::string>& args = {}) {
    return testing::runProgram(std::string("'") + PLUMB_EXE + "' " + words, log_dir, args);
}

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

size_t lineCount(const std::string& text) {
    return static_cast<size_t>(std::count(text.begin(), text.end(), '\n'));
}

/// A small, shared-data-free simulated scan for `plumb fuse`.
std::vector<std::string> smallFuse(const fs::path& out) {
    return {"sim:living_room", "--frames",   "4",     "--intrinsics", "ci",
            "--noise",         "parametric", "--out", out.string()};
}

/// A small simulated scan for `plumb reconstruct` (one fragment, no baseline).
std::vector<std::string> smallReconstruct(const fs::path& out) {
    return {"sim:living_room", "--frames",      "20",    "--intrinsics", "ci", "--noise",
            "parametric",      "--no-baseline", "--out", out.string()};
}

/// True when this build has the backend commands (reconstruct, replay).
bool hasBackend(const fs::path& log_dir) {
    return contains(plumb(log_dir, "--help").out, "  reconstruct ");
}

/// Expects exit 2 and exactly one stderr line naming `what`, with the command's help hint,
/// and that nothing was written to `out`.
void expectUsageError(const ProcessRun& run, const std::string& command, const std::string& what,
                      const fs::path& out) {
    EXPECT_EQ(run.exit_code, 2) << run.err;
    EXPECT_TRUE(contains(run.err, what)) << run.err;
    EXPECT_TRUE(contains(run.err, "(see plumb " + command + " --help)")) << run.err;
    EXPECT_EQ(lineCount(run.err), 1u) << "a one-line hint, not the help:\n" << run.err;
    EXPECT_FALSE(fs::exists(out)) << "the command line is checked before any work";
}

TEST(PlumbCli, BadConfigurationIntrinsicsOrSceneExitTwoBeforeAnyWork) {
    const fs::path logs = testing::freshTempDir("plumb_cli_bad");
    const fs::path out = logs / "out";
    std::vector<std::string> args = smallFuse(out);
    args.insert(args.end(), {"--set", "nosuchkey=1"});
    expectUsageError(plumb(logs, "fuse", args), "fuse", "unknown key 'nosuchkey'", out);

    args = smallFuse(out);
    args.insert(args.end(), {"--set", "tsdf.voxel_size_m=abc"});
    expectUsageError(plumb(logs, "fuse", args), "fuse", "'abc'", out);

    const fs::path bad_file = logs / "bad.toml";
    std::ofstream(bad_file) << "no_such_key = 1\n";
    args = smallFuse(out);
    args.insert(args.end(), {"--config", bad_file.string()});
    expectUsageError(plumb(logs, "fuse", args), "fuse", "bad.toml:1", out);

    args = smallFuse(out);
    args[4] = "no-such-camera";  // --intrinsics
    expectUsageError(plumb(logs, "fuse", args), "fuse", "no-such-camera", out);

    args = smallFuse(out);
    args[0] = "sim:no_such_room";
    expectUsageError(plumb(logs, "fuse", args), "fuse", "no built-in scene 'no_such_room'", out);

    expectUsageError(plumb(logs, "sim", {"no_such_room", "--out", out.string()}), "sim",
                     "no built-in scene 'no_such_room'", out);
    expectUsageError(
        plumb(logs, "sim",
              {"living_room", "--intrinsics", "no-such-camera", "--out", out.string()}),
        "sim", "no-such-camera", out);
    expectUsageError(plumb(logs, "sim", {"living_room", "--frames", "0", "--out", out.string()}),
                     "sim", "--frames", out);
    expectUsageError(plumb(logs, "demo", {"--scene", "no_such_room", "--out", out.string()}),
                     "demo", "no built-in scene 'no_such_room'", out);
    expectUsageError(plumb(logs, "replay"), "replay", "LCM log", out);
    expectUsageError(plumb(logs, "eval traj", {"--bogus"}), "eval traj", "--bogus", out);

    if (hasBackend(logs)) {  // replay checks its configuration before reading the log
        expectUsageError(
            plumb(logs, "replay",
                  {(logs / "scan.lcmlog").string(), "--out", out.string(), "--set", "nosuchkey=1"}),
            "replay", "unknown key 'nosuchkey'", out);
    }

    if (hasBackend(logs)) {  // the same checks in the command with the whole pipeline behind it
        args = smallReconstruct(out);
        args.insert(args.end(), {"--set", "nosuchkey=1"});
        expectUsageError(plumb(logs, "reconstruct", args), "reconstruct", "unknown key 'nosuchkey'",
                         out);
        args = smallReconstruct(out);
        args.insert(args.end(), {"--set", "fusion.tsdf.voxel_size_m=abc"});
        expectUsageError(plumb(logs, "reconstruct", args), "reconstruct",
                         "'abc' is not a valid float value", out);
        args = smallReconstruct(out);
        args[4] = "no-such-camera";  // --intrinsics
        expectUsageError(plumb(logs, "reconstruct", args), "reconstruct", "no-such-camera", out);
        args = smallReconstruct(out);
        args[0] = "sim:no_such_room";
        expectUsageError(plumb(logs, "reconstruct", args), "reconstruct",
                         "no built-in scene 'no_such_room'", out);
    }

    const ProcessRun level = plumb(logs, "--log-level loud fuse", smallFuse(out));
    EXPECT_EQ(level.exit_code, 2) << level.err;
    EXPECT_TRUE(contains(level.err, "--log-level")) << level.err;
}

/// The option blocks of a help text: a line "  -x ..." or "  --xyz ..." and its deeper-indented
/// continuation lines.
std::vector<std::string> optionBlocks(const std::string& help) {
    std::vector<std::string> blocks;
    size_t start = 0;
    while (start < help.size()) {
        size_t end = help.find('\n', start);
        if (end == std::string::npos) end = help.size();
        const std::string line = help.substr(start, end - start);
        start = end + 1;
        if (line.rfind("  -", 0) == 0) {
            blocks.push_back(line);
        } else if (!blocks.empty() && line.rfind("    ", 0) == 0) {
            blocks.back() += "\n" + line;
        } else {
            blocks.emplace_back();  // ends the block
        }
    }
    blocks.erase(std::remove(blocks.begin(), blocks.end(), std::string()), blocks.end());
    return blocks;
}

/// True when the option of `block` takes a value ("--out DIR", "--k1 X, --k2 X", "--exposure-jump
/// K:F"): the word after the flag is written in capitals.
bool takesValue(const std::string& block) {
    const size_t flag_end = block.find(' ', 2);
    if (flag_end == std::string::npos || flag_end + 1 >= block.size()) return false;
    const char c = block[flag_end + 1];
    return std::isupper(static_cast<unsigned char>(c)) != 0;
}

TEST(PlumbCli, ReconstructChecksItsOutputFolderBeforeAnyWork) {
    const fs::path dir = testing::freshTempDir("plumb_cli_reconstruct_out");
    if (!hasBackend(dir)) GTEST_SKIP() << "built without the backend";
    const fs::path file = dir / "a_file";
    std::ofstream(file) << "not a folder\n";
    for (const fs::path& out : {file, file / "below_a_file"}) {
        const ProcessRun run = plumb(
            dir, "reconstruct",
            {"sim:living_room", "--intrinsics", "ci", "--frames", "20", "--out", out.string()});
        EXPECT_EQ(run.exit_code, 2) << run.err;
        EXPECT_TRUE(contains(run.err, "--out " + out.string())) << run.err;
        EXPECT_FALSE(contains(run.err, "fragments fused")) << "checked before tracking:\n"
                                                           << run.err;
    }
    EXPECT_EQ(slurp(file), "not a folder\n");
}

TEST(PlumbCli, ReconstructFrameStepFusesEveryXthFrameLikeFuse) {
    const fs::path dir = testing::freshTempDir("plumb_cli_reconstruct_step");
    if (!hasBackend(dir)) GTEST_SKIP() << "built without the backend";
    const fs::path out = dir / "out";
    const ProcessRun run =
        plumb(dir, "reconstruct",
              {"sim:living_room", "--intrinsics", "ci", "--frames", "60", "--frame-step", "2.5",
               "--no-baseline", "--no-gt", "--quiet", "--out", out.string()});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    // Frames floor(2.5 j) < 60: j = 0..23. metrics.json counts the frames of the fragments.
    const std::string metrics = slurp(out / "metrics.json");
    EXPECT_TRUE(contains(metrics, "\"frames\": 24")) << metrics.substr(0, 400);
    const ProcessRun bad = plumb(dir, "reconstruct",
                                 {"sim:living_room", "--frame-step", "0.5", "--out", out.string()});
    EXPECT_EQ(bad.exit_code, 2);
    EXPECT_TRUE(contains(bad.err, "--frame-step needs a number >= 1")) << bad.err;
}

TEST(PlumbCli, ReconstructFinalModelFromTheKeptFramesIsTheOneFromFramesReadAgain) {
    const fs::path dir = testing::freshTempDir("plumb_cli_reconstruct_kept_frames");
    if (!hasBackend(dir)) GTEST_SKIP() << "built without the backend";
    auto run = [&dir](const std::string& name, const std::string& keep_mb) {
        return plumb(
            dir, "reconstruct",
            {"sim:living_room", "--intrinsics", "ci", "--frames", "30", "--noise", "parametric",
             "--no-gt", "--set", "keep_frames_mb=" + keep_mb, "--out", (dir / name).string()});
    };
    const ProcessRun kept = run("kept", "4096");
    ASSERT_EQ(kept.exit_code, 0) << kept.err;
    EXPECT_FALSE(contains(kept.err, "reads the frames again")) << kept.err;
    const ProcessRun again = run("again", "0");
    ASSERT_EQ(again.exit_code, 0) << again.err;
    // 30 frames of 160x120 hold far more than one megabyte: they are read again, and it says why.
    const ProcessRun over = run("over", "1");
    ASSERT_EQ(over.exit_code, 0) << over.err;
    EXPECT_TRUE(contains(over.err,
                         "the final model reads the frames again: they need more than "
                         "the 1 MB set aside for them"))
        << over.err;
    for (const char* file : {"trajectory.txt", "mesh.ply", "baseline/mesh.ply"}) {
        const std::string reference = slurp(dir / "kept" / file);
        EXPECT_GT(reference.size(), 100u) << file;
        EXPECT_EQ(slurp(dir / "again" / file), reference) << file;
        EXPECT_EQ(slurp(dir / "over" / file), reference) << file;
    }
}

TEST(PlumbCli, ReconstructScoresThePosesADatasetReadsWithItsFrames) {
    const fs::path dir = testing::freshTempDir("plumb_cli_reconstruct_7scenes");
    if (!hasBackend(dir)) GTEST_SKIP() << "built without the backend";
    // A 7-Scenes folder (a .pose.txt per frame, no trajectory file) made from a simulated scan.
    const fs::path sim = dir / "sim", scenes = dir / "seven_scenes";
    const ProcessRun made = plumb(dir, "sim",
                                  {"living_room", "--intrinsics", "ci", "--frames", "40",
                                   "--no-rgb", "--no-gray", "--out", sim.string()});
    ASSERT_EQ(made.exit_code, 0) << made.err;
    Result<io::Trajectory> truth = io::readTumTrajectory(sim / "groundtruth.txt");
    ASSERT_TRUE(truth.isOk()) << truth.status().toString();
    ASSERT_EQ(truth->size(), 40u);
    fs::create_directories(scenes);
    for (size_t k = 0; k < truth->size(); ++k) {
        const std::string stem = fmt::format("frame-{:06d}", k);
        fs::copy_file(sim / "depth" / fmt::format("{:05d}.png", k), scenes / (stem + ".depth.png"));
        const Eigen::Matrix4d T = (*truth)[k].T_W_C.matrix();
        std::ofstream pose(scenes / (stem + ".pose.txt"));
        for (int r = 0; r < 4; ++r) {
            pose << fmt::format("{:.17g} {:.17g} {:.17g} {:.17g}\n", T(r, 0), T(r, 1), T(r, 2),
                                T(r, 3));
        }
    }
    const fs::path out = dir / "out";
    const ProcessRun run = plumb(
        dir, "reconstruct",
        {scenes.string(), "--intrinsics", "ci", "--no-baseline", "--quiet", "--out", out.string()});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_FALSE(contains(run.out, "no ground truth to measure against")) << run.out;
    EXPECT_TRUE(contains(run.out, "ATE RMSE")) << run.out;
    const std::string metrics = slurp(out / "metrics.json");
    EXPECT_TRUE(contains(metrics, "the poses read with 40 frames")) << metrics.substr(0, 600);
}

TEST(PlumbCli, HelpIsCompleteExitsZeroAndStatesEveryDefault) {
    const fs::path logs = testing::freshTempDir("plumb_cli_help");
    const ProcessRun top = plumb(logs, "--help");
    EXPECT_EQ(top.exit_code, 0) << top.err;
    for (const char* part : {"--version", "--log-level", "--help", "exit status", "fuse", "sim",
                             "replay", "eval traj", "demo", "monitor", "config"}) {
        EXPECT_TRUE(contains(top.out, part)) << part << " missing from plumb --help";
    }
    const ProcessRun version = plumb(logs, "--version");
    EXPECT_EQ(version.exit_code, 0);
    EXPECT_EQ(version.out.rfind("plumb ", 0), 0u) << version.out;

    const ProcessRun eval = plumb(logs, "eval --help");
    EXPECT_EQ(eval.exit_code, 0) << eval.err;
    for (const char* part : {"usage: plumb eval", "eval traj", "eval recon", "eval layout"}) {
        EXPECT_TRUE(contains(eval.out, part)) << part << " missing from plumb eval --help";
    }
    EXPECT_EQ(plumb(logs, "eval").exit_code, 2);

    const ProcessRun replay = plumb(logs, "replay --help");
    EXPECT_EQ(replay.exit_code, 0) << replay.err;
    for (const char* part :
         {"usage: plumb replay LOG", "--out", "--fragments", "--no-finalise", "--gt", "--key-file",
          "--key-id", "--config", "--set", "--log-level", "exit status: 0", "2 bad command"}) {
        EXPECT_TRUE(contains(replay.out, part)) << part << " missing from plumb replay --help";
    }

    // Every option that takes a value says what it is when not given.
    std::vector<std::string> commands = {"fuse",   "sim",       "demo",       "monitor",
                                         "replay", "eval traj", "eval recon", "eval layout"};
    if (hasBackend(logs)) commands.emplace_back("reconstruct");
    if (contains(top.out, "  calibrate ")) commands.emplace_back("calibrate");
    for (const std::string& command : commands) {
        const ProcessRun help = plumb(logs, command + " --help");
        ASSERT_EQ(help.exit_code, 0) << command << ": " << help.err;
        EXPECT_TRUE(contains(help.out, "exit status")) << command;
        const std::vector<std::string> blocks = optionBlocks(help.out);
        EXPECT_GE(blocks.size(), 3u) << command;
        for (const std::string& block : blocks) {
            if (!takesValue(block)) continue;
            EXPECT_TRUE(contains(block, "default") || contains(block, "required") ||
                        contains(block, "repeatable"))
                << "plumb " << command << " --help states no default for:\n"
                << block;
        }
    }
}

TEST(PlumbCli, MonitorRefusesAFolderThatIsNotThere) {
    const fs::path logs = testing::freshTempDir("plumb_cli_monitor_dir");
    const ProcessRun missing = plumb(logs, "monitor", {"--dir", "/nonexistent/plumb-out"});
    if (contains(missing.err, "this build has no monitor")) GTEST_SKIP() << missing.err;
    EXPECT_EQ(missing.exit_code, 1) << missing.err;
    EXPECT_TRUE(contains(missing.err, "--dir /nonexistent/plumb-out: no such directory"))
        << missing.err;
    EXPECT_FALSE(contains(missing.out, "serving")) << missing.out;
    { std::ofstream(logs / "a-file") << "x"; }
    const ProcessRun file = plumb(logs, "monitor", {"--dir", (logs / "a-file").string()});
    EXPECT_EQ(file.exit_code, 1) << file.err;
    EXPECT_TRUE(contains(file.err, "not a directory")) << file.err;
}

TEST(PlumbCli, MonitorRefusesAnLcmUrlWithARepeatedOption) {
    // LCM keeps the last of a repeated option: "ttl=0&ttl=255" would listen as a ttl=255 URL
    // while reading as an on-host one. Refused before anything is served, as by the device and
    // the backend.
    const fs::path logs = testing::freshTempDir("plumb_cli_monitor_url");
    const ProcessRun r =
        plumb(logs, "monitor",
              {"--live", "--port", "0", "--lcm-url", "udpm://239.255.76.67:7807?ttl=0&ttl=255"});
    if (contains(r.err, "this build has no monitor")) GTEST_SKIP() << r.err;
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_TRUE(contains(r.err, "option 'ttl' is given more than once")) << r.err;
    EXPECT_FALSE(contains(r.out, "serving")) << r.out;
}

TEST(PlumbCli, LogLevelBeforeOrAfterTheCommandSilencesInfoLines) {
    const fs::path logs = testing::freshTempDir("plumb_cli_log_level");
    const ProcessRun normal = plumb(logs, "fuse", smallFuse(logs / "normal"));
    ASSERT_EQ(normal.exit_code, 0) << normal.err;
    EXPECT_TRUE(contains(normal.err, "plumb fuse info: ")) << normal.err;

    const ProcessRun before = plumb(logs, "--log-level error fuse", smallFuse(logs / "before"));
    ASSERT_EQ(before.exit_code, 0) << before.err;
    EXPECT_EQ(before.err, "") << "no info lines, no progress";

    std::vector<std::string> args = smallFuse(logs / "after");
    args.insert(args.end(), {"--log-level", "error"});
    const ProcessRun after = plumb(logs, "fuse", args);
    ASSERT_EQ(after.exit_code, 0) << after.err;
    EXPECT_EQ(after.err, "");

    args = smallFuse(logs / "inline");
    args.push_back("--log-level=warn");
    const ProcessRun inline_form = plumb(logs, "fuse", args);
    ASSERT_EQ(inline_form.exit_code, 0) << inline_form.err;
    EXPECT_FALSE(contains(inline_form.err, " info: ")) << inline_form.err;
    // The run itself is the same whatever is logged.
    EXPECT_EQ(slurp(logs / "normal/trajectory.txt"), slurp(logs / "after/trajectory.txt"));

    // The same for a command with its own logger and a whole pipeline behind it (in builds with
    // the backend).
    if (hasBackend(logs)) {
        const ProcessRun loud = plumb(logs, "reconstruct", smallReconstruct(logs / "r_normal"));
        ASSERT_EQ(loud.exit_code, 0) << loud.err;
        EXPECT_TRUE(contains(loud.err, "plumb reconstruct info: ")) << loud.err;
        const ProcessRun quiet =
            plumb(logs, "--log-level error reconstruct", smallReconstruct(logs / "r_before"));
        ASSERT_EQ(quiet.exit_code, 0) << quiet.err;
        EXPECT_EQ(quiet.err, "") << "no info lines, no progress";
        EXPECT_EQ(slurp(logs / "r_normal/trajectory.txt"), slurp(logs / "r_before/trajectory.txt"));

        const ProcessRun reconstruct =
            plumb(logs, "reconstruct",
                  {"sim:living_room", "--frames", "40", "--intrinsics", "ci", "--noise",
                   "parametric", "--out", (logs / "reconstruct").string(), "--log-level", "error"});
        ASSERT_EQ(reconstruct.exit_code, 0) << reconstruct.err;
        EXPECT_EQ(reconstruct.err, "");
    }

    // After a command that logs nothing, too.
    const ProcessRun sim_help = plumb(logs, "sim --help --log-level debug");
    EXPECT_EQ(sim_help.exit_code, 0) << sim_help.err;
}

TEST(PlumbCli, LogLevelReachesTheDemosDeviceAndBackend) {
    const fs::path logs = testing::freshTempDir("plumb_cli_demo_log_level");
    if (!contains(plumb(logs, "--help").out, "  demo ") || !hasBackend(logs)) {
        GTEST_SKIP() << "this build has no demo";
    }
    const ProcessRun run =
        plumb(logs, "--log-level error demo",
              {"--frames", "60", "--noise", "parametric", "--out", (logs / "demo").string()});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_EQ(run.err, "") << "plumb-device and plumb-backend log at plumb's level";
    EXPECT_TRUE(contains(run.out, "plumb demo: done")) << run.out;
    // Without raw frames the backend's mesh fuses the fragment surfaces.
    const auto metrics = nlohmann::json::parse(slurp(logs / "demo/metrics.json"));
    EXPECT_EQ(metrics["final_model"], "fragment surfaces fused");
}

TEST(PlumbCli, DemoStreamsRawFramesForTheMesh) {
    const fs::path logs = testing::freshTempDir("plumb_cli_demo_raw_frames");
    if (!contains(plumb(logs, "--help").out, "  demo ") || !hasBackend(logs)) {
        GTEST_SKIP() << "this build has no demo";
    }
    const ProcessRun run = plumb(logs, "--log-level error demo",
                                 {"--frames", "60", "--noise", "parametric", "--raw-frames", "4",
                                  "--out", (logs / "demo").string()});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_TRUE(contains(run.out, "one frame in 4 streamed raw")) << run.out;
    // The backend kept the device's every 4th frame, depth only, and re-integrated them.
    const auto metrics = nlohmann::json::parse(slurp(logs / "demo/metrics.json"));
    EXPECT_EQ(metrics["final_model"],
              "raw frames re-integrated, coloured from the fragment points");
    expectUsageError(plumb(logs, "demo", {"--raw-frames", "-1", "--out", (logs / "none").string()}),
                     "demo", "--raw-frames needs an integer >= 0", logs / "none");
}

/// Flips one byte inside the data of the first IDAT chunk of the PNG at `path`.
void damageIdat(const fs::path& path) {
    std::string bytes = slurp(path);
    const size_t idat = bytes.find("IDAT");
    ASSERT_NE(idat, std::string::npos) << path;
    ASSERT_LT(idat + 14, bytes.size());
    bytes[idat + 14] = static_cast<char>(bytes[idat + 14] ^ 0x5a);
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

TEST(PlumbCli, SimQuietPrintsNothingAndWritesTheSameDataset) {
    const fs::path logs = testing::freshTempDir("plumb_cli_sim_quiet");
    const std::vector<std::string> scan = {"living_room", "--frames", "3",    "--intrinsics",
                                           "ci",          "--noise",  "off",  "--no-gray",
                                           "--no-clean",  "--no-rgb", "--out"};
    std::vector<std::string> loud = scan, quiet = scan;
    loud.push_back((logs / "loud").string());
    quiet.push_back((logs / "quiet").string());
    quiet.emplace_back("--quiet");
    const ProcessRun said = plumb(logs, "sim", loud);
    ASSERT_EQ(said.exit_code, 0) << said.err;
    EXPECT_TRUE(contains(said.out, "plumb sim: wrote 3 frames")) << said.out;
    const ProcessRun silent = plumb(logs, "sim", quiet);
    ASSERT_EQ(silent.exit_code, 0) << silent.err;
    EXPECT_EQ(silent.out, "");
    EXPECT_EQ(silent.err, "");
    for (const char* file : {"groundtruth.txt", "depth.txt", "depth/00002.png"}) {
        EXPECT_EQ(slurp(logs / "quiet" / file), slurp(logs / "loud" / file)) << file;
        EXPECT_FALSE(slurp(logs / "quiet" / file).empty()) << file;
    }
}

TEST(PlumbCli, DamagedPngGetsPlumbsMessageWithoutARawLibpngLine) {
    const fs::path logs = testing::freshTempDir("plumb_cli_png");
    const fs::path scan = logs / "scan";
    const ProcessRun sim = plumb(logs, "sim",
                                 {"living_room", "--frames", "4", "--intrinsics", "ci", "--noise",
                                  "off", "--no-gray", "--no-clean", "--out", scan.string()});
    ASSERT_EQ(sim.exit_code, 0) << sim.err;
    const fs::path truncated = scan / "depth/00001.png";
    fs::resize_file(truncated, fs::file_size(truncated) / 2);
    damageIdat(scan / "depth/00002.png");

    const ProcessRun run =
        plumb(logs, "fuse", {scan.string(), "--quiet", "--out", (logs / "out").string()});
    EXPECT_EQ(run.exit_code, 0) << run.err;  // damaged frames are skipped, with a warning each
    EXPECT_FALSE(contains(run.err, "libpng")) << run.err;
    EXPECT_TRUE(contains(run.err, "00001.png: cannot decode PNG")) << run.err;
    // libpng's own words are in plumb's message.
    EXPECT_TRUE(contains(run.err, "00002.png: cannot decode PNG (truncated or damaged, "))
        << run.err;
    EXPECT_TRUE(contains(run.err, "IDAT: ")) << run.err;  // libpng names the damaged chunk
}

}  // namespace
}  // namespace plumb
