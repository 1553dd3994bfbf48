// SPDX-License-Identifier: Apache-2.0
#include "drivers/device_list.hpp"

#include <fmt/format.h>

#include "drivers/openni2/openni2_source.hpp"
#include "drivers/usb/usb_devices.hpp"
#include "drivers/v4l2/v4l2_source.hpp"

namespace plumb {

DeviceListing listDepthDevices() {
    DeviceListing out;
    auto oni = openni2::listDevices();
    if (oni.isOk()) {
        for (const auto& d : *oni) {
            std::string name = d.vendor.empty() ? d.name : d.vendor + " " + d.name;
            if (d.usb_vendor_id != 0) {
                name += fmt::format(" ({:04x}:{:04x})", d.usb_vendor_id, d.usb_product_id);
            }
            out.devices.push_back({"openni2:" + d.uri, name, "openni2"});
        }
    } else {
        out.notes.push_back("openni2: " + oni.status().message());
    }
    for (const auto& node : v4l2::listDepthNodes()) {
        std::string formats;
        for (uint32_t f : node.formats) {
            formats += fmt::format("{}{}", formats.empty() ? "" : ",", v4l2::fourccName(f));
        }
        out.devices.push_back(
            {"v4l2:" + node.path, node.card + " [" + node.driver + ": " + formats + "]", "v4l2"});
    }
    auto usb = usb::listUsbDepthCameras();
    if (usb.isOk()) {
        for (const auto& c : *usb) out.devices.push_back({"", usb::toString(c), "usb"});
    } else {
        out.notes.push_back("usb: " + usb.status().message());
    }
    return out;
}

std::string formatDeviceList(const DeviceListing& listing) {
    std::string text;
    for (const auto& d : listing.devices) {
        text +=
            fmt::format("{:<40} {}  [{}]\n", d.source.empty() ? "(usb)" : d.source, d.name, d.via);
    }
    if (listing.devices.empty()) text += "no depth cameras found\n";
    for (const auto& n : listing.notes) text += "note: " + n + "\n";
    return text;
}

}  // namespace plumb
