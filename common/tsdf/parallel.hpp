// SPDX-License-Identifier: Apache-2.0
#pragma once

// tsdf::parallelFor is plumb::parallelFor (common/core/parallel.hpp), kept under this name for
// the includes that have not moved to it yet.
//
// Thread-safety: as plumb::parallelFor.

#include "common/core/parallel.hpp"

namespace plumb::tsdf {

using plumb::parallelFor;

}  // namespace plumb::tsdf
