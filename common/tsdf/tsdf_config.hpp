// SPDX-License-Identifier: Apache-2.0
#pragma once

// Configuration schemas (common/config) of the TSDF volume, the raycaster and surface extraction,
// so programs that embed them (`plumb fuse`, `plumb reconstruct`, plumb-device) document and load
// every key.
//
// Thread-safety: plain configuration structs; describe() and validate() touch only their
// argument.

#include "common/config/schema.hpp"
#include "common/tsdf/raycast.hpp"
#include "common/tsdf/surface.hpp"
#include "common/tsdf/tsdf_volume.hpp"

namespace plumb::tsdf {

void describe(config::Schema& s, TsdfConfig& c);
void describe(config::Schema& s, RaycastConfig& c);
void describe(config::Schema& s, SurfaceConfig& c);

}  // namespace plumb::tsdf
