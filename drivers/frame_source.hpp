// SPDX-License-Identifier: Apache-2.0
#pragma once

// The frame vocabulary moved to common/frame/frame_source.hpp (the backend uses it and may not
// include drivers/); this header forwards to it for includes that have not moved yet.

#include "common/frame/frame_source.hpp"
