// SPDX-License-Identifier: Apache-2.0
#pragma once

// The virtual OpenNI2 device: a URI that names a simulated handheld scan, shared by the OpenNI2
// driver plugin that streams it (drivers/openni2/sim_driver) and by tests that compare what came
// through OpenNI2 with the simulator's own frames.
//
//   plumb-sim://<scene>[?frames=N&seed=S&unplug_at=K&unplug_frames=G&registration=1&realtime=0
//                        &fault=F&fault_at=K&plug_file=PATH&colour=C&colour_offset_us=D
//                        &colour_skip=M]
//
// frames        trajectory length (default 300); the camera goes idle after the last frame
// seed          simulator seed (trajectory and noise), default 1
// unplug_at     the device disconnects instead of sending frame K (default: never) ...
// unplug_frames ... and reconnects G frame periods later (default 15); frames K..K+G-1 are lost,
//               like a real camera that keeps moving while it is unplugged
// registration  the device claims depth-to-colour registration support (default 0)
// realtime      pace frames at the video mode's rate (default 1) or send them as fast as rendered
// fault         send frame fault_at damaged, to test consumers: "short" (half the bytes),
//               "empty" (0x0, no bytes) or "format" (labelled RGB888)
// plug_file     the camera is not plugged in until this file exists: opening it fails like
//               opening an absent camera, so a test plugs the camera in by creating the file
// colour        the colour camera: "1" (default) a colour sensor (RGB888, the depth modes'
//               sizes and rates) whose frame k is the simulator's Frame::colour of frame k, sent
//               with depth frame k (same frameIndex and device timestamp) — while the simulator
//               renders no colour, the stream stays silent; "pattern" a test pattern instead,
//               pixel (u, v) of frame k = {(u + k) mod 256, v mod 256, (7 k) mod 256} (not
//               left-right symmetric, different every frame); "0" no colour sensor
// colour_offset_us  colour timestamps run this many microseconds after depth (default 0; real
//               cameras without frame sync differ by a few milliseconds)
// colour_skip   every M-th frame (k = M-1, 2M-1, ...) comes without its colour frame (default
//               0: none), as when a camera's colour stream drops a frame
// fault         also "colour_short": colour frame fault_at carries half its bytes
//
// Thread-safety: pure functions of their arguments: thread-safe.

#include <cstdint>
#include <string>

#include "common/core/status.hpp"
#include "drivers/sim/sim_source.hpp"

namespace plumb::openni2 {

inline constexpr const char* kSimUriPrefix = "plumb-sim://";

struct SimDeviceSpec {
    std::string scene = "living_room";
    size_t frames = 300;
    uint64_t seed = 1;
    int64_t unplug_at = -1;
    int64_t unplug_frames = 15;
    bool registration = false;
    bool realtime = true;
    std::string fault;  ///< "", "short", "empty", "format" or "colour_short"
    int64_t fault_at = -1;
    std::string plug_file;         ///< "" = plugged in from the start
    std::string colour = "1";      ///< "1" (the simulator's colour), "pattern" or "0" (none)
    int64_t colour_offset_us = 0;  ///< colour timestamp minus depth timestamp, microseconds
    int64_t colour_skip = 0;       ///< every this many frames one has no colour (0 = never)
};

/// The colour test pattern of the virtual device (`colour=pattern`) for frame k at width x height.
ColourImage simColourPattern(int64_t k, int width, int height);

/// True when `uri` starts with plumb-sim://.
bool isSimDeviceUri(const std::string& uri);

/// Parses a plumb-sim:// URI; unknown keys and malformed numbers are invalidArgument.
Result<SimDeviceSpec> parseSimDeviceUri(const std::string& uri);

/// The simulator configuration the virtual device renders for a video mode of width x height:
/// the default PrimeSense camera scaled to that size (640x480 fx = 525; 320x240 fx = 262.5).
Result<sim::SimConfig> simConfigFor(const SimDeviceSpec& spec, int width, int height);

/// Depth in metres to an OpenNI depth pixel with `units_per_m` (1000 for DEPTH_1_MM, 10000 for
/// DEPTH_100_UM): rounded; 0, non-finite or out-of-range depth becomes 0 (invalid).
uint16_t depthToPixel(float depth_m, double units_per_m);

/// An OpenNI depth pixel back to metres (0 stays 0).
inline float pixelToDepth(uint16_t pixel, double units_per_m) {
    return static_cast<float>(static_cast<double>(pixel) / units_per_m);
}

}  // namespace plumb::openni2
