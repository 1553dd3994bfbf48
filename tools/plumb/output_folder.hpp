// SPDX-License-Identifier: Apache-2.0
#pragma once

// The --out folder of commands that write a whole output folder (`plumb reconstruct`,
// `plumb fuse`), checked before any work.

#include <filesystem>

#include "common/core/status.hpp"

namespace plumb::tools {

/// Makes `out` ready for a new run: created when missing and checked to be writable. An existing
/// file or an unwritable place fails (kInvalidArgument, kIoError; the message names --out). A
/// folder that is not empty fails too, so that an earlier run's files never mix with this one's,
/// unless `force`: then its contents are removed, provided it looks like an earlier plumb run's
/// output (it holds metrics.json, config.toml, fragments.json, fragments/ or resume/); any other
/// folder is left alone and refused.
Status prepareOutputFolder(const std::filesystem::path& out, bool force);

}  // namespace plumb::tools
