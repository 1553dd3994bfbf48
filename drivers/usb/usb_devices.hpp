// SPDX-License-Identifier: Apache-2.0
#pragma once

// Depth cameras on the USB bus (libusb): the vendor/product ids we know, a listing, and hot-plug
// notifications so a program can start or restart its frame source when a camera arrives or
// leaves. libusb's event thread only calls the user callback; the callback must be thread-safe.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"

namespace plumb::usb {

/// A depth-camera model, or a whole vendor when product_id is 0.
struct KnownCamera {
    uint16_t vendor_id = 0;
    uint16_t product_id = 0;
    const char* name = "";
    const char* api = "";  ///< how plumb reads it: "openni2" or "v4l2"
};

/// PrimeSense/Asus Xtion, Orbbec, Kinect (v1 camera), Intel RealSense (UVC) and Structure.
const std::vector<KnownCamera>& knownDepthCameras();

/// The best match (exact product before vendor-wide), or nullptr.
const KnownCamera* matchDepthCamera(uint16_t vendor_id, uint16_t product_id);

struct UsbCamera {
    uint16_t vendor_id = 0;
    uint16_t product_id = 0;
    int bus = 0;
    int address = 0;
    std::string name;  ///< from KnownCamera
    std::string api;   ///< "openni2" or "v4l2"
};

/// "1d27:0601 bus 1 addr 4 Asus Xtion PRO LIVE (openni2)".
std::string toString(const UsbCamera& camera);

/// Known depth cameras currently on the bus. kUnavailable when libusb cannot start (no USB
/// subsystem, e.g. in a container).
Result<std::vector<UsbCamera>> listUsbDepthCameras();

enum class UsbEvent { kArrived, kLeft };

/// Calls `callback` from libusb's event thread for every known depth camera that arrives or
/// leaves (and, at start, for those already present). Stops and joins in the destructor.
class HotplugMonitor {
  public:
    using Callback = std::function<void(UsbEvent, const UsbCamera&)>;
    static Result<std::unique_ptr<HotplugMonitor>> start(Callback callback);
    ~HotplugMonitor();
    HotplugMonitor(const HotplugMonitor&) = delete;
    HotplugMonitor& operator=(const HotplugMonitor&) = delete;

    /// The filter the libusb callback applies: known cameras reach `callback`, others do not.
    /// Public so tests can drive it without a USB bus. Returns true when the callback ran.
    bool dispatch(UsbEvent event, uint16_t vendor_id, uint16_t product_id, int bus, int address);

    struct Impl;

  private:
    explicit HotplugMonitor(Callback callback);
    Callback callback_;
    std::unique_ptr<Impl> impl_;
};

/// The handler plumb-device installs for a live source: logs every known depth camera that
/// arrives or leaves, and tells `source` when one arrives (FrameSource::cameraArrived), so a
/// source waiting for its unplugged camera reopens it at once. `source` must outlive the monitor.
HotplugMonitor::Callback forwardArrivals(FrameSource& source);

/// The same handler for any receiver: logs arrivals and departures, calls `arrived` on arrivals.
HotplugMonitor::Callback forwardArrivals(std::function<void()> arrived);

}  // namespace plumb::usb
