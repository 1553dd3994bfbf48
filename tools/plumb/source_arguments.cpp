// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/source_arguments.hpp"

#include "drivers/sim/sim_source.hpp"
#include "tools/plumb/command.hpp"

namespace plumb::tools {

std::optional<int> parseSourceOption(std::string_view command, const std::vector<std::string>& args,
                                     size_t* i, SourceOptions* o, bool* matched) {
    const std::string& a = args[*i];
    auto value = [&](std::string* v) {
        if (*i + 1 >= args.size()) return false;
        *v = args[++*i];
        return true;
    };
    std::string v;
    *matched = true;
    if (a == "--frames") {
        if (!value(&v) || !parseNumber(v, &o->max_frames) || o->max_frames == 0)
            return usageError(command, "--frames needs a positive integer");
    } else if (a == "--intrinsics") {
        if (!value(&o->intrinsics))
            return usageError(command, "--intrinsics needs a preset or a file");
    } else if (a == "--depth-scale") {
        if (!value(&v) || !parseNumber(v, &o->depth_scale) || !(o->depth_scale > 0))
            return usageError(command, "--depth-scale needs a positive number");
    } else if (a == "--seed") {
        if (!value(&v) || !parseNumber(v, &o->seed))
            return usageError(command, "--seed needs a non-negative integer");
    } else if (a == "--depth-calibration") {
        if (!value(&o->depth_calibration))
            return usageError(command, "--depth-calibration needs a value");
        if (Status s = checkDepthCalibration(o->depth_calibration); !s.isOk())
            return usageError(command, s.message());
    } else if (a == "--no-colour") {
        o->colour = false;
    } else if (a == "--noise") {
        if (!value(&o->sim_noise)) return usageError(command, "--noise needs a mode");
        if (Status s = sim::checkNoiseMode(o->sim_noise); !s.isOk())
            return usageError(command, s.message());
    } else {
        *matched = false;
    }
    return std::nullopt;
}

}  // namespace plumb::tools
