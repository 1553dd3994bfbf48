// SPDX-License-Identifier: Apache-2.0
#pragma once

// Camera intrinsics stored in a file beside a dataset or named on the command line.
//
// JSON (plumb's own, written by `plumb sim` as `intrinsics.json`):
//   {"width": 640, "height": 480, "fx": 525, "fy": 525, "cx": 319.5, "cy": 239.5,
//    "depth_scale": 1000}
// width/height/fx/fy/cx/cy are required, depth_scale (units per metre) is optional. Open3D's
// PinholeCameraIntrinsic JSON ({"width", "height", "intrinsic_matrix": 9 numbers, column-major})
// is accepted too.
//
// Text (any other extension): whitespace- or comma-separated numbers, '#' starts a comment:
//   4 numbers  fx fy cx cy                 (image size taken from the caller's default)
//   6 numbers  width height fx fy cx cy
//   9 numbers  the 3x3 matrix K, row-major (image size taken from the caller's default)
//
// Thread-safety: the functions keep no state between calls; concurrent calls on different
// files are safe.

#include <filesystem>
#include <optional>

#include "common/camera/pinhole.hpp"
#include "common/core/status.hpp"

namespace plumb::dataset {

struct IntrinsicsFile {
    PinholeCamera camera;               ///< intrinsics and image size
    std::optional<double> depth_scale;  ///< depth units per metre, when the file states it
};

/// Reads an intrinsics file. `default_size` supplies width/height for formats without a size.
/// Errors: kNotFound (missing file), kIoError (unreadable), kCorrupt (malformed; names the file
/// and the field or the number count), kInvalidArgument (non-positive size, zero focal length or
/// non-positive depth scale).
Result<IntrinsicsFile> readIntrinsicsFile(const std::filesystem::path& path,
                                          const PinholeCamera& default_size);

/// Writes plumb's JSON form (all seven fields; `depth_scale` > 0).
Status writeIntrinsicsJson(const std::filesystem::path& path, const PinholeCamera& camera,
                           double depth_scale);

}  // namespace plumb::dataset
