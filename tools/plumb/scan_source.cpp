// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/scan_source.hpp"

#include <fmt/format.h>

#include <cstdlib>
#include <utility>

#include "common/core/logging.hpp"

#if PLUMB_HAVE_BACKEND
#include "backend/ingest/stored_scan.hpp"
#endif

namespace plumb::tools {
namespace {

constexpr std::string_view kStoreScheme = "store:";

struct StoreUri {
    std::string dir;
    std::optional<int64_t> session;
};

Result<StoreUri> parseStoreUri(const std::string& uri) {
    StoreUri parsed;
    std::string rest = uri.substr(kStoreScheme.size());
    const size_t query = rest.find('?');
    if (query != std::string::npos) {
        const std::string option = rest.substr(query + 1);
        rest.resize(query);
        char* end = nullptr;
        const std::string prefix = "session=";
        const long long id = option.rfind(prefix, 0) == 0
                                 ? std::strtoll(option.c_str() + prefix.size(), &end, 10)
                                 : 0;
        if (end == nullptr || *end != '\0' || id <= 0) {
            return invalidArgument(fmt::format(
                "'{}': a store: URI takes ?session=ID (a positive session id) only", uri));
        }
        parsed.session = id;
    }
    if (rest.empty()) {
        return invalidArgument(
            fmt::format("'{}': store: needs the fragment store's directory", uri));
    }
    parsed.dir = rest;
    return parsed;
}

}  // namespace

bool isStoreUri(const std::string& uri) { return uri.rfind(kStoreScheme, 0) == 0; }

std::string normaliseScanUri(const std::string& source) {
    if (source.rfind("sim:", 0) == 0 || source.rfind("dataset:", 0) == 0 || isStoreUri(source))
        return source;
    return "dataset:" + source;
}

Status checkScanSourceArguments(const std::string& uri, const SourceOptions& options) {
    if (!isStoreUri(uri)) return checkSourceArguments(uri, options);
    auto parsed = parseStoreUri(uri);
    if (!parsed.isOk()) return parsed.status();
    if (!options.intrinsics.empty() && !cameraPreset(options.intrinsics).isOk()) {
        return invalidArgument(fmt::format(
            "intrinsics '{}': a store: source takes a camera preset (its own camera is the "
            "camera_info.json beside the store)",
            options.intrinsics));
    }
    if (options.depth_scale > 0.0) {
        return invalidArgument(
            "--depth-scale does not apply to a store: source (raw frames carry "
            "their depth units)");
    }
    if (!options.sim_noise.empty()) {
        return invalidArgument("--noise applies to the simulator only, not to a store: source");
    }
    return checkDepthCalibration(options.depth_calibration);
}

Result<std::unique_ptr<FrameSource>> openScanSource(const std::string& uri,
                                                    const SourceOptions& options) {
    if (!isStoreUri(uri)) return openFrameSource(uri, options);
    PLUMB_RETURN_IF_ERROR(checkScanSourceArguments(uri, options));
#if PLUMB_HAVE_BACKEND
    auto parsed = parseStoreUri(uri);
    if (!parsed.isOk()) return parsed.status();
    backend::StoredScanOptions store_options;
    store_options.session = parsed->session;
    store_options.max_frames = options.max_frames;
    store_options.colour = options.colour;
    if (!options.intrinsics.empty())
        store_options.camera = cameraPreset(options.intrinsics).value();
    auto scan = backend::openStoredScan(parsed->dir, store_options);
    if (!scan.isOk()) return scan.status();
    if (!scan->note.empty()) log::warn("{}", scan->note);
    return withDepthCalibration(std::move(scan->source), options.depth_calibration);
#else
    return unsupported("store: sources need a build with the backend (" + uri + ")");
#endif
}

}  // namespace plumb::tools
