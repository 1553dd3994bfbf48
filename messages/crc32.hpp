// SPDX-License-Identifier: Apache-2.0
#pragma once

// CRC-32 as in IEEE 802.3 / zlib / PNG: reflected polynomial 0xEDB88320, initial value and final
// XOR 0xFFFFFFFF. crc32("123456789") == 0xCBF43926. Computed by zlib's crc32() (Debian's
// zlib1g-dev). Thread-safe.

#include <cstdint>
#include <span>

namespace plumb::messages {

/// CRC-32 of `data`, continuing from `crc` (the CRC of the preceding bytes, 0 for none):
/// crc32(b, crc32(a)) == crc32(a || b).
uint32_t crc32(std::span<const uint8_t> data, uint32_t crc = 0);

}  // namespace plumb::messages
