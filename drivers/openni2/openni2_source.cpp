// SPDX-License-Identifier: Apache-2.0
#include "drivers/openni2/openni2_source.hpp"

#include <OpenNI.h>
#include <fmt/format.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <mutex>
#include <set>
#include <thread>

#include "common/core/logging.hpp"
#include "drivers/dataset/depth_png.hpp"
#include "drivers/device_clock.hpp"

namespace plumb::openni2 {
namespace {

using Clock = std::chrono::steady_clock;

/// OpenNI2's extended error on one line: its lines are tab-indented and newline-terminated.
std::string oniError() {
    const char* e = openni::OpenNI::getExtendedError();
    std::string text;
    for (const char* c = e; c != nullptr && *c != '\0'; ++c) {
        const bool space = *c == '\n' || *c == '\r' || *c == '\t' || *c == ' ';
        if (!space) {
            text += *c;
        } else if (!text.empty() && text.back() != ' ') {
            text += ' ';
        }
    }
    while (!text.empty() && text.back() == ' ') text.pop_back();
    return text.empty() ? std::string("no details from OpenNI2") : text;
}

const char* pixelFormatName(openni::PixelFormat f) {
    switch (f) {
        case openni::PIXEL_FORMAT_DEPTH_1_MM:
            return "DEPTH_1_MM";
        case openni::PIXEL_FORMAT_DEPTH_100_UM:
            return "DEPTH_100_UM";
        case openni::PIXEL_FORMAT_SHIFT_9_2:
            return "SHIFT_9_2";
        case openni::PIXEL_FORMAT_SHIFT_9_3:
            return "SHIFT_9_3";
        case openni::PIXEL_FORMAT_RGB888:
            return "RGB888";
        case openni::PIXEL_FORMAT_GRAY16:
            return "GRAY16";
        default:
            return "other";
    }
}

bool isDepthFormat(openni::PixelFormat f) {
    return f == openni::PIXEL_FORMAT_DEPTH_1_MM || f == openni::PIXEL_FORMAT_DEPTH_100_UM;
}

/// How well a colour mode fits the depth mode: 3 same size and rate, 2 same size, 1 same rate,
/// 0 other; -1 not RGB888.
int colourModeScore(const openni::VideoMode& colour, const openni::VideoMode& depth) {
    if (colour.getPixelFormat() != openni::PIXEL_FORMAT_RGB888) return -1;
    const bool size = colour.getResolutionX() == depth.getResolutionX() &&
                      colour.getResolutionY() == depth.getResolutionY();
    const bool rate = colour.getFps() == depth.getFps();
    return size && rate ? 3 : size ? 2 : rate ? 1 : 0;
}

double unitsPerMetre(openni::PixelFormat f) {
    return f == openni::PIXEL_FORMAT_DEPTH_100_UM ? 10000.0 : 1000.0;
}

/// One OpenNI2 initialise/shutdown pair (OpenNI2 counts them).
class Runtime {
  public:
    static Result<std::unique_ptr<Runtime>> acquire() {
        if (openni::OpenNI::initialize() != openni::STATUS_OK) {
            const std::string why = oniError();
            openni::OpenNI::shutdown();
            return unavailable("OpenNI2 could not initialise: " + why);
        }
        return std::unique_ptr<Runtime>(new Runtime());
    }
    ~Runtime() { openni::OpenNI::shutdown(); }
    Runtime(const Runtime&) = delete;
    Runtime& operator=(const Runtime&) = delete;

  private:
    Runtime() = default;
};

}  // namespace

bool isOniFile(const std::string& uri) {
    const std::filesystem::path p(uri);
    return p.extension() == ".oni" || p.extension() == ".ONI";
}

Result<std::vector<DeviceEntry>> listDevices() {
    auto runtime = Runtime::acquire();
    if (!runtime.isOk()) return runtime.status();
    openni::Array<openni::DeviceInfo> infos;
    openni::OpenNI::enumerateDevices(&infos);
    std::vector<DeviceEntry> out;
    for (int i = 0; i < infos.getSize(); ++i) {
        out.push_back({infos[i].getUri(), infos[i].getVendor(), infos[i].getName(),
                       infos[i].getUsbVendorId(), infos[i].getUsbProductId()});
    }
    return out;
}

struct OpenNI2Source::Impl : openni::OpenNI::DeviceConnectedListener,
                             openni::OpenNI::DeviceDisconnectedListener {
    OpenNI2Config config;
    std::unique_ptr<Runtime> runtime;
    std::string uri;
    bool is_file = false;
    openni::Device device;
    openni::VideoStream stream;
    openni::VideoMode mode;
    /// Colour: the stream (valid when has_colour), its mode, frames read but not yet paired.
    struct ColourSample {
        uint64_t timestamp_us = 0;  ///< device clock
        int device_index = 0;
        ColourImage image;  ///< already at the depth's size
    };
    openni::VideoStream colour_stream;
    openni::VideoMode colour_mode;
    bool has_colour = false;
    bool colour_synced = false;
    std::string colour_problem;  ///< why a colour sensor is not used, for description()
    std::deque<ColourSample> colour_frames;
    Clock::time_point last_colour_time;  ///< when the last colour frame came
    bool colour_seen = false;            ///< a colour frame came since the stream opened
    size_t with_colour = 0;
    size_t without_colour = 0;
    PinholeCamera camera;
    DeviceClock clock;
    bool open = false;
    bool registered = false;
    bool listening = false;
    size_t returned = 0;
    int num_recorded = -1;
    int reconnects = 0;
    int last_index = -1;

    std::mutex mutex;
    std::condition_variable changed;
    std::atomic<bool> disconnected{false};
    std::set<std::string> present;  ///< URIs OpenNI2 reported connected since the disconnect

    void onDeviceConnected(const openni::DeviceInfo* info) override {
        {
            std::lock_guard lock(mutex);
            present.insert(info->getUri());
        }
        changed.notify_all();
    }
    void onDeviceDisconnected(const openni::DeviceInfo* info) override {
        if (uri == info->getUri()) disconnected = true;
        {
            std::lock_guard lock(mutex);
            present.erase(info->getUri());
        }
        changed.notify_all();
    }

    ~Impl() override {
        closeDevice();
        if (listening) {
            openni::OpenNI::removeDeviceConnectedListener(this);
            openni::OpenNI::removeDeviceDisconnectedListener(this);
        }
    }

    void closeDevice() {
        if (colour_stream.isValid()) {
            if (colour_synced) device.setDepthColorSyncEnabled(false);
            colour_stream.stop();
            colour_stream.destroy();
        }
        has_colour = false;
        colour_synced = false;
        colour_frames.clear();
        if (stream.isValid()) {
            stream.stop();
            stream.destroy();
        }
        if (device.isValid()) device.close();
        open = false;
    }

    Status chooseMode() {
        const openni::SensorInfo* info = device.getSensorInfo(openni::SENSOR_DEPTH);
        if (info == nullptr) return unsupported("OpenNI2 device '" + uri + "' has no depth sensor");
        const auto& modes = info->getSupportedVideoModes();
        const openni::VideoMode* best = nullptr;
        std::string listed;
        for (int i = 0; i < modes.getSize(); ++i) {
            const openni::VideoMode& m = modes[i];
            listed +=
                fmt::format("{}{}x{}@{} {}", listed.empty() ? "" : ", ", m.getResolutionX(),
                            m.getResolutionY(), m.getFps(), pixelFormatName(m.getPixelFormat()));
            if (m.getResolutionX() != config.width || m.getResolutionY() != config.height ||
                m.getFps() != config.fps || !isDepthFormat(m.getPixelFormat())) {
                continue;
            }
            // Prefer millimetres (every PrimeSense-class device offers it); 100 um otherwise.
            if (best == nullptr || m.getPixelFormat() == openni::PIXEL_FORMAT_DEPTH_1_MM) {
                best = &m;
            }
        }
        if (best == nullptr) {
            return unsupported(
                fmt::format("OpenNI2 device '{}' has no {}x{}@{} depth mode (it "
                            "offers: {})",
                            uri, config.width, config.height, config.fps, listed));
        }
        if (stream.setVideoMode(*best) != openni::STATUS_OK) {
            return ioError("OpenNI2 refused the depth mode: " + oniError());
        }
        return Status::ok();
    }

    /// Opens the colour stream when there is one (config.colour); never fails the device: a
    /// colour stream that cannot be used is logged and left out (has_colour stays false).
    void openColour(bool start) {
        has_colour = false;
        colour_problem.clear();
        if (!config.colour || !device.hasSensor(openni::SENSOR_COLOR)) return;
        const auto give_up = [&](const std::string& why) {
            colour_problem = why;
            log::warn("OpenNI2 device '{}': {}; streaming depth without colour", uri, why);
            if (colour_stream.isValid()) colour_stream.destroy();
        };
        if (colour_stream.create(device, openni::SENSOR_COLOR) != openni::STATUS_OK) {
            return give_up("cannot create the colour stream: " + oniError());
        }
        if (!is_file) {
            const openni::SensorInfo* info = device.getSensorInfo(openni::SENSOR_COLOR);
            const openni::VideoMode depth_mode = stream.getVideoMode();
            const openni::VideoMode* best = nullptr;
            int best_score = -1;
            if (info != nullptr) {
                const auto& modes = info->getSupportedVideoModes();
                for (int i = 0; i < modes.getSize(); ++i) {
                    const int score = colourModeScore(modes[i], depth_mode);
                    if (score > best_score) {
                        best_score = score;
                        best = &modes[i];
                    }
                }
            }
            if (best == nullptr || best_score < 0)
                return give_up("the colour sensor has no RGB888 mode");
            if (colour_stream.setVideoMode(*best) != openni::STATUS_OK) {
                return give_up("OpenNI2 refused the colour mode: " + oniError());
            }
            if (colour_stream.setMirroringEnabled(false) != openni::STATUS_OK &&
                colour_stream.getMirroringEnabled()) {
                return give_up("cannot switch mirroring off on the colour stream: " + oniError());
            }
        }
        colour_mode = colour_stream.getVideoMode();
        if (is_file && device.getPlaybackControl()->getNumberOfFrames(colour_stream) <= 0) {
            // Waiting for colour that never comes would advance the player past depth frames.
            colour_problem = "the recording has no colour frames";
            colour_stream.destroy();
            return;
        }
        if (colour_mode.getPixelFormat() != openni::PIXEL_FORMAT_RGB888) {
            return give_up(std::string("the colour stream is ") +
                           pixelFormatName(colour_mode.getPixelFormat()) + ", not RGB888");
        }
        if (start && colour_stream.start() != openni::STATUS_OK) {
            return give_up("cannot start the colour stream: " + oniError());
        }
        // Frame sync where the device offers it; without it frames pair by timestamp alone.
        colour_synced = !is_file && device.setDepthColorSyncEnabled(true) == openni::STATUS_OK;
        has_colour = true;
        colour_seen = false;
    }

    Status openDevice(bool start = true) {
        const char* target = uri.empty() ? openni::ANY_DEVICE : uri.c_str();
        if (device.open(target) != openni::STATUS_OK) {
            const std::string why = oniError();
            if (is_file) return notFound("OpenNI2 cannot open recording '" + uri + "': " + why);
            return unavailable("OpenNI2 cannot open device '" +
                               (uri.empty() ? std::string("(first device)") : uri) + "': " + why);
        }
        uri = device.getDeviceInfo().getUri();
        if (is_file) {
            openni::PlaybackControl* playback = device.getPlaybackControl();
            if (playback == nullptr) return internal("'" + uri + "' has no playback control");
            playback->setSpeed(-1.0f);  // manual: one frame per read, none dropped
        }
        if (!device.hasSensor(openni::SENSOR_DEPTH)) {
            closeDevice();
            return unsupported("OpenNI2 device '" + uri + "' has no depth sensor");
        }
        if (stream.create(device, openni::SENSOR_DEPTH) != openni::STATUS_OK) {
            const std::string why = oniError();
            closeDevice();
            return ioError("OpenNI2 cannot create the depth stream of '" + uri + "': " + why);
        }
        if (!is_file) {
            Status s = chooseMode();
            if (!s.isOk()) {
                closeDevice();
                return s;
            }
            // Mirroring off: images as the camera sees them, so the intrinsics hold.
            if (stream.setMirroringEnabled(false) != openni::STATUS_OK &&
                stream.getMirroringEnabled()) {
                const std::string why = oniError();
                closeDevice();
                return ioError("OpenNI2 cannot switch mirroring off on '" + uri + "': " + why);
            }
            registered = false;
            if (config.registration &&
                device.isImageRegistrationModeSupported(
                    openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) &&
                device.setImageRegistrationMode(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) ==
                    openni::STATUS_OK) {
                registered = true;
            }
        }
        mode = stream.getVideoMode();
        if (!isDepthFormat(mode.getPixelFormat())) {
            const std::string format = pixelFormatName(mode.getPixelFormat());
            closeDevice();
            return unsupported("OpenNI2 stream of '" + uri + "' is " + format +
                               ", not DEPTH_1_MM or DEPTH_100_UM");
        }
        if (mode.getResolutionX() <= 0 || mode.getResolutionY() <= 0) {
            closeDevice();
            return corrupt(fmt::format("OpenNI2 stream of '{}' reports a {}x{} video mode", uri,
                                       mode.getResolutionX(), mode.getResolutionY()));
        }
        if (is_file) {
            // libOniFile's player thread walks its stream list without a lock, and at the end of
            // a recording without repeat it spins through that list; destroying the stream then
            // races with it (a crash on close). With repeat on, the thread rewinds after the last
            // frame and parks waiting for the next manual trigger, where destroying the stream is
            // safe. next() ends the recording by its frame count, so nothing is played twice.
            // Only a recording whose length is unknown plays without repeat, ending on a timeout.
            openni::PlaybackControl* playback = device.getPlaybackControl();
            num_recorded = playback->getNumberOfFrames(stream);
            playback->setRepeatEnabled(num_recorded > 0);
        }
        openColour(start);
        if (start && stream.start() != openni::STATUS_OK) {
            const std::string why = oniError();
            closeDevice();
            return ioError("OpenNI2 cannot start the depth stream of '" + uri + "': " + why);
        }
        disconnected = false;
        open = true;
        return Status::ok();
    }

    Status setCamera() {
        const int w = mode.getResolutionX();
        const int h = mode.getResolutionY();
        if (!config.intrinsics.empty()) {
            auto preset = cameraPreset(config.intrinsics);
            if (!preset.isOk()) return preset.status();
            if (preset->width != w || preset->height != h) {
                return invalidArgument(
                    fmt::format("intrinsics '{}' are {}x{} but the OpenNI2 stream is {}x{}",
                                config.intrinsics, preset->width, preset->height, w, h));
            }
            camera = *preset;
            return Status::ok();
        }
        const double hfov = stream.getHorizontalFieldOfView();
        const double vfov = stream.getVerticalFieldOfView();
        camera = PinholeCamera().scaled(static_cast<double>(w) / 640.0);
        camera.width = w;
        camera.height = h;
        if (std::isfinite(hfov) && hfov > 0.1 && hfov < 3.0 && std::isfinite(vfov) && vfov > 0.1 &&
            vfov < 3.0) {
            // A pinhole whose image edges (at -0.5 and w - 0.5) subtend the field of view.
            camera.fx = 0.5 * w / std::tan(0.5 * hfov);
            camera.fy = 0.5 * h / std::tan(0.5 * vfov);
            camera.cx = 0.5 * (w - 1);
            camera.cy = 0.5 * (h - 1);
        }
        return Status::ok();
    }

    static Status internal(std::string m) { return {StatusCode::kInternal, std::move(m)}; }

    /// Waits up to reconnect_wait_ms for the device to come back and reopens it.
    Status reconnect() {
        {
            std::unique_lock lock(mutex);
            changed.wait_for(lock, std::chrono::milliseconds(config.reconnect_wait_ms),
                             [this] { return present.count(uri) != 0; });
        }
        Status s = openDevice();
        if (!s.isOk()) {
            return unavailable("OpenNI2 device '" + uri + "' is still gone (" + s.message() + ")");
        }
        ++reconnects;
        clock.reset();
        return Status::ok();
    }

    Result<Frame> convert(const openni::VideoFrameRef& ref) {
        if (!ref.isValid()) return corrupt("OpenNI2 returned an invalid frame");
        if (ref.getSensorType() != openni::SENSOR_DEPTH) {
            return unsupported("OpenNI2 returned a non-depth frame");
        }
        const openni::PixelFormat format = ref.getVideoMode().getPixelFormat();
        if (!isDepthFormat(format)) {
            return unsupported(std::string("OpenNI2 frame has pixel format ") +
                               pixelFormatName(format) + ", not a depth format");
        }
        const int w = ref.getWidth();
        const int h = ref.getHeight();
        if (w <= 0 || h <= 0 || ref.getDataSize() <= 0 || ref.getData() == nullptr) {
            return corrupt(fmt::format("OpenNI2 frame {} is empty ({}x{}, {} bytes)",
                                       ref.getFrameIndex(), w, h, ref.getDataSize()));
        }
        if (w != camera.width || h != camera.height || ref.getCroppingEnabled()) {
            return corrupt(fmt::format(
                "OpenNI2 frame {} is {}x{}{} but the stream is {}x{}", ref.getFrameIndex(), w, h,
                ref.getCroppingEnabled() ? " (cropped)" : "", camera.width, camera.height));
        }
        const int stride = ref.getStrideInBytes() > 0 ? ref.getStrideInBytes() : w * 2;
        const int64_t needed = static_cast<int64_t>(stride) * (h - 1) + int64_t{w} * 2;
        if (stride < w * 2 || ref.getDataSize() < needed) {
            return corrupt(
                fmt::format("OpenNI2 frame {} is short: {} bytes (stride {}) for {}x{} "
                            "16-bit depth needs {}",
                            ref.getFrameIndex(), ref.getDataSize(), stride, w, h, needed));
        }
        const double units = unitsPerMetre(format);
        Frame frame;
        frame.index = static_cast<int64_t>(returned);
        frame.depth = DepthImage(w, h);
        const auto* bytes = static_cast<const uint8_t*>(ref.getData());
        for (int v = 0; v < h; ++v) {
            const auto* row = reinterpret_cast<const uint16_t*>(bytes + int64_t{stride} * v);
            for (int u = 0; u < w; ++u) {
                frame.depth(u, v) = static_cast<float>(static_cast<double>(row[u]) / units);
            }
        }
        frame.timestamp_s = is_file ? static_cast<double>(ref.getTimestamp()) * 1e-6
                                    : clock.toHost(ref.getTimestamp(), hostNowSeconds());
        frame.name = fmt::format("openni2 frame {}", ref.getFrameIndex());
        last_index = ref.getFrameIndex();
        return frame;
    }

    /// An RGB888 frame as a colour image of the depth's size.
    Result<ColourImage> convertColour(const openni::VideoFrameRef& ref) const {
        if (!ref.isValid()) return corrupt("OpenNI2 returned an invalid colour frame");
        const openni::PixelFormat format = ref.getVideoMode().getPixelFormat();
        if (ref.getSensorType() != openni::SENSOR_COLOR || format != openni::PIXEL_FORMAT_RGB888) {
            return unsupported(std::string("OpenNI2 colour frame has pixel format ") +
                               pixelFormatName(format) + ", not RGB888");
        }
        const int w = ref.getWidth();
        const int h = ref.getHeight();
        if (w <= 0 || h <= 0 || ref.getDataSize() <= 0 || ref.getData() == nullptr) {
            return corrupt(fmt::format("OpenNI2 colour frame {} is empty ({}x{}, {} bytes)",
                                       ref.getFrameIndex(), w, h, ref.getDataSize()));
        }
        const int stride = ref.getStrideInBytes() > 0 ? ref.getStrideInBytes() : w * 3;
        const int64_t needed = static_cast<int64_t>(stride) * (h - 1) + int64_t{w} * 3;
        if (stride < w * 3 || ref.getDataSize() < needed) {
            return corrupt(fmt::format(
                "OpenNI2 colour frame {} is short: {} bytes (stride {}) for {}x{} RGB888 needs {}",
                ref.getFrameIndex(), ref.getDataSize(), stride, w, h, needed));
        }
        ColourImage colour(w, h);
        const auto* bytes = static_cast<const uint8_t*>(ref.getData());
        for (int v = 0; v < h; ++v) {
            std::memcpy(&colour(0, v), bytes + int64_t{stride} * v, static_cast<size_t>(w) * 3);
        }
        if (w == camera.width && h == camera.height) return colour;
        return dataset::resizeColour(colour, camera.width, camera.height);
    }

    /// Reads the colour frames that are ready, waiting up to `timeout_ms` for the first one; at
    /// most one with `at_most_one` (recordings: in manual playback every wait on a stream that
    /// has no frame plays the next one, so only one wait per depth frame keeps them in step).
    void drainColour(int timeout_ms, bool at_most_one = false) {
        openni::VideoStream* streams[] = {&colour_stream};
        int ready = -1;
        for (int wait = timeout_ms;
             openni::OpenNI::waitForAnyStream(streams, 1, &ready, wait) == openni::STATUS_OK;
             wait = 0) {
            openni::VideoFrameRef ref;
            if (colour_stream.readFrame(&ref) != openni::STATUS_OK) {
                log::warn("OpenNI2 device '{}': reading a colour frame failed: {}", uri,
                          oniError());
                return;
            }
            last_colour_time = Clock::now();
            colour_seen = true;
            auto colour = convertColour(ref);
            if (!colour.isOk()) {
                log::warn("OpenNI2 device '{}': colour frame skipped: {}", uri,
                          colour.status().message());
                continue;
            }
            colour_frames.push_back({ref.getTimestamp(), ref.getFrameIndex(), std::move(*colour)});
            while (colour_frames.size() > 16) colour_frames.pop_front();
            if (at_most_one) return;
        }
    }

    /// The buffered colour frame closest to `depth_us` within `tolerance_us`, or end().
    std::deque<ColourSample>::iterator closestColour(uint64_t depth_us, int64_t tolerance_us) {
        auto best = colour_frames.end();
        int64_t best_difference = tolerance_us + 1;
        for (auto it = colour_frames.begin(); it != colour_frames.end(); ++it) {
            const int64_t difference =
                std::llabs(static_cast<int64_t>(it->timestamp_us) - static_cast<int64_t>(depth_us));
            if (difference < best_difference) {
                best_difference = difference;
                best = it;
            }
        }
        return best;
    }

    /// Pairs the depth frame taken at device time `depth_us` with its colour frame (header).
    void attachColour(uint64_t depth_us, Frame* frame) {
        const int64_t tolerance_us = config.colour_max_difference_us > 0
                                         ? config.colour_max_difference_us
                                         : 500000 / std::max(1, mode.getFps());
        auto best = closestColour(depth_us, tolerance_us);
        if (is_file) {
            // A recording holds colour frame k after depth frame k: one wait plays it.
            if (best == colour_frames.end()) {
                drainColour(std::max(config.colour_wait_ms, 200), /*at_most_one=*/true);
                best = closestColour(depth_us, tolerance_us);
            }
        } else {
            drainColour(0);
            best = closestColour(depth_us, tolerance_us);
        }
        // Waiting longer than half a frame period would let the next depth frame replace one
        // not read yet; a colour stream that never sent a frame, or went silent, is not waited
        // for at all.
        const int wait_ms = std::min(config.colour_wait_ms, 500 / std::max(1, mode.getFps()));
        const auto deadline = Clock::now() + std::chrono::milliseconds(wait_ms);
        const auto newer_exists = [&] {
            return !colour_frames.empty() &&
                   static_cast<int64_t>(colour_frames.back().timestamp_us) >
                       static_cast<int64_t>(depth_us) + tolerance_us;
        };
        while (!is_file && colour_seen && best == colour_frames.end() && !newer_exists() &&
               Clock::now() < deadline &&
               Clock::now() - last_colour_time <
                   std::chrono::milliseconds(config.colour_stall_ms)) {
            drainColour(5);
            best = closestColour(depth_us, tolerance_us);
        }
        if (best != colour_frames.end()) {
            frame->colour = std::move(best->image);
            colour_frames.erase(colour_frames.begin(), best + 1);  // older ones pair with nothing
            ++with_colour;
        } else {
            ++without_colour;
        }
        // Colour frames too old for any later depth frame.
        while (!colour_frames.empty() &&
               static_cast<int64_t>(colour_frames.front().timestamp_us) + tolerance_us <
                   static_cast<int64_t>(depth_us)) {
            colour_frames.pop_front();
        }
    }

    Result<Frame> next() {
        if (config.max_frames > 0 && returned >= config.max_frames) {
            return outOfRange(fmt::format("stopped after {} frames (max_frames)", returned));
        }
        if (is_file && num_recorded >= 0 && returned >= static_cast<size_t>(num_recorded)) {
            return outOfRange(fmt::format("end of recording '{}' ({} frames)", uri, returned));
        }
        if (!open) PLUMB_RETURN_IF_ERROR(reconnect());
        const auto deadline = Clock::now() + std::chrono::milliseconds(config.frame_timeout_ms);
        openni::VideoStream* streams[] = {&stream};
        while (true) {
            if (disconnected) {
                closeDevice();
                return unavailable(fmt::format(
                    "OpenNI2 device '{}' disconnected after {} frames; waiting for it to return",
                    uri, returned));
            }
            int ready = -1;
            if (openni::OpenNI::waitForAnyStream(streams, 1, &ready, 50) == openni::STATUS_OK) {
                break;
            }
            if (Clock::now() >= deadline) {
                if (is_file) {
                    return outOfRange(
                        fmt::format("end of recording '{}' ({} frames)", uri, returned));
                }
                closeDevice();
                return unavailable(fmt::format("no depth frame from OpenNI2 device '{}' in {} ms",
                                               uri, config.frame_timeout_ms));
            }
        }
        openni::VideoFrameRef ref;
        if (stream.readFrame(&ref) != openni::STATUS_OK) {
            return ioError("OpenNI2 readFrame failed on '" + uri + "': " + oniError());
        }
        auto frame = convert(ref);
        if (!frame.isOk()) return frame;
        if (has_colour) attachColour(ref.getTimestamp(), &*frame);
        ++returned;
        return frame;
    }
};

OpenNI2Source::OpenNI2Source(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
OpenNI2Source::~OpenNI2Source() = default;

Result<std::unique_ptr<OpenNI2Source>> OpenNI2Source::open(const OpenNI2Config& config) {
    if (config.frame_timeout_ms <= 0 || config.reconnect_wait_ms < 0) {
        return invalidArgument(
            "OpenNI2 source: frame_timeout_ms must be > 0 and "
            "reconnect_wait_ms >= 0");
    }
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    impl->uri = config.uri;
    impl->is_file = isOniFile(config.uri);
    if (impl->is_file && !std::filesystem::is_regular_file(config.uri)) {
        return notFound("OpenNI2 recording '" + config.uri + "' does not exist");
    }
    auto runtime = Runtime::acquire();
    if (!runtime.isOk()) return runtime.status();
    impl->runtime = std::move(runtime).value();
    if (!impl->is_file) {
        openni::OpenNI::addDeviceConnectedListener(impl.get());
        openni::OpenNI::addDeviceDisconnectedListener(impl.get());
        impl->listening = true;
    }
    PLUMB_RETURN_IF_ERROR(impl->openDevice());
    PLUMB_RETURN_IF_ERROR(impl->setCamera());
    return std::unique_ptr<OpenNI2Source>(new OpenNI2Source(std::move(impl)));
}

const PinholeCamera& OpenNI2Source::camera() const { return impl_->camera; }
Result<Frame> OpenNI2Source::next() { return impl_->next(); }
std::optional<size_t> OpenNI2Source::size() const {
    if (!impl_->is_file || impl_->num_recorded < 0) return std::nullopt;
    size_t n = static_cast<size_t>(impl_->num_recorded);
    if (impl_->config.max_frames > 0) n = std::min(n, impl_->config.max_frames);
    return n;
}
std::string OpenNI2Source::description() const {
    const PinholeCamera& c = impl_->camera;
    std::string colour = ", no colour";
    if (impl_->has_colour) {
        const openni::VideoMode& m = impl_->colour_mode;
        colour = fmt::format(
            ", colour RGB888 {}x{}@{}{}{}{}", m.getResolutionX(), m.getResolutionY(), m.getFps(),
            m.getResolutionX() != c.width || m.getResolutionY() != c.height ? " resized to depth"
                                                                            : "",
            impl_->registered || impl_->is_file ? "" : " (not registered to depth)",
            impl_->colour_synced ? ", frame sync" : ", paired by timestamp");
    } else if (!impl_->colour_problem.empty()) {
        colour = ", no colour (" + impl_->colour_problem + ")";
    }
    return fmt::format("OpenNI2 {} '{}' ({}x{}@{} {}{}, fx={:.1f} fy={:.1f}{})",
                       impl_->is_file ? "recording" : "device", impl_->uri, c.width, c.height,
                       impl_->mode.getFps(), pixelFormatName(impl_->mode.getPixelFormat()),
                       impl_->registered ? ", registered to colour" : "", c.fx, c.fy, colour);
}
const std::string& OpenNI2Source::uri() const { return impl_->uri; }
bool OpenNI2Source::isRecording() const { return impl_->is_file; }
bool OpenNI2Source::connected() const { return impl_->open && !impl_->disconnected; }
int OpenNI2Source::reconnects() const { return impl_->reconnects; }
bool OpenNI2Source::registered() const { return impl_->registered; }
bool OpenNI2Source::hasColour() const { return impl_->has_colour; }
size_t OpenNI2Source::framesWithColour() const { return impl_->with_colour; }
size_t OpenNI2Source::framesWithoutColour() const { return impl_->without_colour; }
int OpenNI2Source::lastDeviceFrameIndex() const { return impl_->last_index; }

Status recordOni(const OpenNI2Config& config, const std::string& path, size_t num_frames) {
    if (isOniFile(config.uri)) return invalidArgument("recordOni records a device, not a file");
    // The recorder is attached before the stream starts, so the recording holds the stream from
    // its first frame (the player numbers frames 1..N in recording order).
    auto runtime = Runtime::acquire();
    if (!runtime.isOk()) return runtime.status();
    OpenNI2Source::Impl impl;
    impl.config = config;
    impl.uri = config.uri;
    PLUMB_RETURN_IF_ERROR(impl.openDevice(/*start=*/false));
    PLUMB_RETURN_IF_ERROR(impl.setCamera());
    openni::Recorder recorder;
    if (recorder.create(path.c_str()) != openni::STATUS_OK) {
        return ioError("OpenNI2 cannot create recording '" + path + "': " + oniError());
    }
    if (recorder.attach(impl.stream, false) != openni::STATUS_OK ||
        (impl.has_colour && recorder.attach(impl.colour_stream, false) != openni::STATUS_OK) ||
        recorder.start() != openni::STATUS_OK) {
        return ioError("OpenNI2 cannot record to '" + path + "': " + oniError());
    }
    if (impl.has_colour && impl.colour_stream.start() != openni::STATUS_OK) {
        return ioError("OpenNI2 cannot start the colour stream of '" + impl.uri +
                       "': " + oniError());
    }
    if (impl.stream.start() != openni::STATUS_OK) {
        return ioError("OpenNI2 cannot start the depth stream of '" + impl.uri +
                       "': " + oniError());
    }
    size_t got = 0;
    Status status;
    while (got < num_frames) {
        auto frame = impl.next();
        if (!frame.isOk()) {
            status =
                Status(frame.status().code(), fmt::format("recording '{}' after {} frames: {}",
                                                          path, got, frame.status().message()));
            break;
        }
        ++got;
    }
    recorder.stop();
    recorder.destroy();
    impl.closeDevice();
    return status;
}

}  // namespace plumb::openni2
