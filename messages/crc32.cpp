// SPDX-License-Identifier: Apache-2.0
#include "messages/crc32.hpp"

#include <array>

namespace plumb::messages {
namespace {

// table[b] = the register after shifting byte b through the reflected polynomial eight times.
constexpr std::array<uint32_t, 256> makeTable() {
    std::array<uint32_t, 256> table{};
    for (uint32_t b = 0; b < 256; ++b) {
        uint32_t r = b;
        for (int k = 0; k < 8; ++k) r = (r & 1u) ? (r >> 1) ^ 0xEDB88320u : r >> 1;
        table[b] = r;
    }
    return table;
}

constexpr std::array<uint32_t, 256> kTable = makeTable();

}  // namespace

uint32_t crc32(std::span<const uint8_t> data, uint32_t crc) {
    uint32_t r = ~crc;
    for (const uint8_t byte : data) r = kTable[(r ^ byte) & 0xFFu] ^ (r >> 8);
    return ~r;
}

}  // namespace plumb::messages
