// SPDX-License-Identifier: Apache-2.0
#pragma once

// Lossless compression of 8-bit RGB images for raw frames on the wire (depth_frame2_t's
// COLOUR_DELTA_RICE), with nothing but the standard library (the device side has no image codecs).
//
// Each sample is predicted from its neighbours in the same channel by the median edge detector of
// LOCO-I / JPEG-LS (Weinberger, Seroussi, Sapiro, IEEE TIP 2000): with a = left, b = above,
// c = upper left, pred = min(a, b) if c >= max(a, b), max(a, b) if c <= min(a, b), else a + b - c;
// the first row predicts from the left (the very first sample from 0), the first column from
// above. The residual e = (x - pred) mod 256, taken as a signed byte, is zig-zag mapped to
// z in [0, 255] (0, -1, 1, -2, ... -> 0, 1, 2, 3, ...) and written as a Rice code with parameter
// k: z >> k one-bits, a zero-bit, then the k low bits of z, most significant first.
//
// Stream layout, for each row (top to bottom) and each channel (R, G, B): one byte k in [0, 7]
// (chosen per row and channel to minimise that row's bits), then the row's `width` codes packed
// most significant bit first, padded with zero bits to a whole byte.
//
// Size: the ICL-NUIM office colour images (640x480) take 44-46 % of the raw 3 bytes a pixel
// (their PNG files about 43 %), encoded in about 13 ms and decoded in 10 ms on one core of the
// development machine. Worst case (noise): 9 bits a sample plus 3 bytes a row.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <cstdint>
#include <span>
#include <vector>

#include "common/core/status.hpp"
#include "common/image/image.hpp"

namespace plumb::messages {

/// Encodes `colour` (non-empty) as described above.
std::vector<uint8_t> encodeColourRice(const ColourImage& colour);

/// Decodes a stream of a `width` x `height` image (both > 0). kCorrupt, naming the row, for a
/// Rice parameter above 7, a code longer than any byte value needs, a truncated stream or
/// trailing bytes; the work is bounded by the stream's length and the image size.
Result<ColourImage> decodeColourRice(std::span<const uint8_t> bytes, int width, int height);

}  // namespace plumb::messages
