// SPDX-License-Identifier: Apache-2.0
#pragma once

// Every depth camera plumb can read right now, for `plumb-device --list-devices`: OpenNI2
// devices (openni2:<uri>), V4L2 nodes that offer a depth format (v4l2:/dev/videoN), and known
// depth cameras on the USB bus (which may need one of the former to be read). Back-ends that
// cannot run here (no USB subsystem, OpenNI2 without drivers) add a note instead of failing.
//
// Thread-safety: listDepthDevices probes the system and keeps no state; call it from one thread
// at a time (it initialises and shuts down OpenNI2). formatDeviceList is pure.

#include <string>
#include <vector>

namespace plumb {

struct DepthDevice {
    std::string source;  ///< what to pass to --source / openFrameSource, or "" for USB-only rows
    std::string name;
    std::string via;  ///< "openni2", "v4l2" or "usb"
};

struct DeviceListing {
    std::vector<DepthDevice> devices;
    std::vector<std::string> notes;  ///< back-ends that could not be asked, and why
};

DeviceListing listDepthDevices();

/// One device per line ("openni2:plumb-sim://living_room  Simulated scanner (...)  [openni2]"),
/// then the notes; "no depth cameras found" when there are none.
std::string formatDeviceList(const DeviceListing& listing);

}  // namespace plumb
