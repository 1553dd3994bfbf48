// SPDX-License-Identifier: Apache-2.0
#pragma once

// Layout files (`layout.json`): one JSON object tagged "format": "plumb-layout-1".
//
//   {
//     "format": "plumb-layout-1",
//     "T_W_L": [[r00, r01, r02, tx], [r10, r11, r12, ty], [r20, r21, r22, tz], [0, 0, 0, 1]],
//     "ceiling_height_m": 2.5,                       // null when the ceiling was not seen
//     "room_polygon_L": [[x, y], ...],               // counter-clockwise seen from above, metres
//     "planes": [
//       {"id": 0, "kind": "floor" | "ceiling" | "wall", "normal_L": [nx, ny, nz], "d_L": d,
//        "start_L": [x, y], "end_L": [x, y], "manhattan_snapped": false}, ...
//     ]
//   }
//
// Every field is required ("ceiling_height_m" may be null: 0 in Layout; older files wrote 0).
// Numbers are written with round-trip precision, so write + read gives back the same doubles bit
// for bit. Reading checks types, finiteness, unit normals (1e-6) and a rigid T_W_L; errors name the
// source and the field ("layout.json: planes[2].normal_L: ...").
//
// Thread-safety: the functions keep no state between calls; concurrent calls on different
// files are safe.

#include <nlohmann/json_fwd.hpp>

#include <filesystem>
#include <string>

#include "common/core/status.hpp"
#include "common/layout/layout.hpp"

namespace plumb::io {

/// The value of the "format" field of every layout file this version writes and reads.
inline constexpr const char* kLayoutFormat = "plumb-layout-1";

/// The JSON object of a layout (for embedding in other documents).
nlohmann::json layoutToJson(const Layout& layout);

/// Parses a layout object; `source` names the document in error messages. Malformed content is
/// kCorrupt (naming the field); another "format" tag is kUnsupported.
Result<Layout> layoutFromJson(const nlohmann::json& json, const std::string& source);

/// Writes `layout` to `path` (indented JSON). kIoError when the file cannot be written.
Status writeLayoutJson(const std::filesystem::path& path, const Layout& layout);

/// Reads a layout file. kNotFound when missing, kCorrupt for invalid JSON or content.
Result<Layout> readLayoutJson(const std::filesystem::path& path);

}  // namespace plumb::io
