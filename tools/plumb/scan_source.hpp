// SPDX-License-Identifier: Apache-2.0
#pragma once

// The frame sources of `plumb fuse`, `plumb reconstruct` and `plumb calibrate`: every URI
// openFrameSource opens (drivers/source.hpp), and
//   store:<fragments dir>[?session=ID]
// the raw frames plumb-backend kept of one session of its fragment store (the newest without
// ?session; backend/ingest/raw_frame_store.hpp), as the device captured them (after its own
// --depth-calibration), so that a live scan can be processed again on the workstation, e.g.
// tracked again and fused with a self-calibrated depth table. Its camera is the camera_info.json
// the ingest wrote beside the store, or --intrinsics PRESET. --depth-calibration applies on top
// of the frames; --depth-scale, --seed and --noise do not apply to it.

#include <memory>
#include <string>

#include "common/frame/frame_source.hpp"
#include "drivers/source.hpp"

namespace plumb::tools {

/// True for a store: URI.
bool isStoreUri(const std::string& uri);

/// The source as the commands name it on their command line: sim:, dataset: and store: URIs as
/// they are, anything else a dataset folder ("dataset:" prefixed).
std::string normaliseScanUri(const std::string& source);

/// checkSourceArguments, and for store: URIs the options that do not apply to them.
Status checkScanSourceArguments(const std::string& uri, const SourceOptions& options);

/// Opens `uri` (see the file comment). A store: URI whose session has frames without a raw
/// frame logs a warning saying how many.
Result<std::unique_ptr<FrameSource>> openScanSource(const std::string& uri,
                                                    const SourceOptions& options);

}  // namespace plumb::tools
