// SPDX-License-Identifier: Apache-2.0
#pragma once

// Compact, self-checking byte encoding of a plumb::Fragment for the wire and the fragment store.
//
// Layout (little-endian, no padding), version 1:
//   u32 magic "PLFR" | u16 version | u16 flags (bit 0 normals, bit 1 colours, bit 2 float32
//   positions) | u32 id | u32 segment | u8 end | f64[12] T_W_F (3x4 row-major) | f64 voxel_size_m
//   | f64 tracking_quality | u32 num_frames | num_frames x { i64 frame_index | f64 timestamp_s |
//   f64[12] T_F_C | u8 tracking_ok } (113 bytes each) | u32 num_points | f64[3] origin_F |
//   f64 step_m | positions | normals | colours | u32 CRC-32 of everything before it.
// Version 2 adds flag bit 3 (odometry information): when set, f64[21] follow tracking_quality,
//   the upper triangle of Fragment::odometry_information row by row. Everything else is as in
//   version 1. A fragment without odometry information is written as version 1, byte for byte as
//   before, so readers of version 1 keep reading it; both versions decode.
//
// Positions: quantised relative to the fragment's bounding box, q = round((p - origin) / step)
// stored as uint16 per axis, with origin = box minimum and step = (largest box side) / 65535. A
// fragment up to 32.77 m across thus has step <= 0.5 mm and a per-axis error <= step / 2 <= 0.25 mm
// (a 5 m fragment: step 0.076 mm, error <= 0.038 mm). Larger fragments fall back to float32
// (flag bit 2, 12 bytes per point, exact).
// Normals: octahedral encoding (Meyer et al. 2010) with two snorm16 values, the rounding chosen
// among the four neighbours to minimise the angle; the angular error is below 1.5e-4 rad
// (0.009 degrees; measured maximum over 200k random directions: about 1.3e-4 rad).
// Colours: 3 bytes, only when the cloud has them and the config keeps them.
// Bytes per point: 6 (positions) + 4 (normals) + 3 (colours) = 13 with everything, 10 without
// colours, 6 for bare points. Frames and poses are doubles, exact.
//
// Decoding validates everything (magic, version, flags, counts against the byte length, CRC,
// finite values, valid rotations, enum ranges) and returns StatusCode::kCorrupt with the reason.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <cstdint>
#include <span>
#include <vector>

#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"

namespace plumb::messages {

inline constexpr uint32_t kFragmentMagic = 0x52464C50u;  // "PLFR" little-endian
/// The newest version written (2, when the fragment carries odometry information; else 1).
inline constexpr uint16_t kFragmentCodecVersion = 2;

struct FragmentCodecConfig {
    /// Keep per-point colours when the cloud has them (3 bytes per point).
    bool include_colors = true;
    /// Largest quantisation step for uint16 positions, metres; bigger fragments use float32.
    double max_position_step_m = 0.0005;
};

/// Encodes `fragment`. InvalidArgument for non-finite points/normals, zero normals, inconsistent
/// attribute counts, invalid poses or more than 2^32 - 1 points or frames.
Result<std::vector<uint8_t>> encodeFragment(const Fragment& fragment,
                                            const FragmentCodecConfig& config = {});

/// Decodes and validates bytes produced by encodeFragment. Decoded normals are unit length.
Result<Fragment> decodeFragment(std::span<const uint8_t> bytes);

/// Quantisation step that encodeFragment uses for `points` (0 when it falls back to float32).
double positionStep(const std::vector<Eigen::Vector3f>& points,
                    const FragmentCodecConfig& config = {});

/// Octahedral encoding of a unit normal into two snorm16 values, and back (unit length).
std::pair<int16_t, int16_t> encodeOctahedral(const Eigen::Vector3f& n);
Eigen::Vector3f decodeOctahedral(int16_t x, int16_t y);

}  // namespace plumb::messages
