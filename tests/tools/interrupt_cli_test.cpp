// SPDX-License-Identifier: Apache-2.0
// Ctrl-C as a user presses it (issue 30): SIGINT sent to a real `plumb reconstruct` or `plumb
// fuse` keeps the work done, says so and exits 130, and `--resume` then gives the outputs of a run
// that was never interrupted, byte for byte; a second signal aborts at once; `plumb demo` passes
// the signal to plumb-device and plumb-backend and leaves neither running. Also the --out rules: a
// non-empty folder is refused unless --force, which clears only an earlier plumb run's folder.

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/testing/run_program.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

namespace fs = std::filesystem;

using testing::BackgroundProcess;
using testing::ProcessRun;
using testing::slurp;

ProcessRun plumb(const fs::path& log_dir, const std::vector<std::string>& args) {
    return testing::runProgram(std::string("'") + PLUMB_EXE + "'", log_dir, args);
}

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

bool hasBackend(const fs::path& log_dir) {
    return contains(plumb(log_dir, {"--help"}).out, "  reconstruct ");
}

/// A 150-frame simulated scan (three fragments) reconstructed into `out`.
std::vector<std::string> scan(const fs::path& out) {
    return {"reconstruct",   "sim:living_room", "--intrinsics", "ci",         "--frames",  "150",
            "--no-baseline", "--quiet",         "--out",        out.string(), "--threads", "2"};
}

size_t storedFragments(const fs::path& out) {
    std::error_code ec;
    size_t n = 0;
    for (const auto& e : fs::directory_iterator(out / "fragments", ec)) {
        n += e.path().extension() == ".plf" ? 1 : 0;
    }
    return n;
}

nlohmann::json readJson(const fs::path& path) {
    return nlohmann::json::parse(slurp(path), nullptr, false);
}

/// The files of a finished run that must not depend on an interruption.
const std::vector<std::string> kOutputs = {"trajectory.txt",  "trajectory.log", "pose_graph.json",
                                           "layout.json",     "mesh.ply",       "floorplan.svg",
                                           "registration.log"};

/// Interrupts `scan(out)` with SIGINT once `ready` holds, checks what it kept, resumes it and
/// compares every output with `reference`'s. Returns the interrupted run's metrics.json.
nlohmann::json interruptAndResume(const fs::path& dir, const fs::path& out,
                                  const fs::path& reference, const std::function<bool()>& ready) {
    nlohmann::json interrupted;
    {
        BackgroundProcess run(PLUMB_EXE, scan(out), dir);
        EXPECT_TRUE(run.started());
        EXPECT_TRUE(run.waitUntil(ready, 600)) << run.err();
        run.signal(SIGINT);
        const std::optional<int> rc = run.wait(600);
        EXPECT_EQ(rc, std::optional<int>(130)) << run.err();
        EXPECT_TRUE(contains(run.err(), "interrupted")) << run.err();
        EXPECT_TRUE(contains(run.err(), "plumb reconstruct --resume " + out.string())) << run.err();
        interrupted = readJson(out / "metrics.json");
        EXPECT_EQ(interrupted.value("status", ""), "interrupted") << interrupted.dump(2);
        EXPECT_TRUE(fs::exists(out / "resume" / "fusion_state.bin"));
        // The trajectory tracked so far: one line per tracked frame.
        std::ifstream traj(out / "trajectory.txt");
        size_t poses = 0;
        for (std::string line; std::getline(traj, line);) poses += line.rfind('#', 0) != 0;
        EXPECT_EQ(poses, interrupted.value("frames_fused", size_t{0}));
        EXPECT_EQ(storedFragments(out), interrupted.value("fragments_stored", size_t{0}));
    }
    const ProcessRun resumed = plumb(dir, {"reconstruct", "--resume", out.string(), "--quiet"});
    EXPECT_EQ(resumed.exit_code, 0) << resumed.err;
    EXPECT_TRUE(contains(resumed.err, "resuming after frame")) << resumed.err;
    for (const std::string& f : kOutputs) {
        EXPECT_TRUE(fs::exists(reference / f)) << f;
        EXPECT_EQ(slurp(out / f), slurp(reference / f)) << f << " differs from the run never "
                                                        << "interrupted";
    }
    EXPECT_EQ(storedFragments(out), storedFragments(reference));
    EXPECT_EQ(readJson(out / "metrics.json").value("status", ""), "complete");
    EXPECT_FALSE(fs::exists(out / "resume")) << "a completed run keeps no checkpoint";
    return interrupted;
}

TEST(PlumbInterrupt, ReconstructKeepsItsWorkOnCtrlCAndResumesByteForByte) {
    const fs::path dir = testing::freshTempDir("plumb_interrupt_reconstruct");
    if (!hasBackend(dir)) GTEST_SKIP() << "built without the backend";
    const fs::path reference = dir / "uninterrupted";
    const ProcessRun whole = plumb(dir, scan(reference));
    ASSERT_EQ(whole.exit_code, 0) << whole.err;
    ASSERT_EQ(storedFragments(reference), 3u);

    // During tracking and fusion: as soon as the first fragment is stored (frame 50 of 150).
    const fs::path during_fusion = dir / "during_fusion";
    const nlohmann::json a = interruptAndResume(
        dir, during_fusion, reference, [&] { return storedFragments(during_fusion) >= 1; });
    EXPECT_EQ(a.value("stage", ""), "tracking and fusion") << a.dump(2);
    EXPECT_FALSE(a.value("fusion_finished", true));
    EXPECT_LT(a.value("frames_read", 0), 150);

    // In the backend: once the finished fusion is checkpointed.
    const fs::path in_backend = dir / "in_backend";
    const nlohmann::json b = interruptAndResume(dir, in_backend, reference, [&] {
        return fs::exists(in_backend / "resume" / "fusion_state.bin");
    });
    EXPECT_EQ(b.value("stage", ""), "backend") << b.dump(2);
    EXPECT_TRUE(b.value("fusion_finished", false));
    EXPECT_EQ(b.value("frames_read", 0), 150);
}

TEST(PlumbInterrupt, ASecondSignalAbortsAtOnce) {
    const fs::path dir = testing::freshTempDir("plumb_interrupt_twice");
    if (!hasBackend(dir)) GTEST_SKIP() << "built without the backend";
    const fs::path out = dir / "out";
    BackgroundProcess run(PLUMB_EXE, scan(out), dir);
    ASSERT_TRUE(run.waitUntil([&] { return storedFragments(out) >= 1; }, 600)) << run.err();
    run.signal(SIGINT);
    run.signal(SIGTERM);  // another signal number: two pending SIGINTs would merge into one
    EXPECT_EQ(run.wait(600), std::optional<int>(130)) << run.err();
    EXPECT_TRUE(contains(run.err(), "interrupted again: stopping at once")) << run.err();
    EXPECT_GE(storedFragments(out), 1u) << "stored fragments stay";
}

TEST(PlumbInterrupt, ResumeRefusesAFolderWithoutAnInterruptedRunAndExtraOptions) {
    const fs::path dir = testing::freshTempDir("plumb_interrupt_resume_args");
    if (!hasBackend(dir)) GTEST_SKIP() << "built without the backend";
    const ProcessRun none = plumb(dir, {"reconstruct", "--resume", dir.string()});
    EXPECT_EQ(none.exit_code, 2) << none.err;
    EXPECT_TRUE(contains(none.err, "no interrupted run there")) << none.err;
    const ProcessRun extra =
        plumb(dir, {"reconstruct", "--resume", dir.string(), "--frames", "10"});
    EXPECT_EQ(extra.exit_code, 2) << extra.err;
    EXPECT_TRUE(contains(extra.err, "takes only --quiet and --threads")) << extra.err;
}

TEST(PlumbInterrupt, ANonEmptyOutputFolderIsRefusedUnlessForceClearsAnEarlierRun) {
    const fs::path dir = testing::freshTempDir("plumb_interrupt_force");
    if (!hasBackend(dir)) GTEST_SKIP() << "built without the backend";
    std::vector<std::string> small = {
        "reconstruct", "sim:living_room", "--intrinsics", "ci", "--frames",
        "20",          "--no-baseline",   "--quiet"};
    auto into = [&](const fs::path& out, bool force) {
        std::vector<std::string> args = small;
        args.insert(args.end(), {"--out", out.string()});
        if (force) args.push_back("--force");
        return plumb(dir, args);
    };
    // Someone else's folder: refused, with or without --force, and left as it was.
    const fs::path other = dir / "other";
    fs::create_directories(other);
    std::ofstream(other / "notes.txt") << "mine\n";
    for (bool force : {false, true}) {
        const ProcessRun r = into(other, force);
        EXPECT_EQ(r.exit_code, 2) << r.err;
        EXPECT_TRUE(contains(r.err, force ? "--force clears only" : "not empty")) << r.err;
        EXPECT_FALSE(contains(r.err, "fragments fused")) << "checked before any work";
    }
    EXPECT_EQ(slurp(other / "notes.txt"), "mine\n");
    EXPECT_EQ(std::distance(fs::directory_iterator(other), fs::directory_iterator()), 1);

    // An earlier run's folder with a baseline/ that this run would not write: --force clears it.
    const fs::path earlier = dir / "earlier";
    fs::create_directories(earlier / "baseline");
    std::ofstream(earlier / "metrics.json") << "{}\n";
    std::ofstream(earlier / "baseline" / "mesh.ply") << "old\n";
    EXPECT_EQ(into(earlier, false).exit_code, 2);
    EXPECT_TRUE(fs::exists(earlier / "baseline" / "mesh.ply"));
    const ProcessRun forced = into(earlier, true);
    EXPECT_EQ(forced.exit_code, 0) << forced.err;
    EXPECT_FALSE(fs::exists(earlier / "baseline")) << "no earlier run's files mix in";
    EXPECT_TRUE(fs::exists(earlier / "mesh.ply"));
}

bool hasFuse(const fs::path& log_dir) {
    return contains(plumb(log_dir, {"--help"}).out, "  fuse ");
}

/// A 120-frame simulated scan at 160x120 (three fragments of 40 frames) fused into `out`.
std::vector<std::string> fuseScan(const fs::path& out) {
    return {"fuse",       "sim:living_room", "--intrinsics", "ci",        "--noise",
            "parametric", "--frames",        "120",          "--set",     "frames_per_fragment=40",
            "--quiet",    "--out",           out.string(),   "--threads", "2"};
}

/// The files of a folder, by name, with their contents (not descending into sub-folders).
std::map<std::string, std::string> filesIn(const fs::path& dir) {
    std::map<std::string, std::string> files;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec)) {
        if (e.is_regular_file()) files[e.path().filename().string()] = slurp(e.path());
    }
    return files;
}

size_t fragmentFiles(const fs::path& out) {
    size_t n = 0;
    for (const auto& [name, bytes] : filesIn(out)) n += fs::path(name).extension() == ".ply";
    return n;
}

/// fragments.json without its measured times (ms_per_frame and the live figures derived from
/// them), which differ between any two runs.
std::string withoutTimes(nlohmann::json summary) {
    summary.erase("ms_per_frame");
    if (summary.contains("live")) {
        for (const char* key :
             {"keeps_fraction", "keeps_fraction_by_mean", "longest_drop_run", "max_latency_ms"}) {
            summary["live"].erase(key);
        }
    }
    return summary.dump(2);
}

TEST(PlumbInterrupt, FuseKeepsItsWorkOnCtrlCAndResumesByteForByte) {
    const fs::path dir = testing::freshTempDir("plumb_interrupt_fuse");
    if (!hasFuse(dir)) GTEST_SKIP() << "built without the device pipeline";
    const fs::path reference = dir / "uninterrupted";
    const ProcessRun whole = plumb(dir, fuseScan(reference));
    ASSERT_EQ(whole.exit_code, 0) << whole.err;
    ASSERT_EQ(fragmentFiles(reference), 3u);
    EXPECT_EQ(readJson(reference / "fragments.json").value("status", ""), "complete");
    EXPECT_FALSE(fs::exists(reference / "resume")) << "a completed run keeps no checkpoint";

    // Interrupted as soon as the first fragment is written (frame 40 of 120), mid-fragment.
    const fs::path out = dir / "interrupted";
    {
        BackgroundProcess run(PLUMB_EXE, fuseScan(out), dir);
        ASSERT_TRUE(run.started());
        ASSERT_TRUE(run.waitUntil([&] { return fs::exists(out / "fragment_000.json"); }, 600))
            << run.err();
        run.signal(SIGINT);
        EXPECT_EQ(run.wait(600), std::optional<int>(130)) << run.err();
        EXPECT_TRUE(contains(run.err(), "plumb fuse: interrupted after")) << run.err();
        EXPECT_TRUE(contains(run.err(), "plumb fuse --resume " + out.string())) << run.err();
    }
    const nlohmann::json interrupted = readJson(out / "fragments.json");
    EXPECT_EQ(interrupted.value("status", ""), "interrupted") << interrupted.dump(2);
    EXPECT_EQ(interrupted.value("resume", ""), "plumb fuse --resume " + out.string());
    const size_t frames_read = interrupted.value("frames_read", size_t{0});
    EXPECT_GE(frames_read, 40u);
    EXPECT_LT(frames_read, 120u) << "stopped mid-scan";
    // The fragments written so far, each complete, and listed.
    const size_t written = interrupted.value("fragments_written", size_t{0});
    EXPECT_GE(written, 1u);
    EXPECT_EQ(fragmentFiles(out), written);
    EXPECT_EQ(interrupted.at("fragments").size(), written);
    for (size_t id = 0; id < written; ++id) {
        const std::string stem = fmt::format("fragment_{:03d}", id);
        for (const char* ext : {".ply", ".json"}) {
            EXPECT_TRUE(slurp(out / (stem + ext)) == slurp(reference / (stem + ext)))
                << stem << ext << " differs from the run never interrupted";
        }
    }
    // The trajectory tracked so far: one line per tracked frame, the open fragment's included.
    std::ifstream traj(out / "trajectory.txt");
    size_t poses = 0;
    for (std::string line; std::getline(traj, line);) poses += line.rfind('#', 0) != 0;
    EXPECT_EQ(poses, interrupted.value("frames", size_t{0}) -
                         interrupted.value("frames_tracking_failed", size_t{0}));
    EXPECT_GT(poses, 40u * written) << "the open fragment's frames are in it";
    EXPECT_TRUE(fs::exists(out / "resume" / "fuse_state.bin"));

    // A new run into the interrupted folder is refused (it would mix in); --resume continues.
    EXPECT_EQ(plumb(dir, fuseScan(out)).exit_code, 2);
    const fs::file_time_type first_written = fs::last_write_time(out / "fragment_000.ply");
    const ProcessRun resumed = plumb(dir, {"fuse", "--resume", out.string(), "--quiet"});
    ASSERT_EQ(resumed.exit_code, 0) << resumed.err;
    EXPECT_TRUE(contains(resumed.err, fmt::format("resuming after frame {} ", frames_read)))
        << resumed.err;
    EXPECT_EQ(fs::last_write_time(out / "fragment_000.ply"), first_written)
        << "continued, not started again";
    const std::map<std::string, std::string> expected = filesIn(reference), got = filesIn(out);
    for (const auto& [name, bytes] : expected) {
        ASSERT_TRUE(got.count(name)) << name << " missing";
        if (name == "fragments.json") continue;
        EXPECT_TRUE(got.at(name) == bytes) << name << " differs from the run never interrupted";
    }
    EXPECT_EQ(got.size(), expected.size());
    EXPECT_EQ(withoutTimes(readJson(out / "fragments.json")),
              withoutTimes(readJson(reference / "fragments.json")));
    EXPECT_FALSE(fs::exists(out / "resume")) << "a completed run keeps no checkpoint";
}

TEST(PlumbInterrupt, FuseStopsAtOnceOnASecondSignal) {
    const fs::path dir = testing::freshTempDir("plumb_interrupt_fuse_twice");
    if (!hasFuse(dir)) GTEST_SKIP() << "built without the device pipeline";
    const fs::path out = dir / "out";
    BackgroundProcess run(PLUMB_EXE, fuseScan(out), dir);
    ASSERT_TRUE(run.waitUntil([&] { return fs::exists(out / "fragment_000.json"); }, 600))
        << run.err();
    run.signal(SIGINT);
    run.signal(SIGTERM);  // another signal number: two pending SIGINTs would merge into one
    EXPECT_EQ(run.wait(600), std::optional<int>(130)) << run.err();
    EXPECT_TRUE(contains(run.err(), "interrupted again: stopping at once")) << run.err();
    EXPECT_FALSE(contains(run.err(), "plumb fuse: interrupted after")) << run.err();
    EXPECT_TRUE(fs::exists(out / "fragment_000.ply")) << "written fragments stay";
}

TEST(PlumbInterrupt, FuseResumeRefusesAFolderWithoutAnInterruptedFuseAndExtraOptions) {
    const fs::path dir = testing::freshTempDir("plumb_interrupt_fuse_resume_args");
    if (!hasFuse(dir)) GTEST_SKIP() << "built without the device pipeline";
    const ProcessRun none = plumb(dir, {"fuse", "--resume", dir.string()});
    EXPECT_EQ(none.exit_code, 2) << none.err;
    EXPECT_TRUE(contains(none.err, "no interrupted run there")) << none.err;
    const ProcessRun extra = plumb(dir, {"fuse", "--resume", dir.string(), "--frames", "10"});
    EXPECT_EQ(extra.exit_code, 2) << extra.err;
    EXPECT_TRUE(contains(extra.err, "takes only --quiet and --threads")) << extra.err;
    // The record of another command's run names the command that continues it.
    fs::create_directories(dir / "resume");
    std::ofstream(dir / "resume" / "run.json")
        << R"({"format": "plumb-reconstruct-run-1", "arguments": [], "cwd": "/",)"
        << R"( "config_toml": ""})"
        << "\n";
    const ProcessRun other = plumb(dir, {"fuse", "--resume", dir.string()});
    EXPECT_EQ(other.exit_code, 2) << other.err;
    EXPECT_TRUE(contains(other.err, "continue it with plumb reconstruct --resume " + dir.string()))
        << other.err;
}

TEST(PlumbInterrupt, FuseRefusesANonEmptyOutputFolderUnlessForceClearsAnEarlierRun) {
    const fs::path dir = testing::freshTempDir("plumb_interrupt_fuse_force");
    if (!hasFuse(dir)) GTEST_SKIP() << "built without the device pipeline";
    auto into = [&](const fs::path& out, bool force) {
        std::vector<std::string> args = {"fuse",    "sim:living_room", "--intrinsics", "ci",
                                         "--noise", "parametric",      "--frames",     "10",
                                         "--quiet", "--out",           out.string()};
        if (force) args.push_back("--force");
        return plumb(dir, args);
    };
    // Someone else's folder: refused, with or without --force, before any work, left as it was.
    const fs::path other = dir / "other";
    fs::create_directories(other);
    std::ofstream(other / "notes.txt") << "mine\n";
    for (bool force : {false, true}) {
        const ProcessRun r = into(other, force);
        EXPECT_EQ(r.exit_code, 2) << r.err;
        EXPECT_TRUE(contains(r.err, force ? "--force clears only" : "not empty")) << r.err;
        EXPECT_FALSE(contains(r.err, "fusing")) << "checked before any work";
    }
    EXPECT_EQ(slurp(other / "notes.txt"), "mine\n");
    EXPECT_EQ(std::distance(fs::directory_iterator(other), fs::directory_iterator()), 1);

    // An earlier run's folder with a fragment this run would not write: --force clears it.
    const fs::path earlier = dir / "earlier";
    ASSERT_EQ(into(earlier, false).exit_code, 0);
    std::ofstream(earlier / "fragment_009.ply") << "old\n";
    const ProcessRun refused = into(earlier, false);
    EXPECT_EQ(refused.exit_code, 2) << refused.err;
    EXPECT_TRUE(contains(refused.err, "--out " + earlier.string())) << refused.err;
    EXPECT_TRUE(fs::exists(earlier / "fragment_009.ply"));
    const ProcessRun forced = into(earlier, true);
    EXPECT_EQ(forced.exit_code, 0) << forced.err;
    EXPECT_FALSE(fs::exists(earlier / "fragment_009.ply")) << "no earlier run's files mix in";
    EXPECT_TRUE(fs::exists(earlier / "fragment_000.ply"));
}

TEST(PlumbInterrupt, DemoPassesCtrlCToItsChildrenAndLeavesNoneRunning) {
    const fs::path dir = testing::freshTempDir("plumb_interrupt_demo");
    if (!contains(plumb(dir, {"--help"}).out, "  demo ")) GTEST_SKIP() << "this build has no demo";
    const fs::path out = dir / "demo_out";
    BackgroundProcess demo(PLUMB_EXE, {"demo", "--out", out.string(), "--frames", "300"}, dir);
    ASSERT_TRUE(demo.started());
    // Both children are running once plumb-device is (it starts after plumb-backend).
    const bool device_started = demo.waitUntil(
        [&] {
            for (pid_t pid : testing::processesMentioning(out.string())) {
                if (contains(slurp(fs::path("/proc") / std::to_string(pid) / "cmdline"),
                             "plumb-device")) {
                    return true;
                }
            }
            return false;
        },
        120);
    ASSERT_TRUE(device_started) << demo.err();
    demo.signal(SIGINT);
    const std::optional<int> rc = demo.wait(300);
    ASSERT_TRUE(rc.has_value()) << "the demo did not stop:\n" << demo.err();
    EXPECT_EQ(*rc, 130) << demo.err();
    EXPECT_TRUE(contains(demo.err(), "interrupted")) << demo.err();
    EXPECT_TRUE(testing::processesMentioning(out.string()).empty())
        << "a child of the demo outlived it";
}

}  // namespace
}  // namespace plumb
