// SPDX-License-Identifier: Apache-2.0
#include "messages/crc32.hpp"

#include <zlib.h>

#include <algorithm>
#include <limits>

namespace plumb::messages {

uint32_t crc32(std::span<const uint8_t> data, uint32_t crc) {
    uLong r = crc;
    // zlib takes a uInt length: feed larger spans in pieces (the CRC continues across them).
    constexpr size_t kPiece = std::numeric_limits<uInt>::max();
    while (!data.empty()) {
        const size_t n = std::min(data.size(), kPiece);
        r = ::crc32(r, data.data(), static_cast<uInt>(n));
        data = data.subspan(n);
    }
    return static_cast<uint32_t>(r);
}

}  // namespace plumb::messages
