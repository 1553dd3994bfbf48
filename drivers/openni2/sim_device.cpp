// SPDX-License-Identifier: Apache-2.0
#include "drivers/openni2/sim_device.hpp"

#include <charconv>
#include <cmath>

namespace plumb::openni2 {
namespace {

template <typename T>
Status parseNumber(const std::string& key, const std::string& text, T* out) {
    const char* end = text.data() + text.size();
    auto [ptr, ec] = std::from_chars(text.data(), end, *out);
    if (ec != std::errc() || ptr != end || text.empty()) {
        return invalidArgument("plumb-sim URI: '" + key + "=" + text + "' is not a number");
    }
    return Status::ok();
}

}  // namespace

bool isSimDeviceUri(const std::string& uri) { return uri.rfind(kSimUriPrefix, 0) == 0; }

Result<SimDeviceSpec> parseSimDeviceUri(const std::string& uri) {
    if (!isSimDeviceUri(uri)) {
        return invalidArgument("'" + uri + "' is not a " + std::string(kSimUriPrefix) + " URI");
    }
    SimDeviceSpec spec;
    const std::string rest = uri.substr(std::string(kSimUriPrefix).size());
    const auto q = rest.find('?');
    spec.scene = rest.substr(0, q);
    if (spec.scene.empty()) return invalidArgument("plumb-sim URI '" + uri + "' names no scene");
    if (q == std::string::npos) return spec;
    std::string query = rest.substr(q + 1);
    size_t pos = 0;
    while (pos <= query.size()) {
        const auto amp = query.find('&', pos);
        const std::string item =
            query.substr(pos, amp == std::string::npos ? std::string::npos : amp - pos);
        pos = amp == std::string::npos ? query.size() + 1 : amp + 1;
        if (item.empty()) continue;
        const auto eq = item.find('=');
        if (eq == std::string::npos) {
            return invalidArgument("plumb-sim URI: '" + item + "' is not key=value");
        }
        const std::string key = item.substr(0, eq);
        const std::string value = item.substr(eq + 1);
        int flag = 0;
        if (key == "frames") {
            PLUMB_RETURN_IF_ERROR(parseNumber(key, value, &spec.frames));
            if (spec.frames == 0) return invalidArgument("plumb-sim URI: frames must be > 0");
        } else if (key == "seed") {
            PLUMB_RETURN_IF_ERROR(parseNumber(key, value, &spec.seed));
        } else if (key == "unplug_at") {
            PLUMB_RETURN_IF_ERROR(parseNumber(key, value, &spec.unplug_at));
        } else if (key == "unplug_frames") {
            PLUMB_RETURN_IF_ERROR(parseNumber(key, value, &spec.unplug_frames));
            if (spec.unplug_frames < 1) {
                return invalidArgument("plumb-sim URI: unplug_frames must be >= 1");
            }
        } else if (key == "registration") {
            PLUMB_RETURN_IF_ERROR(parseNumber(key, value, &flag));
            spec.registration = flag != 0;
        } else if (key == "realtime") {
            PLUMB_RETURN_IF_ERROR(parseNumber(key, value, &flag));
            spec.realtime = flag != 0;
        } else if (key == "fault") {
            if (value != "short" && value != "empty" && value != "format" &&
                value != "colour_short") {
                return invalidArgument(
                    "plumb-sim URI: fault must be short, empty, format or colour_short");
            }
            spec.fault = value;
        } else if (key == "fault_at") {
            PLUMB_RETURN_IF_ERROR(parseNumber(key, value, &spec.fault_at));
        } else if (key == "plug_file") {
            if (value.empty()) return invalidArgument("plumb-sim URI: plug_file needs a path");
            spec.plug_file = value;
        } else if (key == "colour") {
            if (value != "0" && value != "1" && value != "pattern") {
                return invalidArgument("plumb-sim URI: colour must be 0, 1 or pattern");
            }
            spec.colour = value;
        } else if (key == "colour_offset_us") {
            PLUMB_RETURN_IF_ERROR(parseNumber(key, value, &spec.colour_offset_us));
            if (spec.colour_offset_us < 0) {
                return invalidArgument("plumb-sim URI: colour_offset_us must be >= 0");
            }
        } else if (key == "colour_skip") {
            PLUMB_RETURN_IF_ERROR(parseNumber(key, value, &spec.colour_skip));
            if (spec.colour_skip < 0) {
                return invalidArgument("plumb-sim URI: colour_skip must be >= 0");
            }
        } else {
            return invalidArgument("plumb-sim URI: unknown key '" + key +
                                   "' (frames, seed, unplug_at, unplug_frames, registration, "
                                   "realtime, fault, fault_at, plug_file, colour, "
                                   "colour_offset_us, colour_skip)");
        }
    }
    return spec;
}

Result<sim::SimConfig> simConfigFor(const SimDeviceSpec& spec, int width, int height) {
    sim::SimConfig config;
    config.scene = spec.scene;
    config.seed = spec.seed;
    config.trajectory.seed = spec.seed;
    config.trajectory.num_frames = spec.frames;
    const PinholeCamera base;  // PrimeSense 640x480
    if (width * base.height != height * base.width || width <= 0) {
        return unsupported("virtual OpenNI2 device: no " + std::to_string(width) + "x" +
                           std::to_string(height) + " mode (4:3 only)");
    }
    config.camera = base.scaled(static_cast<double>(width) / base.width);
    return config;
}

ColourImage simColourPattern(int64_t k, int width, int height) {
    ColourImage out(width, height);
    for (int v = 0; v < height; ++v) {
        for (int u = 0; u < width; ++u) {
            out(u, v) = Rgb8{static_cast<uint8_t>((u + k) & 0xff), static_cast<uint8_t>(v & 0xff),
                             static_cast<uint8_t>((7 * k) & 0xff)};
        }
    }
    return out;
}

uint16_t depthToPixel(float depth_m, double units_per_m) {
    if (!std::isfinite(depth_m) || depth_m <= 0.0f) return 0;
    const double v = std::round(static_cast<double>(depth_m) * units_per_m);
    if (v < 1.0 || v > 65535.0) return 0;
    return static_cast<uint16_t>(v);
}

}  // namespace plumb::openni2
