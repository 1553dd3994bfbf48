// SPDX-License-Identifier: Apache-2.0
#pragma once

// Encoding and checked decoding of the generated LCM types. The generated decode() trusts array
// counts and string lengths (it allocates from them before checking the buffer length), so every
// message from the network is first walked against a schema of its type: fingerprint, every count
// and length checked against the bytes that remain, no trailing bytes. Only then is the generated
// decode() run. Malformed input yields StatusCode::kCorrupt, never a crash or a large allocation.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <cstddef>
#include <cstdint>
#include <exception>
#include <span>
#include <string>
#include <vector>

#include "common/core/status.hpp"
#include "messages/lcm/plumb/camera_info_t.hpp"
#include "messages/lcm/plumb/config_snapshot_t.hpp"
#include "messages/lcm/plumb/depth_frame2_t.hpp"
#include "messages/lcm/plumb/depth_frame3_t.hpp"
#include "messages/lcm/plumb/depth_frame_t.hpp"
#include "messages/lcm/plumb/device_status_t.hpp"
#include "messages/lcm/plumb/envelope_t.hpp"
#include "messages/lcm/plumb/fragment_ack_t.hpp"
#include "messages/lcm/plumb/fragment_backoff_t.hpp"
#include "messages/lcm/plumb/fragment_chunk_t.hpp"
#include "messages/lcm/plumb/fragment_header_t.hpp"
#include "messages/lcm/plumb/retransmit_request_t.hpp"

namespace plumb::messages {

using Bytes = std::vector<uint8_t>;

/// Largest LCM message plumb accepts from the wire (a 640x480 raw depth frame is 600 KB).
inline constexpr size_t kMaxMessageBytes = 16u << 20;

/// Field kinds of an LCM struct as they appear on the wire (big-endian, no padding).
enum class WireField : uint8_t {
    kI8,       ///< int8_t / byte / boolean
    kI16,      ///< int16_t
    kI32,      ///< int32_t / float
    kI64,      ///< int64_t / double
    kString,   ///< int32 length including the terminating NUL, then the bytes
    kCount,    ///< int32 element count of the next array field (must be >= 0)
    kBytes,    ///< byte array sized by the last kCount
    kI32Array  ///< int32 array sized by the last kCount
};

/// The fields of one LCM type in declaration order.
struct WireSchema {
    const char* name;
    std::vector<WireField> fields;
};

/// Schema of a generated type; specialised for every type in messages/lcm.
template <typename T>
const WireSchema& wireSchema();

template <>
const WireSchema& wireSchema<plumb::device_status_t>();
template <>
const WireSchema& wireSchema<plumb::fragment_header_t>();
template <>
const WireSchema& wireSchema<plumb::fragment_chunk_t>();
template <>
const WireSchema& wireSchema<plumb::fragment_ack_t>();
template <>
const WireSchema& wireSchema<plumb::retransmit_request_t>();
template <>
const WireSchema& wireSchema<plumb::fragment_backoff_t>();
template <>
const WireSchema& wireSchema<plumb::camera_info_t>();
template <>
const WireSchema& wireSchema<plumb::depth_frame_t>();
template <>
const WireSchema& wireSchema<plumb::depth_frame2_t>();
template <>
const WireSchema& wireSchema<plumb::depth_frame3_t>();
template <>
const WireSchema& wireSchema<plumb::config_snapshot_t>();
template <>
const WireSchema& wireSchema<plumb::envelope_t>();

/// Ok when `bytes` is exactly one well-formed message of `schema` with fingerprint `hash`.
Status checkWire(const WireSchema& schema, int64_t hash, std::span<const uint8_t> bytes);

/// True when `bytes` starts with the fingerprint of T (cheap type test before decoding).
template <typename T>
bool hasFingerprint(std::span<const uint8_t> bytes) {
    if (bytes.size() < 8) return false;
    uint64_t h = 0;
    for (int i = 0; i < 8; ++i) h = (h << 8) | bytes[i];
    return static_cast<int64_t>(h) == T::getHash();
}

/// Decodes one message of type T after checking it against its schema.
template <typename T>
Result<T> decodeMessage(std::span<const uint8_t> bytes) {
    const WireSchema& schema = wireSchema<T>();
    PLUMB_RETURN_IF_ERROR(checkWire(schema, T::getHash(), bytes));
    T msg;
    try {
        const int n = msg.decode(bytes.data(), 0, static_cast<int>(bytes.size()));
        if (n < 0 || static_cast<size_t>(n) != bytes.size()) {
            return corrupt(std::string(schema.name) + ": LCM decode failed");
        }
    } catch (const std::exception& e) {
        return corrupt(std::string(schema.name) + ": LCM decode threw: " + e.what());
    }
    return msg;
}

/// Encodes `msg` (fingerprint included). Array counts must match the array sizes (PLUMB_CHECK).
template <typename T>
Bytes encodeMessage(const T& msg) {
    const int size = msg.getEncodedSize();
    PLUMB_CHECK(size > 0) << "LCM encoded size " << size;
    Bytes out(static_cast<size_t>(size));
    const int n = msg.encode(out.data(), 0, size);
    PLUMB_CHECK(n == size) << wireSchema<T>().name << ": encode wrote " << n << " of " << size
                           << " bytes (array count and size disagree?)";
    return out;
}

}  // namespace plumb::messages
