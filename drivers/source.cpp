// SPDX-License-Identifier: Apache-2.0
#include "drivers/source.hpp"

#include <filesystem>

#include "drivers/dataset/dataset.hpp"
#include "drivers/sim/sim_source.hpp"

namespace plumb {

Result<std::unique_ptr<FrameSource>> openFrameSource(const std::string& uri,
                                                     const SourceOptions& options) {
    (void)options;
    const auto colon = uri.find(':');
    const std::string scheme = colon == std::string::npos ? "" : uri.substr(0, colon);
    const std::string rest = colon == std::string::npos ? uri : uri.substr(colon + 1);
    if (scheme.empty() && std::filesystem::is_directory(uri)) {
        return openFrameSource("dataset:" + uri, options);
    }
    if (scheme == "dataset") {
        dataset::DatasetConfig config;
        config.intrinsics = options.intrinsics;
        config.depth_scale = options.depth_scale;
        config.max_frames = options.max_frames;
        auto source = dataset::DatasetSource::open(rest, config);
        if (!source.isOk()) return source.status();
        return std::unique_ptr<FrameSource>(std::move(source).value());
    }
    if (scheme == "sim") {
        sim::SimConfig config;
        config.scene = rest;
        config.seed = options.seed;
        config.trajectory.seed = options.seed;
        config.trajectory.num_frames = options.max_frames > 0 ? options.max_frames : 600;
        if (!options.intrinsics.empty()) {
            auto camera = cameraPreset(options.intrinsics);
            if (!camera.isOk()) return camera.status();
            config.camera = *camera;
        }
        auto source = sim::SimSource::create(config);
        if (!source.isOk()) return source.status();
        return std::unique_ptr<FrameSource>(std::move(source).value());
    }
    return unsupported("unknown frame source '" + uri + "' (scheme '" + scheme + "', target '" +
                       rest + "'); use dataset:<dir> or sim:<scene>");
}

}  // namespace plumb
