// SPDX-License-Identifier: Apache-2.0
#pragma once

// Stanford PLY files for point clouds and triangle meshes.
//
// Reading accepts `ascii`, `binary_little_endian` and `binary_big_endian` 1.0 with:
//  - element `vertex`: `x y z` (required), `nx ny nz` (optional, all three), `red green blue`
//    (optional; uchar as is, float/double in [0, 1] scaled to 0..255, other integer types
//    clamped to 0..255). Any other property, scalar or list, is skipped by its type.
//  - element `face`: a list named `vertex_indices` or `vertex_index` with any integer count and
//    index types. Triangles are kept, quads and larger polygons are fan-triangulated
//    (v0 v1 v2, v0 v2 v3, ...). Other face properties are skipped.
//  - any other element is skipped. Scalar types: char/int8, uchar/uint8, short/int16,
//    ushort/uint16, int/int32, uint/uint32, float/float32, double/float64.
// Errors name the file and what is wrong: kNotFound (missing file), kCorrupt (not a PLY, bad
// header, truncated body with the number of elements expected and read, non-numbers, non-finite
// positions or normals, face indices out of range, faces with fewer than 3 vertices),
// kUnsupported (unknown format or property type, missing x/y/z).
//
// Writing produces `ascii` or `binary_little_endian`: float x y z [nx ny nz] [uchar red green
// blue] and, for meshes, `property list uchar int vertex_indices`. ASCII numbers are written with
// the shortest representation that reads back to the same float, so both formats round-trip
// exactly. Positions and normals must be finite and attributes consistent (kInvalidArgument).
//
// Thread-safety: the functions keep no state between calls; concurrent calls on different
// files are safe.

#include <filesystem>

#include "common/cloud/point_cloud.hpp"
#include "common/core/status.hpp"

namespace plumb::io {

enum class PlyFormat { kAscii, kBinaryLittleEndian };

/// Reads the vertices of a PLY file (faces, if any, are validated and then dropped).
Result<PointCloud> readPointCloud(const std::filesystem::path& path);

/// Reads vertices and faces of a PLY file; a file without a face element gives no triangles.
Result<TriangleMesh> readTriangleMesh(const std::filesystem::path& path);

/// Writes a cloud with its normals and colours when present. kIoError if the file cannot be
/// written.
Status writePointCloud(const std::filesystem::path& path, const PointCloud& cloud,
                       PlyFormat format = PlyFormat::kBinaryLittleEndian);

/// Writes a mesh: vertices with normals and colours when present, and its triangles.
Status writeTriangleMesh(const std::filesystem::path& path, const TriangleMesh& mesh,
                         PlyFormat format = PlyFormat::kBinaryLittleEndian);

}  // namespace plumb::io
