// SPDX-License-Identifier: Apache-2.0
#pragma once

// Configuration schemas (common/config) of the on-device pipeline: preprocessing, ICP tracking
// and fusion into fragments. FusionConfig is registered as the program configuration "fusion"
// (`plumb config doc fusion`), the configuration of `plumb fuse`.
//
// Thread-safety: plain configuration structs; describe() and validate() touch only their
// argument.

#include "common/config/schema.hpp"
#include "device/preprocess/preprocess.hpp"
#include "device/tracking/icp.hpp"

namespace plumb::device {

struct FusionConfig;

void describe(config::Schema& s, PreprocessConfig& c);
void describe(config::Schema& s, IcpConfig& c);
void describe(config::Schema& s, PhotometricConfig& c);
void describe(config::Schema& s, FusionConfig& c);

}  // namespace plumb::device
