// SPDX-License-Identifier: Apache-2.0
// `plumb demo`: the main job on the embedded default. A simulated handheld scan of a built-in
// room runs through plumb-device and plumb-backend as two processes talking LCM on loopback
// (ttl=0: nothing leaves the host); the backend reconstructs and scores the result against the
// simulator's exact ground truth, and the demo prints the summary.

#include <fmt/format.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "common/core/logging.hpp"
#include "common/io/ply.hpp"
#include "common/io/trajectory.hpp"
#include "common/layout/layout.hpp"
#include "common/layout/layout_json.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tools/plumb/command.hpp"

extern char** environ;

namespace plumb::tools {
namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage =
    "usage: plumb demo [options]\n"
    "\n"
    "Scans a built-in simulated room with the simulated handheld scanner and reconstructs it the\n"
    "way a real deployment does: plumb-device tracks, fuses and streams fragments over LCM on\n"
    "loopback (ttl=0), plumb-backend receives them, registers them, estimates the layout,\n"
    "alternates it with layout-constrained global registration and writes the output contract.\n"
    "The result is scored against the simulator's exact ground truth (trajectory, surface,\n"
    "layout) and the --no-layout baseline.\n"
    "\n"
    "options:\n"
    "  --out DIR        output folder (default out/demo)\n"
    "  --scene NAME     living_room (default), weak_manhattan, l_shape, corridor\n"
    "  --frames N       frames of the scan at 30 Hz (default 520: about 5 m of walking, half\n"
    "                   the way round living_room, and every wall seen; about 1000 close the\n"
    "                   loop; 300 see a third of the room)\n"
    "  --noise MODE     simulated depth noise: redwood (default; with the measured distortion\n"
    "                   table, which bends frames by up to several cm at 3 m), undistorted,\n"
    "                   parametric, off\n"
    "  --depth-calibration X  the device's depth calibration: sensor (default; the simulated\n"
    "                   sensor is calibrated with its measured table), none (raw, bent depth),\n"
    "                   or a dist-model.txt file\n"
    "  --raw-frames N   the device also streams every N-th frame's depth raw, and the\n"
    "                   backend re-integrates them for the mesh, coloured from the fragments\n"
    "                   (plumb-device's stream.raw_frame_every = N, stream.raw_frame_colour =\n"
    "                   false; README deployment step 5); default 0: none, the mesh fuses the\n"
    "                   fragments' surfaces (less accurate: BENCHMARKS.md)\n"
    "  --port P         LCM UDP port on 239.255.76.67 (default: 7667 + pid % 1000)\n"
    "  -h, --help       this text\n"
    "\n"
    "Ctrl-C (or SIGTERM) is passed on to plumb-device and plumb-backend, and the demo waits\n"
    "for them to stop cleanly; a second Ctrl-C kills them.\n"
    "\n"
    "exit status: 0 done, 1 a process or stage failed, 2 bad command line, 130 interrupted.\n";

constexpr const char* kCommand = "demo";

/// plumb-device and plumb-backend live beside `plumb` in an install (same folder) and in the
/// build tree (../device, ../backend); else on PATH.
std::optional<fs::path> findProgram(const std::string& name, const std::string& build_subdir) {
    std::error_code ec;
    const fs::path self = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) {
        for (const fs::path& candidate :
             {self.parent_path() / name, self.parent_path().parent_path() / build_subdir / name}) {
            if (fs::exists(candidate)) return candidate;
        }
    }
    if (const char* path = std::getenv("PATH")) {
        std::string all = path;
        size_t start = 0;
        while (start <= all.size()) {
            const size_t end = std::min(all.find(':', start), all.size());
            const fs::path candidate = fs::path(all.substr(start, end - start)) / name;
            if (access(candidate.c_str(), X_OK) == 0) return candidate;
            start = end + 1;
        }
    }
    return std::nullopt;
}

Result<pid_t> spawn(const fs::path& program, const std::vector<std::string>& args) {
    std::vector<std::string> all{program.string()};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_t pid = 0;
    const int rc = posix_spawn(&pid, program.c_str(), nullptr, nullptr, argv.data(), environ);
    if (rc != 0) return ioError(fmt::format("cannot start {}: {}", program.string(), strerror(rc)));
    return pid;
}

/// SIGINT and SIGTERM received by the demo (counted by its handler).
std::atomic<int> g_signals{0};

void countSignal(int) { g_signals.fetch_add(1); }

/// Waits for `pid` to exit and returns its exit status (128 + the signal that ended it), while
/// passing Ctrl-C on: the demo's first SIGINT or SIGTERM goes to every child in `children` as
/// SIGINT (each stops its work cleanly), a second one kills them (SIGKILL).
int waitExit(pid_t pid, const std::vector<pid_t>& children) {
    int forwarded = 0;
    for (;;) {
        int status = 0;
        const pid_t r = waitpid(pid, &status, WNOHANG);
        if (r == pid) {
            if (WIFEXITED(status)) return WEXITSTATUS(status);
            return 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
        }
        if (r < 0 && errno != EINTR) return -1;
        const int received = g_signals.load();
        if (received > forwarded) {
            if (forwarded == 0) {
                std::cerr << "plumb demo: interrupted; stopping plumb-device and plumb-backend "
                             "(Ctrl-C again to kill them)\n";
            }
            for (const pid_t child : children) kill(child, forwarded == 0 ? SIGINT : SIGKILL);
            forwarded = received;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
}

/// The ground truth of the scan the device will render, for the backend to score against.
Status writeGroundTruth(const std::string& scene, size_t frames, const fs::path& dir) {
    SourceOptions options;
    options.max_frames = frames;
    Result<std::unique_ptr<FrameSource>> source = openFrameSource("sim:" + scene, options);
    if (!source.isOk()) return source.status();
    const auto* sim = dynamic_cast<const sim::SimSource*>(&(*source)->underlying());
    if (!sim) return failedPrecondition("sim: did not open the simulated scanner");
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) return ioError(fmt::format("{}: {}", dir.string(), ec.message()));
    PLUMB_RETURN_IF_ERROR(io::writeTumTrajectory(dir / "groundtruth.txt", sim->trajectory()));
    PLUMB_RETURN_IF_ERROR(
        io::writePointCloud(dir / "gt_points.ply", sim::sampleSurfaces(sim->scene(), 0.01)));
    Result<Layout> layout = makeRoomLayout(sim->scene().polygon, sim->scene().height_m);
    if (!layout.isOk()) return layout.status();
    return io::writeLayoutJson(dir / "layout.json", *layout);
}

int runDemo(const std::vector<std::string>& args) {
    fs::path out = "out/demo";
    std::string scene = "living_room";
    std::string noise = "redwood";
    std::string depth_calibration = "sensor";
    size_t frames = 520;
    int raw_frame_every = 0;
    int port = 7667 + static_cast<int>(getpid() % 1000);
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        const bool has_value = i + 1 < args.size();
        if (a == "-h" || a == "--help") {
            std::cout << kUsage;
            return kExitOk;
        } else if (a == "--out" && has_value) {
            out = args[++i];
        } else if (a == "--scene" && has_value) {
            scene = args[++i];
            if (Status s = sim::checkSceneName(scene); !s.isOk())
                return usageError(kCommand, s.message());
        } else if (a == "--frames" && has_value) {
            if (!parseNumber(args[++i], &frames) || frames < 60)
                return usageError(kCommand, "--frames needs an integer >= 60");
        } else if (a == "--noise" && has_value) {
            noise = args[++i];
            if (Status s = sim::checkNoiseMode(noise); !s.isOk())
                return usageError(kCommand, s.message());
        } else if (a == "--depth-calibration" && has_value) {
            depth_calibration = args[++i];
            if (Status s = checkDepthCalibration(depth_calibration); !s.isOk())
                return usageError(kCommand, s.message());
        } else if (a == "--raw-frames" && has_value) {
            if (!parseNumber(args[++i], &raw_frame_every) || raw_frame_every < 0)
                return usageError(kCommand, "--raw-frames needs an integer >= 0");
        } else if (a == "--port" && has_value) {
            if (!parseNumber(args[++i], &port) || port < 1024 || port > 65535)
                return usageError(kCommand, "--port needs an integer in [1024, 65535]");
        } else {
            return usageError(kCommand, "unknown or incomplete option " + a);
        }
    }
    const std::optional<fs::path> device = findProgram("plumb-device", "device");
    const std::optional<fs::path> backend = findProgram("plumb-backend", "backend");
    if (!device || !backend) {
        std::cerr << "plumb demo: cannot find " << (device ? "plumb-backend" : "plumb-device")
                  << " beside plumb, in the build tree or on PATH\n";
        return kExitFailure;
    }
    std::error_code ec;
    fs::remove_all(out, ec);
    fs::create_directories(out, ec);
    if (ec) {
        return failure(kCommand, ioError(out.string() + ": " + ec.message()));
    }
    const fs::path gt_dir = out / "ground_truth";
    std::cout << fmt::format(
        "plumb demo: simulated scan of '{}', {} frames, noise {}{}\n", scene, frames, noise,
        raw_frame_every > 0
            ? fmt::format(", one frame in {} streamed raw (depth only)", raw_frame_every)
            : std::string());
    if (Status s = writeGroundTruth(scene, frames, gt_dir); !s.isOk()) return failure(kCommand, s);
    const std::string url = fmt::format("udpm://239.255.76.67:{}?ttl=0", port);
    const std::string log_level = log::levelName(log::currentLevel());  // plumb's, for both
    std::cout << fmt::format("plumb demo: device and backend talk over {}\n", url);

    // From here on Ctrl-C goes to the children (waitExit), and the demo waits for them.
    struct sigaction sa {};
    sa.sa_handler = countSignal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART;
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    Result<pid_t> backend_pid =
        spawn(*backend, {"--live", "--until-end", "--out", out.string(), "--lcm-url", url, "--gt",
                         gt_dir.string(), "--timeout", "3600", "--log-level", log_level});
    if (!backend_pid.isOk()) return failure(kCommand, backend_pid.status());
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    if (g_signals.load() > 0) {
        kill(*backend_pid, SIGINT);
        waitExit(*backend_pid, {*backend_pid});
        std::cerr << "plumb demo: interrupted\n";
        return kExitInterrupted;
    }
    Result<pid_t> device_pid =
        spawn(*device, {"--source", "sim:" + scene, "--frames", std::to_string(frames), "--noise",
                        noise, "--depth-calibration", depth_calibration, "--lcm-url", url,
                        "--spool-dir", (out / "device_spool").string(), "--log-level", log_level,
                        "--set", fmt::format("stream.raw_frame_every={}", raw_frame_every), "--set",
                        "stream.raw_frame_colour=false"});
    if (!device_pid.isOk()) {
        kill(*backend_pid, SIGTERM);
        waitExit(*backend_pid, {*backend_pid});
        return failure(kCommand, device_pid.status());
    }
    const int device_rc = waitExit(*device_pid, {*device_pid, *backend_pid});
    if (device_rc != 0 && g_signals.load() == 0) {
        std::cerr << fmt::format("plumb demo: plumb-device exited with {}; stopping the backend\n",
                                 device_rc);
        kill(*backend_pid, SIGTERM);
    }
    const int backend_rc = waitExit(*backend_pid, {*backend_pid});
    if (g_signals.load() > 0) {
        std::cerr << fmt::format(
            "plumb demo: interrupted; plumb-device exited with {}, plumb-backend with {}; what "
            "they kept is in {}\n",
            device_rc, backend_rc, out.string());
        return kExitInterrupted;
    }
    if (device_rc != 0) return kExitFailure;
    if (backend_rc != 0) {
        std::cerr << fmt::format("plumb demo: plumb-backend exited with {}\n", backend_rc);
        return kExitFailure;
    }
    std::cout << "\nplumb demo: done. Output in " << fs::absolute(out).string() << "\n"
              << "  report.html (open in a browser), metrics.json, mesh.ply, layout.json,\n"
              << "  floorplan.svg, trajectory.txt, pose_graph.json, config.toml;\n"
              << "  the --no-layout baseline in baseline/, the ground truth in ground_truth/\n";
    return kExitOk;
}

}  // namespace

PLUMB_COMMAND(demo, "demo",
              "simulated scan -> plumb-device -> LCM -> plumb-backend -> scored reconstruction",
              runDemo);

}  // namespace plumb::tools
