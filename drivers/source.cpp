// SPDX-License-Identifier: Apache-2.0
#include "drivers/source.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <thread>

#include "common/core/logging.hpp"
#include "drivers/calibrated_source.hpp"
#include "drivers/dataset/dataset.hpp"
#include "drivers/openni2/openni2_source.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/v4l2/v4l2_source.hpp"

namespace plumb {
namespace {

/// "640x480@30" -> width, height, fps.
Status parseDepthMode(const std::string& mode, int* width, int* height, int* fps) {
    char x = 0;
    char at = 0;
    if (std::sscanf(mode.c_str(), "%d%c%d%c%d", width, &x, height, &at, fps) != 5 || x != 'x' ||
        at != '@' || *width <= 0 || *height <= 0 || *fps <= 0) {
        return invalidArgument("depth mode '" + mode + "' is not WxH@fps (e.g. 640x480@30)");
    }
    return Status::ok();
}

/// The raw source, without calibration. `sensor_calibration` receives the table the sensor
/// ships with (empty when it has none).
Result<std::unique_ptr<FrameSource>> openRawSource(const std::string& uri,
                                                   const SourceOptions& options,
                                                   std::string* sensor_calibration) {
    const auto colon = uri.find(':');
    const std::string scheme = colon == std::string::npos ? "" : uri.substr(0, colon);
    const std::string rest = colon == std::string::npos ? uri : uri.substr(colon + 1);
    if (scheme.empty() && std::filesystem::is_directory(uri)) {
        return openRawSource("dataset:" + uri, options, sensor_calibration);
    }
    if (scheme == "dataset") {
        dataset::DatasetConfig config;
        config.intrinsics = options.intrinsics;
        config.depth_scale = options.depth_scale;
        config.max_frames = options.max_frames;
        config.load_colour = options.colour;
        auto source = dataset::DatasetSource::open(rest, config);
        if (!source.isOk()) return source.status();
        return std::unique_ptr<FrameSource>(std::move(source).value());
    }
    if (scheme == "sim") {
        sim::SimConfig config;
        config.scene = rest;
        config.seed = options.seed;
        config.trajectory.seed = options.seed;
        config.trajectory.num_frames = options.max_frames > 0 ? options.max_frames : 600;
        config.colour.enabled = options.colour;  // --no-colour: the camera renders depth only
        if (!options.intrinsics.empty()) {
            auto camera = cameraPreset(options.intrinsics);
            if (!camera.isOk()) return camera.status();
            config.camera = *camera;
        }
        if (!options.sim_noise.empty()) {
            PLUMB_RETURN_IF_ERROR(sim::parseNoiseMode(options.sim_noise, &config.noise));
        }
        auto source = sim::SimSource::create(config);
        if (!source.isOk()) return source.status();
        if (config.noise.enabled && config.noise.distortion == sim::DistortionKind::kTable) {
            auto table = sim::findNoiseModelFile(config.noise_model_path);
            if (!table.isOk()) return table.status();
            *sensor_calibration = table->string();
        }
        return std::unique_ptr<FrameSource>(std::move(source).value());
    }
    if (scheme == "openni2" || uri == "openni2") {
        openni2::OpenNI2Config config;
        config.uri = scheme == "openni2" ? rest : "";
        config.max_frames = options.max_frames;
        config.intrinsics = options.intrinsics;
        config.colour = options.colour;
        PLUMB_RETURN_IF_ERROR(
            parseDepthMode(options.depth_mode, &config.width, &config.height, &config.fps));
        auto source = openni2::OpenNI2Source::open(config);
        if (!source.isOk()) return source.status();
        return std::unique_ptr<FrameSource>(std::move(source).value());
    }
    if (scheme == "v4l2") {
        v4l2::V4l2Config config;
        PLUMB_RETURN_IF_ERROR(v4l2::parseV4l2Target(rest, &config));
        if (!options.colour) config.colour_device.clear();
        config.max_frames = options.max_frames;
        config.intrinsics = options.intrinsics;
        if (options.depth_scale > 0.0) config.units_per_m = options.depth_scale;
        PLUMB_RETURN_IF_ERROR(
            parseDepthMode(options.depth_mode, &config.width, &config.height, &config.fps));
        auto source = v4l2::V4l2Source::open(config);
        if (!source.isOk()) return source.status();
        return std::unique_ptr<FrameSource>(std::move(source).value());
    }
    return unsupported("unknown frame source '" + uri + "' (scheme '" + scheme + "', target '" +
                       rest +
                       "'); use dataset:<dir>, sim:<scene>, openni2[:<uri>] or "
                       "v4l2:/dev/videoN[?colour=/dev/videoM]");
}

}  // namespace

Status checkDepthCalibration(const std::string& value) {
    if (value.empty() || value == "sensor" || value == "none") return Status::ok();
    if (std::filesystem::is_regular_file(value)) return Status::ok();
    return notFound("depth calibration '" + value +
                    "' is neither 'sensor', 'none' nor an existing dist-model.txt file");
}

Result<std::unique_ptr<FrameSource>> withDepthCalibration(std::unique_ptr<FrameSource> raw,
                                                          const std::string& choice,
                                                          const std::string& sensor_table) {
    PLUMB_RETURN_IF_ERROR(checkDepthCalibration(choice));
    const std::string path = choice.empty() || choice == "sensor" ? sensor_table
                             : choice == "none"                   ? std::string()
                                                                  : choice;
    if (path.empty()) return raw;
    auto calibration = DepthCalibration::load(path);
    if (!calibration.isOk()) return calibration.status();
    return std::unique_ptr<FrameSource>(
        std::make_unique<CalibratedSource>(std::move(raw), std::move(calibration).value()));
}

Result<std::unique_ptr<FrameSource>> openFrameSource(const std::string& uri,
                                                     const SourceOptions& options) {
    PLUMB_RETURN_IF_ERROR(checkDepthCalibration(options.depth_calibration));
    std::string sensor_calibration;
    auto source = openRawSource(uri, options, &sensor_calibration);
    if (!source.isOk()) return source.status();
    return withDepthCalibration(std::move(source).value(), options.depth_calibration,
                                sensor_calibration);
}

Status checkSourceArguments(const std::string& uri, const SourceOptions& options) {
    const bool sim = uri.rfind("sim:", 0) == 0;
    if (!options.intrinsics.empty()) {
        const Result<PinholeCamera> preset = cameraPreset(options.intrinsics);
        std::error_code ec;
        if (!preset.isOk() && sim) {
            return invalidArgument(
                fmt::format("intrinsics '{}': the simulator takes a camera preset: {}",
                            options.intrinsics, preset.status().message()));
        }
        if (!preset.isOk() && !std::filesystem::is_regular_file(options.intrinsics, ec)) {
            return invalidArgument(
                fmt::format("intrinsics '{}' is neither a camera preset nor an existing file: {}",
                            options.intrinsics, preset.status().message()));
        }
    }
    PLUMB_RETURN_IF_ERROR(checkDepthCalibration(options.depth_calibration));
    if (sim) PLUMB_RETURN_IF_ERROR(sim::checkSceneName(uri.substr(4)));
    return Status::ok();
}

bool isLiveCameraUri(const std::string& uri) {
    if (uri == "openni2") return true;
    if (uri.rfind("v4l2:", 0) == 0) return true;
    return uri.rfind("openni2:", 0) == 0 && !openni2::isOniFile(uri.substr(8));
}

bool isAbsentCamera(const std::string& uri, const Status& status) {
    const StatusCode code = status.code();
    return isLiveCameraUri(uri) &&
           (code == StatusCode::kNotFound || code == StatusCode::kUnavailable);
}

void ArrivalRelay::arrived() {
    std::lock_guard lock(mutex_);
    if (source_ != nullptr) {
        source_->cameraArrived();
        return;
    }
    pending_ = true;
    changed_.notify_all();
}

void ArrivalRelay::attach(FrameSource* source) {
    std::lock_guard lock(mutex_);
    source_ = source;
    pending_ = false;
}

bool ArrivalRelay::waitForArrival(int ms) {
    std::unique_lock lock(mutex_);
    const bool arrived =
        changed_.wait_for(lock, std::chrono::milliseconds(ms), [this] { return pending_; });
    pending_ = false;
    return arrived;
}

Result<std::unique_ptr<FrameSource>> openFrameSourceWhenPresent(const std::string& uri,
                                                                const SourceOptions& options,
                                                                const CameraWait& wait,
                                                                ArrivalRelay* relay,
                                                                const std::function<bool()>& stop) {
    using Clock = std::chrono::steady_clock;
    const auto start = Clock::now();
    auto elapsed_s = [&start] {
        return std::chrono::duration<double>(Clock::now() - start).count();
    };
    double next_report_s = wait.report_s;
    for (int attempt = 1;; ++attempt) {
        auto source = openFrameSource(uri, options);
        if (source.isOk()) {
            if (attempt > 1) {
                log::info("camera '{}' is present after {:.1f} s; starting", uri, elapsed_s());
            }
            return source;
        }
        const Status& why = source.status();
        if (wait.timeout_s == 0.0 || !isAbsentCamera(uri, why)) return why;
        if (attempt == 1) {
            log::info("waiting for camera '{}' to be plugged in ({}){}", uri, why.message(),
                      wait.timeout_s > 0.0 ? fmt::format(" for up to {:g} s", wait.timeout_s)
                                           : std::string(" until stopped"));
        }
        // Pause retry_ms, in slices so a stop request is seen within 100 ms.
        const auto until = Clock::now() + std::chrono::milliseconds(std::max(1, wait.retry_ms));
        while (Clock::now() < until) {
            if (stop && stop()) {
                return unavailable(
                    fmt::format("stopped while waiting for the camera ({})", why.message()));
            }
            if (wait.timeout_s > 0.0 && elapsed_s() >= wait.timeout_s) {
                return unavailable(fmt::format("no camera plugged in within {:g} s ({})",
                                               wait.timeout_s, why.message()));
            }
            const auto left =
                std::chrono::duration_cast<std::chrono::milliseconds>(until - Clock::now());
            const int slice = static_cast<int>(std::clamp<int64_t>(left.count(), 1, 100));
            if (relay == nullptr) {
                std::this_thread::sleep_for(std::chrono::milliseconds(slice));
            } else if (relay->waitForArrival(slice)) {
                log::info("a depth camera arrived; trying '{}' again", uri);
                break;
            }
        }
        if (wait.report_s > 0.0 && elapsed_s() >= next_report_s) {
            log::info("still waiting for camera '{}' ({:.0f} s)", uri, elapsed_s());
            next_report_s += wait.report_s;
        }
    }
}

}  // namespace plumb
