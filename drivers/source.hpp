// SPDX-License-Identifier: Apache-2.0
#pragma once

// Opens a FrameSource from a URI:
//   dataset:<dir>     recorded dataset, layout detected (drivers/dataset)
//   sim:<scene>       simulated handheld scanner (drivers/sim)
// A bare directory path is taken as dataset:<dir>.

#include <memory>
#include <string>

#include "drivers/frame_source.hpp"

namespace plumb {

struct SourceOptions {
    /// Intrinsics override: a preset name (see cameraPreset) or a file; empty = detect or default.
    std::string intrinsics;
    /// Depth units per metre override; 0 = the dataset's own (TUM/ICL-NUIM 5000, Redwood 1000).
    double depth_scale = 0.0;
    /// Stop after this many frames; 0 = all.
    size_t max_frames = 0;
    /// Seed for sources with randomness (the simulator's noise and hand shake).
    uint64_t seed = 1;
};

Result<std::unique_ptr<FrameSource>> openFrameSource(const std::string& uri,
                                                     const SourceOptions& options = {});

}  // namespace plumb
