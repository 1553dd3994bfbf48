// SPDX-License-Identifier: Apache-2.0
// plumb-device: capture -> tracking/fusion -> fragments over LCM (device/stream/device_runner.hpp).

#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config.hpp"
#include "common/core/logging.hpp"
#include "common/core/usage.hpp"
#include "device/stream/device_runner.hpp"
#include "drivers/device_list.hpp"
#include "drivers/recording_source.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "drivers/usb/usb_devices.hpp"
#include "messages/conversions.hpp"
#include "messages/lcm_link.hpp"

namespace {

constexpr const char* kProgram = "plumb-device";
constexpr const char* kUsage =
    "usage: plumb-device --source URI [options]\n"
    "\n"
    "Captures depth frames, tracks and fuses them into fragments and sends every fragment to\n"
    "plumb-backend over LCM until it is acknowledged. Exits 0 when the source ended and every\n"
    "fragment was acknowledged; 1 when fragments remain unacknowledged (they stay in the spool\n"
    "directory and are sent first by the next run) or were lost (the spool stayed full: the\n"
    "message names them) or were rejected by the backend (moved to <spool-dir>/quarantine with\n"
    "the reason, not sent again); 2 for a bad command line.\n"
    "\n"
    "  --source URI         sim:<scene> | dataset:<dir> | any source drivers/source.hpp opens\n"
    "  --list-devices       print the depth cameras found (OpenNI2, V4L2, USB) and exit\n"
    "  --config FILE        device configuration (TOML; `plumb config doc device`)\n"
    "  --set KEY=VALUE      override one configuration key (repeatable)\n"
    "  --frames N           stop the source after N frames (default: all)\n"
    "  --intrinsics X       camera preset or intrinsics file (sets capture.intrinsics)\n"
    "  --noise MODE         sim: sources only: redwood (default), undistorted, parametric, off\n"
    "  --depth-calibration X  undistort depth: sensor (default: the sensor's own table; the\n"
    "                       simulated sensor with the measured table is calibrated with it,\n"
    "                       real cameras have none), none, or a CLAMS/Redwood dist-model.txt\n"
    "  --no-colour          read depth only, even when the source has colour (datasets,\n"
    "                       OpenNI2 and V4L2 colour streams)\n"
    "  --realtime           pace recorded sources like a live sensor (capture.realtime)\n"
    "  --wait-for-camera S  a live camera (openni2, v4l2) not plugged in at start: wait up to S\n"
    "                       seconds for it, or 'forever' (capture.wait_for_camera_s; default 0,\n"
    "                       fail at once)\n"
    "  --lcm-url URL        LCM URL (default udpm://239.255.76.67:7667?ttl=0, stays on host)\n"
    "  --allow-remote       allow an LCM URL that can leave this machine\n"
    "  --key-file FILE      shared key (hex) for HMAC-SHA256 authentication of every message\n"
    "  --key-id N           identifier of the key (default 1)\n"
    "  --spool-dir DIR      keep unacknowledged fragments here across runs (default: memory)\n"
    "  --dump-dir DIR       also write every encoded fragment here as sent\n"
    "  --record DIR         also record every captured frame to DIR (a new folder) as a plumb\n"
    "                       dataset: depth/*.png in mm, depth.txt, intrinsics.json, capture.txt,\n"
    "                       rgb/*.png and rgb.txt when the source has colour; replay it with\n"
    "                       --source dataset:DIR\n"
    "  --session-id N       session id (default: start time in microseconds)\n"
    "  --log-level L        trace|debug|info|warn|error|off (default info)\n";

std::atomic<int> g_stop_requests{0};

extern "C" void onSignal(int) { g_stop_requests.fetch_add(1); }

/// Seconds >= 0, or "forever" (-1).
bool parseSeconds(const std::string& text, double* out) {
    if (text == "forever") {
        *out = -1.0;
        return true;
    }
    if (text.empty()) return false;
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (*end != '\0' || !std::isfinite(v) || v < 0.0) return false;
    *out = v;
    return true;
}

bool parseInt64(const std::string& text, int64_t* out) {
    if (text.empty()) return false;
    char* end = nullptr;
    const long long v = std::strtoll(text.c_str(), &end, 10);
    if (*end != '\0') return false;
    *out = v;
    return true;
}

/// The command line of plumb-device (every option but --config/--set).
struct DeviceArgs {
    std::string source_uri, spool_dir, dump_dir, record_dir, intrinsics, sim_noise,
        depth_calibration;
    plumb::messages::LinkOptions link_options;
    int64_t frames = 0, session_id = 0;
    bool realtime = false;
    bool colour = true;
    std::optional<double> wait_for_camera_s;
    plumb::log::Level level = plumb::log::Level::kInfo;
};

/// Parses `args` into `out`. Returns the exit status when the program is done (help, the device
/// list: 0; a usage error: 2), nothing when it should run.
std::optional<int> parseArguments(const std::vector<std::string>& args, DeviceArgs* out) {
    using namespace plumb;
    int64_t key_id = 1;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&](std::string* v) {
            if (i + 1 >= args.size()) return false;
            *v = args[++i];
            return true;
        };
        std::string v;
        if (a == "--help" || a == "-h") {
            std::fputs(kUsage, stdout);
            return 0;
        } else if (a == "--list-devices") {
            std::fputs(formatDeviceList(listDepthDevices()).c_str(), stdout);
            return 0;
        } else if (a == "--source") {
            if (!value(&out->source_uri))
                return usageError(kProgram, "--source needs a value", kUsage);
        } else if (a == "--frames") {
            if (!value(&v) || !parseInt64(v, &out->frames) || out->frames < 0)
                return usageError(kProgram, "--frames needs a count >= 0", kUsage);
        } else if (a == "--intrinsics") {
            if (!value(&out->intrinsics))
                return usageError(kProgram, "--intrinsics needs a value", kUsage);
        } else if (a == "--noise") {
            if (!value(&out->sim_noise))
                return usageError(kProgram, "--noise needs a mode", kUsage);
            if (Status s = sim::checkNoiseMode(out->sim_noise); !s.isOk())
                return usageError(kProgram, s.message(), kUsage);
        } else if (a == "--depth-calibration") {
            if (!value(&out->depth_calibration))
                return usageError(kProgram, "--depth-calibration needs a value", kUsage);
            if (Status s = checkDepthCalibration(out->depth_calibration); !s.isOk())
                return usageError(kProgram, s.message(), kUsage);
        } else if (a == "--realtime") {
            out->realtime = true;
        } else if (a == "--no-colour") {
            out->colour = false;
        } else if (a == "--wait-for-camera") {
            double seconds = 0.0;
            if (!value(&v) || !parseSeconds(v, &seconds))
                return usageError(kProgram, "--wait-for-camera needs seconds >= 0 or 'forever'",
                                  kUsage);
            out->wait_for_camera_s = seconds;
        } else if (a == "--lcm-url") {
            if (!value(&out->link_options.url))
                return usageError(kProgram, "--lcm-url needs a value", kUsage);
        } else if (a == "--allow-remote") {
            out->link_options.allow_remote = true;
        } else if (a == "--key-file") {
            if (!value(&v)) return usageError(kProgram, "--key-file needs a value", kUsage);
            out->link_options.key_file = v;
        } else if (a == "--key-id") {
            if (!value(&v) || !parseInt64(v, &key_id) || key_id < 0 || key_id > INT32_MAX)
                return usageError(kProgram, "--key-id needs a non-negative 32-bit integer", kUsage);
            out->link_options.key_id = static_cast<int32_t>(key_id);
        } else if (a == "--spool-dir") {
            if (!value(&out->spool_dir))
                return usageError(kProgram, "--spool-dir needs a value", kUsage);
        } else if (a == "--dump-dir") {
            if (!value(&out->dump_dir))
                return usageError(kProgram, "--dump-dir needs a value", kUsage);
        } else if (a == "--record") {
            if (!value(&out->record_dir))
                return usageError(kProgram, "--record needs a folder", kUsage);
            if (Status st = RecordingSource::checkFolder(out->record_dir); !st.isOk())
                return usageError(kProgram, st.message(), kUsage);
        } else if (a == "--session-id") {
            if (!value(&v) || !parseInt64(v, &out->session_id) || out->session_id <= 0)
                return usageError(kProgram, "--session-id needs a positive integer", kUsage);
        } else if (a == "--log-level") {
            if (!value(&v) || !log::parseLevel(v, &out->level))
                return usageError(kProgram, "--log-level needs trace|debug|info|warn|error|off",
                                  kUsage);
        } else {
            return usageError(kProgram, "unknown argument '" + a + "'", kUsage);
        }
    }
    if (out->source_uri.empty()) return usageError(kProgram, "--source is required", kUsage);
    if (!out->sim_noise.empty() && out->source_uri.rfind("sim:", 0) != 0) {
        return usageError(kProgram, "--noise applies to sim: sources only", kUsage);
    }
    return std::nullopt;
}

/// "3, 4, 7" (at most 20 ids, then "and N more").
std::string formatIds(const std::vector<uint32_t>& ids) {
    std::string out;
    for (size_t i = 0; i < ids.size() && i < 20; ++i) {
        out += (i > 0 ? ", " : "") + std::to_string(ids[i]);
    }
    if (ids.size() > 20) out += " and " + std::to_string(ids.size() - 20) + " more";
    return out;
}

/// Logs what the run did and returns plumb-device's exit status: 1 when the source failed, or
/// fragments stayed unacknowledged or were lost, else 0.
int summarise(const plumb::device::DeviceRunReport& r, const DeviceArgs& a,
              const plumb::RecordingSource* recorder, const plumb::messages::LcmLink& link) {
    using namespace plumb;
    log::info(
        "frames: {} captured, {} processed ({:.0f} %), {} dropped; fragments: {} cut, {} "
        "acknowledged, {} kept unacknowledged, {} lost, {} rejected by the backend",
        r.frames_captured, r.frames_processed,
        100.0 * messages::processedFraction(r.frames_processed, r.frames_dropped), r.frames_dropped,
        r.fragments_cut, r.fragments_acked, r.unacknowledged.size(), r.lost.size(),
        r.quarantined.size());
    if (recorder != nullptr) {
        log::info("recorded {} frame(s) to {}", recorder->recorded(), a.record_dir);
    }
    if (link.authenticated() && link.authStats().rejected() > 0) {
        log::warn("rejected {} unauthenticated message(s)", link.authStats().rejected());
    }
    int code = 0;
    if (r.source_error) {
        log::error("the source failed: {}", r.source_message);
        code = 1;
    }
    if (!r.unacknowledged.empty()) {
        if (a.spool_dir.empty()) {
            log::error(
                "{} fragment(s) were not acknowledged by a backend and are lost with this "
                "process (run with --spool-dir to keep them)",
                r.unacknowledged.size());
        } else {
            log::error(
                "{} fragment(s) were not acknowledged by a backend; they are kept in {} and "
                "are sent first by the next run",
                r.unacknowledged.size(), a.spool_dir);
        }
        code = 1;
    }
    if (!r.quarantined.empty()) {
        if (r.quarantine_dir.empty()) {
            log::error("{} fragment(s) were rejected for good by the backend and dropped",
                       r.quarantined.size());
        } else {
            log::error(
                "{} fragment(s) were rejected for good by the backend and moved to {} (the reason "
                "beside each); they are not sent again",
                r.quarantined.size(), r.quarantine_dir.string());
        }
        code = 1;
    }
    if (!r.lost.empty()) {
        log::error("{} fragment(s) of this run never entered the spool and are lost: {} ({})",
                   r.lost.size(), formatIds(r.lost), r.spool_error);
        code = 1;
    }
    return code;
}

}  // namespace

int main(int argc, char** argv) {
    using namespace plumb;
    std::vector<std::string> args(argv + 1, argv + argc);
    auto config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(kProgram, config_args.status().message(), kUsage);
    DeviceArgs a;
    if (const std::optional<int> exit_code = parseArguments(args, &a)) return *exit_code;
    const std::string& source_uri = a.source_uri;
    log::setupLogging("plumb-device", a.level);

    device::DeviceRunOptions options;
    if (Status s = config::load(*config_args, options.config); !s.isOk()) {
        std::fprintf(stderr, "plumb-device: %s\n", s.toString().c_str());
        return kExitUsage;
    }
    if (!a.intrinsics.empty()) options.config.capture.intrinsics = a.intrinsics;
    if (a.realtime) options.config.capture.realtime = true;
    if (a.wait_for_camera_s) options.config.capture.wait_for_camera_s = *a.wait_for_camera_s;
    options.config_toml = config::toToml(options.config, "plumb-device configuration (effective)");
    options.spool_dir = a.spool_dir;
    options.dump_dir = a.dump_dir;
    options.session_id = a.session_id > 0 ? a.session_id
                                          : std::chrono::duration_cast<std::chrono::microseconds>(
                                                std::chrono::system_clock::now().time_since_epoch())
                                                .count();

    SourceOptions source_options;
    source_options.intrinsics = options.config.capture.intrinsics;
    source_options.max_frames = static_cast<size_t>(a.frames);
    source_options.seed = options.config.capture.seed;
    source_options.sim_noise = a.sim_noise;
    source_options.depth_calibration = a.depth_calibration;
    source_options.colour = a.colour;
    struct sigaction sa {};
    sa.sa_handler = onSignal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);

    // Live cameras: USB hot-plug wakes the wait for a camera absent at start, then ends the
    // source's reconnect wait as soon as an unplugged camera returns. Declared in this order so
    // the monitor stops before the source goes away, and the source before the relay.
    const device::CaptureConfig& capture = options.config.capture;
    ArrivalRelay arrivals;
    std::unique_ptr<FrameSource> source;
    std::unique_ptr<usb::HotplugMonitor> hotplug;
    if (capture.usb_hotplug && isLiveCameraUri(source_uri)) {
        auto monitor =
            usb::HotplugMonitor::start(usb::forwardArrivals([&arrivals] { arrivals.arrived(); }));
        if (monitor.isOk()) {
            hotplug = std::move(monitor).value();
            log::info("usb: watching for depth cameras arriving and leaving");
        } else {
            log::info(
                "usb: no hot-plug notifications ({}); a vanished camera is retried "
                "periodically",
                monitor.status().message());
        }
    }
    CameraWait wait;
    wait.timeout_s = capture.wait_for_camera_s;
    auto opened = openFrameSourceWhenPresent(source_uri, source_options, wait, &arrivals,
                                             [] { return g_stop_requests.load() > 0; });
    if (!opened.isOk()) {
        log::error("cannot open source '{}': {}", source_uri, opened.status().toString());
        if (wait.timeout_s == 0.0 && isAbsentCamera(source_uri, opened.status())) {
            log::info("to wait for the camera to be plugged in: --wait-for-camera SECONDS|forever");
        }
        return 1;
    }
    source = std::move(opened).value();
    RecordingSource* recorder = nullptr;
    if (!a.record_dir.empty()) {
        auto recording = RecordingSource::create(std::move(source), a.record_dir);
        if (!recording.isOk()) {
            log::error("cannot record: {}", recording.status().toString());
            return 1;
        }
        recorder = recording->get();
        source = std::move(recording).value();
    }
    arrivals.attach(source.get());
    auto link = messages::LcmLink::open(a.link_options);
    if (!link.isOk()) {
        log::error("{}", link.status().toString());
        return 1;
    }
    log::info("source {}; LCM {}{}; session {}", source->description(), (*link)->url(),
              (*link)->authenticated() ? " (authenticated)" : "", options.session_id);

    messages::LcmLink& l = **link;
    device::DeviceLink device_link{&l.transport(), [&l](int ms) { return l.pump(ms); }};
    auto report = device::runDevice(*source, options, device_link, g_stop_requests);
    if (!report.isOk()) {
        log::error("{}", report.status().toString());
        return 1;
    }
    return summarise(*report, a, recorder, l);
}
