// SPDX-License-Identifier: Apache-2.0
#pragma once

// In-memory PNG encoding (libpng) and base64, for images embedded in report.html as
// `data:image/png;base64,...` URIs so the single file works offline. No I/O.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <string>
#include <string_view>

#include "backend/report/mesh_render.hpp"
#include "common/core/status.hpp"

namespace plumb::backend {

/// The PNG file bytes of `image` (8-bit RGB, maximum zlib compression). Errors: an empty or
/// inconsistent image, or libpng failing (its message is returned).
Result<std::string> encodePng(const RgbImage& image);

/// RFC 4648 base64 with padding.
std::string base64(std::string_view bytes);

/// `data:image/png;base64,...` of `image`; empty when it cannot be encoded.
std::string pngDataUri(const RgbImage& image);

}  // namespace plumb::backend
