// SPDX-License-Identifier: Apache-2.0
#include "drivers/usb/usb_devices.hpp"

#include <fmt/format.h>
#include <libusb.h>

#include <atomic>
#include <thread>

#include "common/core/logging.hpp"

namespace plumb::usb {

const std::vector<KnownCamera>& knownDepthCameras() {
    // Vendor/product ids as the devices enumerate (lsusb); vendor-wide rows catch new models.
    static const std::vector<KnownCamera> kCameras = {
        {0x1d27, 0x0600, "PrimeSense Carmine / Asus Xtion PRO", "openni2"},
        {0x1d27, 0x0601, "Asus Xtion PRO LIVE / Carmine 1.09", "openni2"},
        {0x1d27, 0x0609, "PrimeSense Carmine 1.09", "openni2"},
        {0x1d27, 0x0000, "PrimeSense-based sensor", "openni2"},
        {0x2bc5, 0x0401, "Orbbec Astra", "openni2"},
        {0x2bc5, 0x0402, "Orbbec Astra S", "openni2"},
        {0x2bc5, 0x0403, "Orbbec Astra Pro", "openni2"},
        {0x2bc5, 0x0404, "Orbbec Astra Mini", "openni2"},
        {0x2bc5, 0x0407, "Orbbec Astra Mini S", "openni2"},
        {0x2bc5, 0x0000, "Orbbec depth camera", "openni2"},
        {0x045e, 0x02ae, "Microsoft Kinect (Xbox 360) camera", "openni2"},
        {0x045e, 0x02bf, "Microsoft Kinect for Windows camera", "openni2"},
        {0x8086, 0x0aa5, "Intel RealSense F200", "v4l2"},
        {0x8086, 0x0a66, "Intel RealSense SR300", "v4l2"},
        {0x8086, 0x0ad1, "Intel RealSense D400", "v4l2"},
        {0x8086, 0x0ad2, "Intel RealSense D410", "v4l2"},
        {0x8086, 0x0ad3, "Intel RealSense D415", "v4l2"},
        {0x8086, 0x0ad6, "Intel RealSense USB2 D400", "v4l2"},
        {0x8086, 0x0b07, "Intel RealSense D435", "v4l2"},
        {0x8086, 0x0b3a, "Intel RealSense D435i", "v4l2"},
        {0x8086, 0x0b5c, "Intel RealSense D455", "v4l2"},
        {0x8086, 0x0b64, "Intel RealSense L515", "v4l2"},
    };
    return kCameras;
}

const KnownCamera* matchDepthCamera(uint16_t vendor_id, uint16_t product_id) {
    const KnownCamera* vendor_match = nullptr;
    for (const auto& c : knownDepthCameras()) {
        if (c.vendor_id != vendor_id) continue;
        if (c.product_id == product_id) return &c;
        if (c.product_id == 0) vendor_match = &c;
    }
    return vendor_match;
}

std::string toString(const UsbCamera& c) {
    return fmt::format("{:04x}:{:04x} bus {} addr {} {} ({})", c.vendor_id, c.product_id, c.bus,
                       c.address, c.name, c.api);
}

namespace {

UsbCamera describe(const KnownCamera& known, uint16_t vid, uint16_t pid, int bus, int address) {
    return {vid, pid, bus, address, known.name, known.api};
}

}  // namespace

Result<std::vector<UsbCamera>> listUsbDepthCameras() {
    libusb_context* ctx = nullptr;
    if (int r = libusb_init(&ctx); r != 0) {
        return unavailable(std::string("libusb cannot start: ") + libusb_strerror(r));
    }
    libusb_device** list = nullptr;
    const ssize_t n = libusb_get_device_list(ctx, &list);
    if (n < 0) {
        libusb_exit(ctx);
        return unavailable(std::string("libusb cannot list devices: ") +
                           libusb_strerror(static_cast<int>(n)));
    }
    std::vector<UsbCamera> out;
    for (ssize_t i = 0; i < n; ++i) {
        libusb_device_descriptor d{};
        if (libusb_get_device_descriptor(list[i], &d) != 0) continue;
        if (const KnownCamera* k = matchDepthCamera(d.idVendor, d.idProduct)) {
            out.push_back(describe(*k, d.idVendor, d.idProduct, libusb_get_bus_number(list[i]),
                                   libusb_get_device_address(list[i])));
        }
    }
    libusb_free_device_list(list, 1);
    libusb_exit(ctx);
    return out;
}

struct HotplugMonitor::Impl {
    libusb_context* ctx = nullptr;
    libusb_hotplug_callback_handle handle = 0;
    bool registered = false;
    std::atomic<bool> stop{false};
    std::thread thread;
};

namespace {

int LIBUSB_CALL onHotplug(libusb_context* /*ctx*/, libusb_device* device,
                          libusb_hotplug_event event, void* user) {
    auto* monitor = static_cast<HotplugMonitor*>(user);
    libusb_device_descriptor d{};
    if (libusb_get_device_descriptor(device, &d) != 0) return 0;
    monitor->dispatch(
        event == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED ? UsbEvent::kArrived : UsbEvent::kLeft,
        d.idVendor, d.idProduct, libusb_get_bus_number(device), libusb_get_device_address(device));
    return 0;  // stay registered
}

}  // namespace

HotplugMonitor::HotplugMonitor(Callback callback)
    : callback_(std::move(callback)), impl_(std::make_unique<Impl>()) {}

bool HotplugMonitor::dispatch(UsbEvent event, uint16_t vendor_id, uint16_t product_id, int bus,
                              int address) {
    const KnownCamera* known = matchDepthCamera(vendor_id, product_id);
    if (known == nullptr || !callback_) return false;
    callback_(event, describe(*known, vendor_id, product_id, bus, address));
    return true;
}

Result<std::unique_ptr<HotplugMonitor>> HotplugMonitor::start(Callback callback) {
    std::unique_ptr<HotplugMonitor> m(new HotplugMonitor(std::move(callback)));
    if (int r = libusb_init(&m->impl_->ctx); r != 0) {
        return unavailable(std::string("libusb cannot start: ") + libusb_strerror(r));
    }
    if (libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) == 0) {
        return unsupported("this libusb has no hot-plug support");
    }
    const int r = libusb_hotplug_register_callback(
        m->impl_->ctx,
        static_cast<libusb_hotplug_event>(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED |
                                          LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
        LIBUSB_HOTPLUG_ENUMERATE, LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY,
        LIBUSB_HOTPLUG_MATCH_ANY, onHotplug, m.get(), &m->impl_->handle);
    if (r != LIBUSB_SUCCESS) {
        return unavailable(std::string("libusb hot-plug registration failed: ") +
                           libusb_strerror(r));
    }
    m->impl_->registered = true;
    Impl* impl = m->impl_.get();
    impl->thread = std::thread([impl] {
        while (!impl->stop) {
            timeval tv{0, 100000};
            libusb_handle_events_timeout_completed(impl->ctx, &tv, nullptr);
        }
    });
    return m;
}

HotplugMonitor::~HotplugMonitor() {
    if (!impl_) return;
    impl_->stop = true;
    if (impl_->registered) libusb_hotplug_deregister_callback(impl_->ctx, impl_->handle);
    if (impl_->thread.joinable()) impl_->thread.join();
    if (impl_->ctx != nullptr) libusb_exit(impl_->ctx);
}

HotplugMonitor::Callback forwardArrivals(std::function<void()> arrived) {
    return [arrived = std::move(arrived)](UsbEvent event, const UsbCamera& camera) {
        if (event == UsbEvent::kArrived) {
            log::info("usb: {} arrived", toString(camera));
            if (arrived) arrived();
        } else {
            log::warn("usb: {} left", toString(camera));
        }
    };
}

HotplugMonitor::Callback forwardArrivals(FrameSource& source) {
    return forwardArrivals([&source] { source.cameraArrived(); });
}

}  // namespace plumb::usb
