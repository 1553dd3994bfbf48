// SPDX-License-Identifier: Apache-2.0
// `plumb sim`: renders a simulated handheld scan of a room into a TUM-layout dataset.

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "drivers/dataset/intrinsics_file.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "tools/plumb/command.hpp"

namespace plumb::tools {
namespace {

constexpr const char* kUsage =
    "usage: plumb sim <scene> --out DIR [options]\n"
    "\n"
    "Renders a simulated handheld depth scan of <scene> (a built-in room: living_room,\n"
    "weak_manhattan, l_shape, corridor; or a .toml scene file) and writes a TUM-layout dataset:\n"
    "depth/ (uint16 mm), depth.txt, rgb/ (8-bit RGB PNG, registered to depth), rgb.txt,\n"
    "groundtruth.txt, trajectory.log, intrinsics.json, gt_points.ply, layout.json, sim.json,\n"
    "depth_clean/ and gray/.\n"
    "\n"
    "options:\n"
    "  --out DIR            output folder (required)\n"
    "  --frames N           number of frames (default 600)\n"
    "  --loop | --no-loop   closed loop back to the start (default) or no revisits\n"
    "  --roll-sway DEG      the camera rolls about its optical axis by up to DEG degrees\n"
    "                       (period 8 s; default 0: level)\n"
    "  --trajectory FILE    TUM trajectory (camera->world) instead of the generated one\n"
    "                       (default: a generated handheld walk round the room)\n"
    "  --noise MODE         off | redwood (default, measured distortion table) |\n"
    "                       parametric (k1/k2 distortion) | undistorted\n"
    "  --noise-model FILE   Redwood dist-model.txt (default: $PLUMB_NOISE_MODEL, then the\n"
    "                       shared data folder)\n"
    "  --k1 X, --k2 X       parametric distortion strength (default 0.02, 0)\n"
    "  --max-depth M        sensor range limit in metres (default 4.0; 0 = none)\n"
    "  --no-missing         no grazing-angle, depth-edge or random dropout (default: dropout on)\n"
    "  --intrinsics X       camera preset (primesense, ci, ...) or intrinsics file\n"
    "                       (default primesense 640x480)\n"
    "  --seed S             seed of noise and hand shake (default 1)\n"
    "  --gt-spacing M       spacing of gt_points.ply samples in metres (default 0.01)\n"
    "  --no-clean           do not write depth_clean/ (default: written)\n"
    "  --no-gray            do not write gray/ (default: written)\n"
    "  --quiet              print nothing on success (default: the scene and a summary line)\n"
    "  -h, --help           this text\n"
    "\n"
    "colour camera (rgb/):\n"
    "  --texture MODE       textured (patterned walls with pictures, floor, furniture) |\n"
    "                       plain (one uniform colour per surface); default: the scene's\n"
    "                       own setting (built-in rooms are textured)\n"
    "  --rgb-noise L        Gaussian noise std per channel in 8-bit levels (default 2; 0 = none)\n"
    "  --exposure-std X     std of ln(gain) of a smooth random exposure drift (default 0 = off)\n"
    "  --exposure-period N  frames between independent drift values (default 90)\n"
    "  --exposure-jump K:F  multiply the gain by F from frame K on (repeatable; default none)\n"
    "  --no-rgb             render no colour and write no rgb/ or rgb.txt (default: colour)\n"
    "\n"
    "exit status: 0 written, 1 the scene, trajectory or output failed (the message says which),\n"
    "2 bad command line.\n";

constexpr const char* kCommand = "sim";

// "K:F": frame K (non-negative integer), factor F (positive number).
bool parseExposureJump(const std::string& text, sim::ExposureJump* jump) {
    const size_t colon = text.find(':');
    if (colon == std::string::npos) return false;
    uint64_t frame = 0;
    double factor = 0.0;
    if (!parseNumber(text.substr(0, colon), &frame) ||
        !parseNumber(text.substr(colon + 1), &factor) || !(factor > 0.0)) {
        return false;
    }
    jump->frame = frame;
    jump->factor = factor;
    return true;
}

int runSim(const std::vector<std::string>& args) {
    sim::SimConfig config;
    sim::SimDatasetOptions options;
    std::string out_dir;
    std::string scene;
    uint64_t frames = 600;
    bool quiet = false;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&](std::string* v) {
            if (i + 1 >= args.size()) return false;
            *v = args[++i];
            return true;
        };
        std::string v;
        if (a == "--help" || a == "-h") {
            std::printf("%s", kUsage);
            return kExitOk;
        } else if (a == "--out") {
            if (!value(&out_dir)) return usageError(kCommand, "--out needs a folder");
        } else if (a == "--frames") {
            if (!value(&v) || !parseNumber(v, &frames) || frames == 0) {
                return usageError(kCommand, "--frames needs a positive integer");
            }
        } else if (a == "--loop") {
            config.trajectory.loop = true;
        } else if (a == "--no-loop") {
            config.trajectory.loop = false;
        } else if (a == "--roll-sway") {
            if (!value(&v) || !parseNumber(v, &config.trajectory.roll_sway_deg) ||
                std::abs(config.trajectory.roll_sway_deg) > 90.0)
                return usageError(kCommand, "--roll-sway needs degrees in [-90, 90]");
        } else if (a == "--trajectory") {
            if (!value(&config.trajectory_file))
                return usageError(kCommand, "--trajectory needs a file");
        } else if (a == "--noise") {
            if (!value(&v)) return usageError(kCommand, "--noise needs a mode");
            const Status s = sim::parseNoiseMode(v, &config.noise);
            if (!s.isOk()) return usageError(kCommand, s.message());
        } else if (a == "--noise-model") {
            if (!value(&config.noise_model_path))
                return usageError(kCommand, "--noise-model needs a file");
        } else if (a == "--k1") {
            if (!value(&v) || !parseNumber(v, &config.noise.k1)) {
                return usageError(kCommand, "--k1 needs a number");
            }
        } else if (a == "--k2") {
            if (!value(&v) || !parseNumber(v, &config.noise.k2)) {
                return usageError(kCommand, "--k2 needs a number");
            }
        } else if (a == "--max-depth") {
            if (!value(&v) || !parseNumber(v, &config.noise.max_depth_m) ||
                config.noise.max_depth_m < 0.0) {
                return usageError(kCommand, "--max-depth needs a non-negative number of metres");
            }
        } else if (a == "--no-missing") {
            config.noise.missing_data = false;
        } else if (a == "--intrinsics") {
            if (!value(&v))
                return usageError(kCommand, "--intrinsics needs a preset name or a file");
            auto preset = cameraPreset(v);
            if (preset.isOk()) {
                config.camera = *preset;
            } else if (std::filesystem::exists(v)) {
                auto file = dataset::readIntrinsicsFile(v, config.camera);
                if (!file.isOk()) return failure(kCommand, file.status());
                config.camera = file->camera;
            } else {
                return usageError(kCommand,
                                  "--intrinsics: '" + v + "' is neither a preset nor a file");
            }
        } else if (a == "--seed") {
            if (!value(&v) || !parseNumber(v, &config.seed)) {
                return usageError(kCommand, "--seed needs a non-negative integer");
            }
        } else if (a == "--gt-spacing") {
            if (!value(&v) || !parseNumber(v, &options.gt_spacing_m) ||
                !(options.gt_spacing_m >= 0.001)) {
                return usageError(kCommand, "--gt-spacing needs a number of metres >= 0.001");
            }
        } else if (a == "--no-clean") {
            options.write_clean = false;
        } else if (a == "--no-gray") {
            options.write_gray = false;
        } else if (a == "--texture") {
            if (!value(&v)) return usageError(kCommand, "--texture needs textured or plain");
            config.texture = sim::parseTextureMode(v);
            if (!config.texture) {
                return usageError(kCommand,
                                  "--texture: unknown mode '" + v + "' (use textured or plain)");
            }
        } else if (a == "--rgb-noise") {
            if (!value(&v) || !parseNumber(v, &config.colour.noise_std_levels) ||
                !(config.colour.noise_std_levels >= 0.0)) {
                return usageError(kCommand,
                                  "--rgb-noise needs a non-negative number of 8-bit levels");
            }
        } else if (a == "--exposure-std") {
            if (!value(&v) || !parseNumber(v, &config.colour.exposure_log_std) ||
                !(config.colour.exposure_log_std >= 0.0)) {
                return usageError(kCommand, "--exposure-std needs a non-negative number");
            }
        } else if (a == "--exposure-period") {
            if (!value(&v) || !parseNumber(v, &config.colour.exposure_period_frames) ||
                !(config.colour.exposure_period_frames > 0.0)) {
                return usageError(kCommand, "--exposure-period needs a positive number of frames");
            }
        } else if (a == "--exposure-jump") {
            sim::ExposureJump jump;
            if (!value(&v) || !parseExposureJump(v, &jump)) {
                return usageError(kCommand,
                                  "--exposure-jump needs FRAME:FACTOR (e.g. 30:0.6, factor > 0)");
            }
            config.colour.exposure_jumps.push_back(jump);
        } else if (a == "--quiet") {
            quiet = true;
        } else if (a == "--no-rgb") {
            config.colour.enabled = false;
            options.write_rgb = false;
        } else if (!a.empty() && a[0] == '-') {
            return usageError(kCommand, "unknown option '" + a + "'");
        } else if (scene.empty()) {
            scene = a;
        } else {
            return usageError(kCommand, "more than one scene given ('" + scene + "', '" + a + "')");
        }
    }
    if (scene.empty()) return usageError(kCommand, "no scene given");
    if (Status s = sim::checkSceneName(scene); !s.isOk()) return usageError(kCommand, s.message());
    if (out_dir.empty()) return usageError(kCommand, "--out DIR is required");
    config.scene = scene;
    config.trajectory.num_frames = frames;
    config.trajectory.seed = config.seed;

    auto source = sim::SimSource::create(config);
    if (!source.isOk()) return failure(kCommand, source.status());
    if (!quiet) std::printf("plumb sim: %s\n", (*source)->description().c_str());
    const auto start = std::chrono::steady_clock::now();
    const Status written = sim::writeSimDataset(**source, out_dir, options);
    if (!written.isOk()) return failure(kCommand, written);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (quiet) return kExitOk;
    std::printf("plumb sim: wrote %zu frames to %s in %.1f s\n", *(*source)->size(),
                out_dir.c_str(), seconds);
    return kExitOk;
}

}  // namespace
}  // namespace plumb::tools

PLUMB_COMMAND(sim, "sim", "render a simulated handheld scan of a room into a dataset folder",
              plumb::tools::runSim);
