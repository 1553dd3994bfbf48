// SPDX-License-Identifier: Apache-2.0
// An OpenNI2 driver plugin (OniDriverAPI) whose device is the simulated handheld scanner, so the
// real OpenNI2 path — initialize, enumerate, open, set the video mode, stream, record, play back,
// disconnect and reconnect — runs where no camera exists. Built as libPlumbSimDevice.so.0 and put
// into an OpenNI2/Drivers directory next to (a link to) libOpenNI2.so.0; see
// drivers/CMakeLists.txt.
//
// It behaves like a PrimeSense-class RGB-D camera: depth modes 640x480@30 and 320x240@60 in
// DEPTH_1_MM or DEPTH_100_UM, a colour sensor with RGB888 modes of the same sizes and rates
// (unless the URI says colour=0), mirroring ON by default (as PS1080 devices ship), field of view
// reported through HORIZONTAL_FOV/VERTICAL_FOV, device timestamps in microseconds from the start
// of streaming. Frame k of the stream is SimSource::render(k) of the URI's configuration
// (drivers/openni2/sim_device.hpp), frameIndex = k. The depth stream's thread is the camera's
// shutter: it renders frame k and, when the colour stream is started, hands it the frame's colour
// (the simulator's Frame::colour, or the test pattern), which goes out just before the depth
// frame, with the same frameIndex and the depth's timestamp (plus colour_offset_us). Colour
// without a started depth stream sends nothing. No frame sync (enableFrameSync is not supported):
// clients pair by timestamp. The default device is plumb-sim://<scene> with the scene from
// $PLUMB_SIM_DEVICE (default living_room); any other plumb-sim:// URI opens through tryDevice.
//
// We write the C entry points ourselves instead of using ONI_EXPORT_DRIVER, which needs XnLib.

#include <Driver/OniDriverAPI.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

#include "drivers/dataset/depth_png.hpp"
#include "drivers/openni2/sim_device.hpp"
#include "drivers/sim/sim_source.hpp"

namespace plumb::openni2::simdriver {
namespace {

using oni::driver::DeviceBase;
using oni::driver::DriverBase;
using oni::driver::StreamBase;

constexpr OniVideoMode kModes[] = {
    {ONI_PIXEL_FORMAT_DEPTH_1_MM, 640, 480, 30},
    {ONI_PIXEL_FORMAT_DEPTH_1_MM, 320, 240, 60},
    {ONI_PIXEL_FORMAT_DEPTH_100_UM, 640, 480, 30},
    {ONI_PIXEL_FORMAT_DEPTH_100_UM, 320, 240, 60},
};
constexpr int kNumModes = static_cast<int>(sizeof(kModes) / sizeof(kModes[0]));
constexpr OniVideoMode kColourModes[] = {
    {ONI_PIXEL_FORMAT_RGB888, 640, 480, 30},
    {ONI_PIXEL_FORMAT_RGB888, 320, 240, 60},
};
constexpr int kNumColourModes = static_cast<int>(sizeof(kColourModes) / sizeof(kColourModes[0]));

int bytesPerPixel(const OniVideoMode& mode) {
    return mode.pixelFormat == ONI_PIXEL_FORMAT_RGB888 ? 3 : 2;
}

class SimStream;

/// Where the depth thread finds the started colour stream of the same device handle.
struct ColourTap {
    std::mutex mutex;
    SimStream* stream = nullptr;  ///< the started colour stream, or null
};

class SimDriver;

/// The physical camera behind a URI: survives device handles, remembers where the scan is.
struct Camera {
    std::string uri;
    SimDeviceSpec spec;
    OniDeviceInfo info{};
    std::mutex mutex;
    int64_t next_index = 0;    ///< sim frame the camera captures next
    bool plugged = true;       ///< false between the unplug and the reconnect
    bool unplug_done = false;  ///< the scheduled unplug happens once
};

class SimStream final : public StreamBase {
  public:
    SimStream(SimDriver* driver, std::shared_ptr<Camera> camera, std::atomic<bool>* device_alive,
              OniSensorType sensor, std::shared_ptr<ColourTap> tap)
        : driver_(driver),
          camera_(std::move(camera)),
          device_alive_(device_alive),
          sensor_(sensor),
          tap_(std::move(tap)),
          mode_(sensor == ONI_SENSOR_COLOR ? kColourModes[0] : kModes[0]) {}
    ~SimStream() override { stop(); }

    OniStatus setProperty(int id, const void* data, int size) override {
        if (id == ONI_STREAM_PROPERTY_VIDEO_MODE) {
            if (size != sizeof(OniVideoMode)) return ONI_STATUS_BAD_PARAMETER;
            const auto* mode = static_cast<const OniVideoMode*>(data);
            const OniVideoMode* modes = sensor_ == ONI_SENSOR_COLOR ? kColourModes : kModes;
            const int count = sensor_ == ONI_SENSOR_COLOR ? kNumColourModes : kNumModes;
            for (int i = 0; i < count; ++i) {
                const OniVideoMode& m = modes[i];
                if (m.pixelFormat == mode->pixelFormat && m.resolutionX == mode->resolutionX &&
                    m.resolutionY == mode->resolutionY && m.fps == mode->fps) {
                    if (running_) return ONI_STATUS_OUT_OF_FLOW;
                    mode_ = m;
                    return ONI_STATUS_OK;
                }
            }
            return ONI_STATUS_NOT_SUPPORTED;
        }
        if (id == ONI_STREAM_PROPERTY_CROPPING) {
            if (size != sizeof(OniCropping)) return ONI_STATUS_BAD_PARAMETER;
            return static_cast<const OniCropping*>(data)->enabled ? ONI_STATUS_NOT_SUPPORTED
                                                                  : ONI_STATUS_OK;
        }
        if (id == ONI_STREAM_PROPERTY_MIRRORING) {
            if (size != sizeof(OniBool)) return ONI_STATUS_BAD_PARAMETER;
            mirror_ = *static_cast<const OniBool*>(data) != 0;
            return ONI_STATUS_OK;
        }
        return ONI_STATUS_NOT_SUPPORTED;
    }

    OniStatus getProperty(int id, void* data, int* size) override {
        const PinholeCamera cam = PinholeCamera().scaled(mode_.resolutionX / 640.0);
        switch (id) {
            case ONI_STREAM_PROPERTY_VIDEO_MODE:
                return put(mode_, data, size);
            case ONI_STREAM_PROPERTY_MIRRORING:
                return put(static_cast<OniBool>(mirror_ ? TRUE : FALSE), data, size);
            case ONI_STREAM_PROPERTY_HORIZONTAL_FOV:
                return put(static_cast<float>(2.0 * std::atan(cam.width / (2.0 * cam.fx))), data,
                           size);
            case ONI_STREAM_PROPERTY_VERTICAL_FOV:
                return put(static_cast<float>(2.0 * std::atan(cam.height / (2.0 * cam.fy))), data,
                           size);
            case ONI_STREAM_PROPERTY_MAX_VALUE:
                return put(static_cast<int>(10000), data, size);
            case ONI_STREAM_PROPERTY_MIN_VALUE:
                return put(static_cast<int>(0), data, size);
            case ONI_STREAM_PROPERTY_STRIDE:
                return put(static_cast<int>(mode_.resolutionX * bytesPerPixel(mode_)), data, size);
            case ONI_STREAM_PROPERTY_CROPPING: {
                // Never cropped; OpenNI2's recorder stores this and its player needs it.
                OniCropping cropping{};
                cropping.enabled = FALSE;
                return put(cropping, data, size);
            }
            default:
                return ONI_STATUS_NOT_SUPPORTED;
        }
    }

    OniBool isPropertySupported(int id) override {
        return id == ONI_STREAM_PROPERTY_VIDEO_MODE || id == ONI_STREAM_PROPERTY_MIRRORING ||
               id == ONI_STREAM_PROPERTY_HORIZONTAL_FOV || id == ONI_STREAM_PROPERTY_VERTICAL_FOV ||
               id == ONI_STREAM_PROPERTY_MAX_VALUE || id == ONI_STREAM_PROPERTY_MIN_VALUE ||
               id == ONI_STREAM_PROPERTY_STRIDE || id == ONI_STREAM_PROPERTY_CROPPING;
    }

    int getRequiredFrameSize() override {
        return mode_.resolutionX * mode_.resolutionY * bytesPerPixel(mode_);
    }

    OniStatus start() override;
    void stop() override {
        if (sensor_ == ONI_SENSOR_COLOR) {
            // Waits for a delivery in progress on the depth thread.
            std::lock_guard lock(tap_->mutex);
            if (tap_->stream == this) tap_->stream = nullptr;
            running_ = false;
            return;
        }
        {
            std::lock_guard lock(mutex_);
            stop_requested_ = true;
        }
        wake_.notify_all();
        if (thread_.joinable()) thread_.join();
        running_ = false;
    }

    /// Colour stream: sends `colour` as frame k with device time `timestamp_us`. Called by the
    /// depth thread with tap_->mutex held.
    void deliverColour(const ColourImage& colour, int64_t k, uint64_t timestamp_us);

  private:
    template <typename T>
    static OniStatus put(const T& value, void* data, int* size) {
        if (*size < static_cast<int>(sizeof(T))) return ONI_STATUS_BAD_PARAMETER;
        std::memcpy(data, &value, sizeof(T));
        *size = sizeof(T);
        return ONI_STATUS_OK;
    }
    void run(std::unique_ptr<sim::SimSource> source);

    SimDriver* driver_;
    std::shared_ptr<Camera> camera_;
    std::atomic<bool>* device_alive_;
    OniSensorType sensor_;
    std::shared_ptr<ColourTap> tap_;
    OniVideoMode mode_;
    bool mirror_ = true;  // PS1080 devices mirror by default; clients turn it off
    std::atomic<bool> running_{false};
    std::mutex mutex_;
    std::condition_variable wake_;
    bool stop_requested_ = false;
    std::thread thread_;
};

class SimDevice final : public DeviceBase {
  public:
    SimDevice(SimDriver* driver, std::shared_ptr<Camera> camera)
        : driver_(driver), camera_(std::move(camera)), tap_(std::make_shared<ColourTap>()) {
        sensors_[0].sensorType = ONI_SENSOR_DEPTH;
        sensors_[0].numSupportedVideoModes = kNumModes;
        sensors_[0].pSupportedVideoModes = modes_;
        for (int i = 0; i < kNumModes; ++i) modes_[i] = kModes[i];
        sensors_[1].sensorType = ONI_SENSOR_COLOR;
        sensors_[1].numSupportedVideoModes = kNumColourModes;
        sensors_[1].pSupportedVideoModes = colour_modes_;
        for (int i = 0; i < kNumColourModes; ++i) colour_modes_[i] = kColourModes[i];
    }

    OniStatus getSensorInfoList(OniSensorInfo** infos, int* count) override {
        *infos = sensors_;
        *count = hasColour() ? 2 : 1;
        return ONI_STATUS_OK;
    }
    StreamBase* createStream(OniSensorType type) override {
        if (!alive_) return nullptr;
        if (type != ONI_SENSOR_DEPTH && !(type == ONI_SENSOR_COLOR && hasColour())) return nullptr;
        return new SimStream(driver_, camera_, &alive_, type, tap_);
    }
    bool hasColour() const { return camera_->spec.colour != "0"; }
    void destroyStream(StreamBase* stream) override { delete stream; }

    OniStatus setProperty(int id, const void* data, int size) override {
        if (id == ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION && camera_->spec.registration) {
            if (size != sizeof(OniImageRegistrationMode)) return ONI_STATUS_BAD_PARAMETER;
            registration_ = *static_cast<const OniImageRegistrationMode*>(data);
            return ONI_STATUS_OK;
        }
        return ONI_STATUS_NOT_SUPPORTED;
    }
    OniStatus getProperty(int id, void* data, int* size) override {
        if (id == ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION && camera_->spec.registration) {
            if (*size < static_cast<int>(sizeof(OniImageRegistrationMode))) {
                return ONI_STATUS_BAD_PARAMETER;
            }
            std::memcpy(data, &registration_, sizeof(registration_));
            *size = sizeof(registration_);
            return ONI_STATUS_OK;
        }
        if (id == ONI_DEVICE_PROPERTY_SERIAL_NUMBER) {
            const std::string serial = "SIM-" + camera_->spec.scene;
            if (*size < static_cast<int>(serial.size() + 1)) return ONI_STATUS_BAD_PARAMETER;
            std::memcpy(data, serial.c_str(), serial.size() + 1);
            *size = static_cast<int>(serial.size() + 1);
            return ONI_STATUS_OK;
        }
        return ONI_STATUS_NOT_SUPPORTED;
    }
    OniBool isPropertySupported(int id) override {
        return (id == ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION && camera_->spec.registration) ||
               id == ONI_DEVICE_PROPERTY_SERIAL_NUMBER;
    }
    OniBool isImageRegistrationModeSupported(OniImageRegistrationMode mode) override {
        return mode == ONI_IMAGE_REGISTRATION_OFF || camera_->spec.registration;
    }

    /// Set false when the camera is unplugged: this handle never streams again.
    std::atomic<bool> alive_{true};

  private:
    SimDriver* driver_;
    std::shared_ptr<Camera> camera_;
    std::shared_ptr<ColourTap> tap_;
    OniSensorInfo sensors_[2]{};
    OniVideoMode modes_[kNumModes];
    OniVideoMode colour_modes_[kNumColourModes];
    OniImageRegistrationMode registration_ = ONI_IMAGE_REGISTRATION_OFF;
};

class SimDriver final : public DriverBase {
  public:
    explicit SimDriver(OniDriverServices* services) : DriverBase(services) {}

    OniStatus initialize(oni::driver::DeviceConnectedCallback connected,
                         oni::driver::DeviceDisconnectedCallback disconnected,
                         oni::driver::DeviceStateChangedCallback state_changed,
                         void* cookie) override {
        DriverBase::initialize(connected, disconnected, state_changed, cookie);
        const char* scene = std::getenv("PLUMB_SIM_DEVICE");
        const std::string uri = std::string(kSimUriPrefix) +
                                (scene != nullptr && *scene != '\0' ? scene : "living_room");
        if (addCamera(uri) == nullptr) return ONI_STATUS_ERROR;
        return ONI_STATUS_OK;
    }

    OniStatus tryDevice(const char* uri) override {
        if (uri == nullptr || !isSimDeviceUri(uri)) return ONI_STATUS_ERROR;
        {
            std::lock_guard lock(mutex_);
            if (cameras_.count(uri) != 0) return ONI_STATUS_ERROR;  // known (maybe unplugged)
        }
        auto spec = parseSimDeviceUri(uri);
        if (spec.isOk() && !spec->plug_file.empty() && !std::filesystem::exists(spec->plug_file)) {
            return ONI_STATUS_ERROR;  // not plugged in yet: OpenNI2 reports no such device
        }
        return addCamera(uri) != nullptr ? ONI_STATUS_OK : ONI_STATUS_ERROR;
    }

    DeviceBase* deviceOpen(const char* uri, const char* /*mode*/) override {
        std::shared_ptr<Camera> camera;
        {
            std::lock_guard lock(mutex_);
            auto it = cameras_.find(uri);
            if (it == cameras_.end()) return nullptr;
            camera = it->second;
        }
        {
            std::lock_guard lock(camera->mutex);
            if (!camera->plugged) return nullptr;
        }
        return new SimDevice(this, camera);
    }

    void deviceClose(DeviceBase* device) override { delete device; }

    void shutdown() override {
        std::vector<std::thread> threads;
        {
            std::lock_guard lock(mutex_);
            shutting_down_ = true;
            threads.swap(replug_threads_);
        }
        replug_wake_.notify_all();
        for (auto& t : threads) t.join();
    }

    /// Called by a stream thread when its camera reaches the scheduled unplug frame.
    void unplug(const std::shared_ptr<Camera>& camera) {
        deviceDisconnected(&camera->info);
        std::lock_guard lock(mutex_);
        if (shutting_down_) return;
        replug_threads_.emplace_back([this, camera] {
            const double period_s = 1.0 / 30.0;
            const auto gap = std::chrono::duration<double>(
                camera->spec.realtime ? camera->spec.unplug_frames * period_s : 0.2);
            {
                std::unique_lock lock(mutex_);
                if (replug_wake_.wait_for(lock, gap, [this] { return shutting_down_; })) return;
            }
            {
                std::lock_guard lock(camera->mutex);
                camera->plugged = true;
            }
            deviceConnected(&camera->info);
        });
    }

  private:
    Camera* addCamera(const std::string& uri) {
        auto spec = parseSimDeviceUri(uri);
        if (!spec.isOk()) {
            getServices().errorLoggerAppend("%s", spec.status().toString().c_str());
            return nullptr;
        }
        auto camera = std::make_shared<Camera>();
        camera->uri = uri;
        camera->spec = *spec;
        std::snprintf(camera->info.uri, sizeof(camera->info.uri), "%s", uri.c_str());
        std::snprintf(camera->info.vendor, sizeof(camera->info.vendor), "plumb");
        std::snprintf(camera->info.name, sizeof(camera->info.name), "Simulated scanner (%s)",
                      spec->scene.c_str());
        camera->info.usbVendorId = 0;
        camera->info.usbProductId = 0;
        {
            std::lock_guard lock(mutex_);
            cameras_[uri] = camera;
        }
        deviceConnected(&camera->info);
        return camera.get();
    }

    std::mutex mutex_;
    std::map<std::string, std::shared_ptr<Camera>> cameras_;
    std::vector<std::thread> replug_threads_;
    std::condition_variable replug_wake_;
    bool shutting_down_ = false;
};

OniStatus SimStream::start() {
    if (running_) return ONI_STATUS_OK;
    if (!device_alive_->load()) return ONI_STATUS_ERROR;
    if (sensor_ == ONI_SENSOR_COLOR) {
        std::lock_guard lock(tap_->mutex);
        tap_->stream = this;
        running_ = true;
        return ONI_STATUS_OK;
    }
    auto config = simConfigFor(camera_->spec, mode_.resolutionX, mode_.resolutionY);
    if (!config.isOk()) return ONI_STATUS_NOT_SUPPORTED;
    auto source = sim::SimSource::create(*config);
    if (!source.isOk()) return ONI_STATUS_ERROR;
    {
        std::lock_guard lock(mutex_);
        stop_requested_ = false;
    }
    running_ = true;
    thread_ = std::thread([this, s = std::move(source).value()]() mutable { run(std::move(s)); });
    return ONI_STATUS_OK;
}

void SimStream::run(std::unique_ptr<sim::SimSource> source) {
    const double units = mode_.pixelFormat == ONI_PIXEL_FORMAT_DEPTH_100_UM ? 10000.0 : 1000.0;
    const auto period = std::chrono::duration<double>(1.0 / mode_.fps);
    const auto start = std::chrono::steady_clock::now();
    uint64_t sent = 0;  // frames of this streaming session: the device clock restarts at 0
    while (true) {
        int64_t k = 0;
        {
            std::lock_guard lock(camera_->mutex);
            if (!camera_->plugged || !device_alive_->load()) return;
            k = camera_->next_index;
            if (k >= static_cast<int64_t>(source->size().value_or(0))) return;  // end: idle
            if (!camera_->unplug_done && camera_->spec.unplug_at >= 0 &&
                k >= camera_->spec.unplug_at) {
                camera_->unplug_done = true;
                camera_->plugged = false;
                camera_->next_index = k + camera_->spec.unplug_frames;  // lost while unplugged
                device_alive_->store(false);
            } else {
                camera_->next_index = k + 1;
            }
        }
        if (!device_alive_->load()) {
            driver_->unplug(camera_);
            return;
        }
        auto rendered = source->render(static_cast<size_t>(k));
        if (!rendered.isOk()) return;
        const DepthImage& depth = rendered->frame.depth;
        OniFrame* frame = getServices().acquireFrame();
        if (frame == nullptr) return;
        const int w = mode_.resolutionX;
        const int h = mode_.resolutionY;
        auto* pixels = static_cast<uint16_t*>(frame->data);
        for (int v = 0; v < h; ++v) {
            for (int u = 0; u < w; ++u) {
                const int src_u = mirror_ ? w - 1 - u : u;
                pixels[v * w + u] = depthToPixel(depth(src_u, v), units);
            }
        }
        frame->dataSize = w * h * 2;
        frame->sensorType = ONI_SENSOR_DEPTH;
        // The device clock: microseconds since this streaming session started. Paced frames are
        // stamped with their slot (start + (sent + 1) periods), as a camera stamps exposures at
        // its frame rate even when they reach the host late; unpaced ones when they are ready.
        const auto now_us = std::chrono::duration_cast<std::chrono::microseconds>(
                                std::chrono::steady_clock::now() - start)
                                .count();
        const auto slot_us =
            std::chrono::duration_cast<std::chrono::microseconds>(period * (sent + 1)).count();
        const auto timestamp = static_cast<uint64_t>(camera_->spec.realtime ? slot_us : now_us);
        frame->timestamp = timestamp;
        frame->frameIndex = static_cast<int>(k);
        frame->width = w;
        frame->height = h;
        frame->videoMode = mode_;
        frame->croppingEnabled = FALSE;
        frame->cropOriginX = 0;
        frame->cropOriginY = 0;
        frame->stride = w * 2;
        if (k == camera_->spec.fault_at) {
            if (camera_->spec.fault == "short") {
                frame->dataSize = w * h;
            } else if (camera_->spec.fault == "empty") {
                frame->dataSize = 0;
                frame->width = 0;
                frame->height = 0;
            } else if (camera_->spec.fault == "format") {
                frame->videoMode.pixelFormat = ONI_PIXEL_FORMAT_RGB888;
            }
        }
        ++sent;
        {
            std::unique_lock lock(mutex_);
            if (camera_->spec.realtime) {
                wake_.wait_until(lock, start + period * sent, [this] { return stop_requested_; });
            }
            if (stop_requested_) {
                lock.unlock();
                getServices().releaseFrame(frame);
                return;
            }
        }
        // The colour camera exposes with the depth camera and its frame k reaches the host
        // first: a reader that has depth frame k finds its colour frame there, however late
        // this thread runs after sending the depth frame.
        const SimDeviceSpec& spec = camera_->spec;
        const bool skipped = spec.colour_skip > 0 && (k + 1) % spec.colour_skip == 0;
        if (spec.colour != "0" && !skipped) {
            std::lock_guard lock(tap_->mutex);
            if (tap_->stream != nullptr) {
                const ColourImage colour =
                    spec.colour == "pattern" ? simColourPattern(k, w, h) : rendered->frame.colour;
                if (!colour.empty()) {
                    tap_->stream->deliverColour(
                        colour, k, timestamp + static_cast<uint64_t>(spec.colour_offset_us));
                }
            }
        }
        raiseNewFrame(frame);
        getServices().releaseFrame(frame);
    }
}

void SimStream::deliverColour(const ColourImage& colour, int64_t k, uint64_t timestamp_us) {
    const int w = mode_.resolutionX;
    const int h = mode_.resolutionY;
    const ColourImage sized =
        colour.width() == w && colour.height() == h ? colour : dataset::resizeColour(colour, w, h);
    OniFrame* frame = getServices().acquireFrame();
    if (frame == nullptr) return;
    auto* pixels = static_cast<uint8_t*>(frame->data);
    for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
            const Rgb8& c = sized(mirror_ ? w - 1 - u : u, v);
            uint8_t* p = pixels + (static_cast<size_t>(v) * w + u) * 3;
            p[0] = c.r;
            p[1] = c.g;
            p[2] = c.b;
        }
    }
    frame->dataSize = w * h * 3;
    frame->sensorType = ONI_SENSOR_COLOR;
    frame->timestamp = timestamp_us;
    frame->frameIndex = static_cast<int>(k);
    frame->width = w;
    frame->height = h;
    frame->videoMode = mode_;
    frame->croppingEnabled = FALSE;
    frame->cropOriginX = 0;
    frame->cropOriginY = 0;
    frame->stride = w * 3;
    if (k == camera_->spec.fault_at && camera_->spec.fault == "colour_short") {
        frame->dataSize = w * h;
    }
    raiseNewFrame(frame);
    getServices().releaseFrame(frame);
}

SimDriver* g_driver = nullptr;

}  // namespace
}  // namespace plumb::openni2::simdriver

// The OniDriverAPI entry points OpenNI2 resolves with dlsym (see OniDriverAPI.h).
using plumb::openni2::simdriver::g_driver;
using plumb::openni2::simdriver::SimDriver;
namespace drv = oni::driver;

extern "C" {
ONI_C_API_EXPORT void oniDriverCreate(OniDriverServices* services) {
    g_driver = new SimDriver(services);
}
ONI_C_API_EXPORT void oniDriverDestroy() {
    g_driver->shutdown();
    delete g_driver;
    g_driver = nullptr;
}
ONI_C_API_EXPORT OniStatus oniDriverInitialize(drv::DeviceConnectedCallback connected,
                                               drv::DeviceDisconnectedCallback disconnected,
                                               drv::DeviceStateChangedCallback state_changed,
                                               void* cookie) {
    return g_driver->initialize(connected, disconnected, state_changed, cookie);
}
ONI_C_API_EXPORT OniStatus oniDriverTryDevice(const char* uri) { return g_driver->tryDevice(uri); }
ONI_C_API_EXPORT drv::DeviceBase* oniDriverDeviceOpen(const char* uri, const char* mode) {
    return g_driver->deviceOpen(uri, mode);
}
ONI_C_API_EXPORT void oniDriverDeviceClose(drv::DeviceBase* device) {
    g_driver->deviceClose(device);
}
ONI_C_API_EXPORT OniStatus oniDriverDeviceGetSensorInfoList(drv::DeviceBase* device,
                                                            OniSensorInfo** infos, int* count) {
    return device->getSensorInfoList(infos, count);
}
ONI_C_API_EXPORT drv::StreamBase* oniDriverDeviceCreateStream(drv::DeviceBase* device,
                                                              OniSensorType type) {
    return device->createStream(type);
}
ONI_C_API_EXPORT void oniDriverDeviceDestroyStream(drv::DeviceBase* device,
                                                   drv::StreamBase* stream) {
    device->destroyStream(stream);
}
ONI_C_API_EXPORT OniStatus oniDriverDeviceSetProperty(drv::DeviceBase* device, int id,
                                                      const void* data, int size) {
    return device->setProperty(id, data, size);
}
ONI_C_API_EXPORT OniStatus oniDriverDeviceGetProperty(drv::DeviceBase* device, int id, void* data,
                                                      int* size) {
    return device->getProperty(id, data, size);
}
ONI_C_API_EXPORT OniBool oniDriverDeviceIsPropertySupported(drv::DeviceBase* device, int id) {
    return device->isPropertySupported(id);
}
ONI_C_API_EXPORT void oniDriverDeviceSetPropertyChangedCallback(
    drv::DeviceBase* device, drv::PropertyChangedCallback handler, void* cookie) {
    device->setPropertyChangedCallback(handler, cookie);
}
ONI_C_API_EXPORT void oniDriverDeviceNotifyAllProperties(drv::DeviceBase* device) {
    device->notifyAllProperties();
}
ONI_C_API_EXPORT OniStatus oniDriverDeviceInvoke(drv::DeviceBase* device, int id, void* data,
                                                 int size) {
    return device->invoke(id, data, size);
}
ONI_C_API_EXPORT OniBool oniDriverDeviceIsCommandSupported(drv::DeviceBase* device, int id) {
    return device->isCommandSupported(id);
}
ONI_C_API_EXPORT OniStatus oniDriverDeviceTryManualTrigger(drv::DeviceBase* device) {
    return device->tryManualTrigger();
}
ONI_C_API_EXPORT OniBool oniDriverDeviceIsImageRegistrationModeSupported(
    drv::DeviceBase* device, OniImageRegistrationMode mode) {
    return device->isImageRegistrationModeSupported(mode);
}
ONI_C_API_EXPORT void oniDriverStreamSetServices(drv::StreamBase* stream,
                                                 OniStreamServices* services) {
    stream->setServices(reinterpret_cast<drv::StreamServices*>(services));
}
ONI_C_API_EXPORT OniStatus oniDriverStreamSetProperty(drv::StreamBase* stream, int id,
                                                      const void* data, int size) {
    return stream->setProperty(id, data, size);
}
ONI_C_API_EXPORT OniStatus oniDriverStreamGetProperty(drv::StreamBase* stream, int id, void* data,
                                                      int* size) {
    return stream->getProperty(id, data, size);
}
ONI_C_API_EXPORT OniBool oniDriverStreamIsPropertySupported(drv::StreamBase* stream, int id) {
    return stream->isPropertySupported(id);
}
ONI_C_API_EXPORT void oniDriverStreamSetPropertyChangedCallback(
    drv::StreamBase* stream, drv::PropertyChangedCallback handler, void* cookie) {
    stream->setPropertyChangedCallback(handler, cookie);
}
ONI_C_API_EXPORT void oniDriverStreamNotifyAllProperties(drv::StreamBase* stream) {
    stream->notifyAllProperties();
}
ONI_C_API_EXPORT OniStatus oniDriverStreamInvoke(drv::StreamBase* stream, int id, void* data,
                                                 int size) {
    return stream->invoke(id, data, size);
}
ONI_C_API_EXPORT OniBool oniDriverStreamIsCommandSupported(drv::StreamBase* stream, int id) {
    return stream->isCommandSupported(id);
}
ONI_C_API_EXPORT OniStatus oniDriverStreamStart(drv::StreamBase* stream) { return stream->start(); }
ONI_C_API_EXPORT void oniDriverStreamStop(drv::StreamBase* stream) { stream->stop(); }
ONI_C_API_EXPORT int oniDriverStreamGetRequiredFrameSize(drv::StreamBase* stream) {
    return stream->getRequiredFrameSize();
}
ONI_C_API_EXPORT void oniDriverStreamSetNewFrameCallback(drv::StreamBase* stream,
                                                         drv::NewFrameCallback handler,
                                                         void* cookie) {
    stream->setNewFrameCallback(handler, cookie);
}
ONI_C_API_EXPORT OniStatus oniDriverStreamConvertDepthToColorCoordinates(drv::StreamBase* depth,
                                                                         drv::StreamBase* color,
                                                                         int x, int y,
                                                                         OniDepthPixel z, int* cx,
                                                                         int* cy) {
    return depth->convertDepthToColorCoordinates(color, x, y, z, cx, cy);
}
ONI_C_API_EXPORT void* oniDriverEnableFrameSync(drv::StreamBase** streams, int count) {
    return g_driver->enableFrameSync(streams, count);
}
ONI_C_API_EXPORT void oniDriverDisableFrameSync(void* group) { g_driver->disableFrameSync(group); }
}
