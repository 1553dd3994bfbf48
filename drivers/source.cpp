// SPDX-License-Identifier: Apache-2.0
#include "drivers/source.hpp"

#include <filesystem>

#include "drivers/dataset/dataset.hpp"

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
    return unsupported("unknown frame source '" + uri + "' (scheme '" + scheme + "', target '" +
                       rest + "'); use dataset:<dir> or sim:<scene>");
}

}  // namespace plumb
