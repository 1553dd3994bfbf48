// SPDX-License-Identifier: Apache-2.0
#include "messages/wire.hpp"

#include <fmt/format.h>

namespace plumb::messages {
namespace {

using F = WireField;

int32_t readI32(const uint8_t* p) {
    return static_cast<int32_t>((uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) |
                                (uint32_t{p[2]} << 8) | uint32_t{p[3]});
}

}  // namespace

template <>
const WireSchema& wireSchema<plumb::device_status_t>() {
    static const WireSchema kSchema{"device_status_t",
                                    {F::kI64, F::kI64, F::kI64, F::kI64, F::kI8, F::kI64, F::kI64,
                                     F::kI32, F::kI32, F::kI32, F::kI64, F::kI64}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::fragment_header_t>() {
    static const WireSchema kSchema{
        "fragment_header_t",
        {F::kI64, F::kI64, F::kI64, F::kI32, F::kI32, F::kI32, F::kI64, F::kI32, F::kI16, F::kI16}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::fragment_chunk_t>() {
    static const WireSchema kSchema{"fragment_chunk_t",
                                    {F::kI64, F::kI64, F::kI64, F::kI32, F::kI32, F::kI32, F::kI32,
                                     F::kI64, F::kI32, F::kI32, F::kCount, F::kBytes}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::fragment_ack_t>() {
    static const WireSchema kSchema{"fragment_ack_t",
                                    {F::kI64, F::kI64, F::kI64, F::kI32, F::kI32, F::kI8}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::retransmit_request_t>() {
    static const WireSchema kSchema{"retransmit_request_t",
                                    {F::kI64, F::kI64, F::kI64, F::kI32, F::kCount, F::kI32Array}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::fragment_backoff_t>() {
    static const WireSchema kSchema{
        "fragment_backoff_t", {F::kI64, F::kI64, F::kI64, F::kI32, F::kI8, F::kI64, F::kString}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::camera_info_t>() {
    static const WireSchema kSchema{"camera_info_t",
                                    {F::kI64, F::kI64, F::kI32, F::kI32, F::kI64, F::kI64, F::kI64,
                                     F::kI64, F::kI64, F::kString}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::depth_frame_t>() {
    static const WireSchema kSchema{
        "depth_frame_t",
        {F::kI64, F::kI64, F::kI64, F::kI32, F::kI32, F::kI64, F::kI8, F::kCount, F::kBytes}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::depth_frame2_t>() {
    static const WireSchema kSchema{"depth_frame2_t",
                                    {F::kI64, F::kI64, F::kI64, F::kI32, F::kI32, F::kI64, F::kI8,
                                     F::kCount, F::kBytes, F::kI8, F::kCount, F::kBytes}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::depth_frame3_t>() {
    // The session id, then a depth_frame2_t's fields (a nested struct carries no hash of its own).
    static const WireSchema kSchema{"depth_frame3_t",
                                    {F::kI64, F::kI64, F::kI64, F::kI64, F::kI32, F::kI32, F::kI64,
                                     F::kI8, F::kCount, F::kBytes, F::kI8, F::kCount, F::kBytes}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::config_snapshot_t>() {
    static const WireSchema kSchema{"config_snapshot_t",
                                    {F::kI64, F::kI64, F::kString, F::kString, F::kString}};
    return kSchema;
}
template <>
const WireSchema& wireSchema<plumb::envelope_t>() {
    static const WireSchema kSchema{
        "envelope_t",
        {F::kI64, F::kI64, F::kI64, F::kI32, F::kCount, F::kBytes, F::kCount, F::kBytes}};
    return kSchema;
}

Status checkWire(const WireSchema& schema, int64_t hash, std::span<const uint8_t> bytes) {
    const size_t n = bytes.size();
    if (n > kMaxMessageBytes) {
        return corrupt(fmt::format("{}: message of {} bytes exceeds the limit of {}", schema.name,
                                   n, kMaxMessageBytes));
    }
    if (n < 8) return corrupt(fmt::format("{}: truncated ({} bytes)", schema.name, n));
    uint64_t h = 0;
    for (size_t i = 0; i < 8; ++i) h = (h << 8) | bytes[i];
    if (static_cast<int64_t>(h) != hash) {
        return corrupt(fmt::format("{}: wrong type (fingerprint {:016x})", schema.name, h));
    }
    size_t pos = 8;
    int64_t count = -1;  // the last kCount, consumed by the next array
    auto need = [&](size_t k, size_t field) -> Status {
        if (n - pos < k) {
            return corrupt(fmt::format("{}: truncated at field {} (byte {} of {})", schema.name,
                                       field, pos, n));
        }
        return Status::ok();
    };
    for (size_t f = 0; f < schema.fields.size(); ++f) {
        switch (schema.fields[f]) {
            case F::kI8:
                PLUMB_RETURN_IF_ERROR(need(1, f));
                pos += 1;
                break;
            case F::kI16:
                PLUMB_RETURN_IF_ERROR(need(2, f));
                pos += 2;
                break;
            case F::kI32:
                PLUMB_RETURN_IF_ERROR(need(4, f));
                pos += 4;
                break;
            case F::kI64:
                PLUMB_RETURN_IF_ERROR(need(8, f));
                pos += 8;
                break;
            case F::kString: {
                PLUMB_RETURN_IF_ERROR(need(4, f));
                const int32_t len = readI32(bytes.data() + pos);
                pos += 4;
                if (len < 1) {
                    return corrupt(
                        fmt::format("{}: string field {} has length {}", schema.name, f, len));
                }
                PLUMB_RETURN_IF_ERROR(need(static_cast<size_t>(len), f));
                if (bytes[pos + static_cast<size_t>(len) - 1] != 0) {
                    return corrupt(
                        fmt::format("{}: string field {} is not terminated", schema.name, f));
                }
                pos += static_cast<size_t>(len);
                break;
            }
            case F::kCount: {
                PLUMB_RETURN_IF_ERROR(need(4, f));
                count = readI32(bytes.data() + pos);
                pos += 4;
                if (count < 0) {
                    return corrupt(fmt::format("{}: negative array count {} at field {}",
                                               schema.name, count, f));
                }
                break;
            }
            case F::kBytes:
            case F::kI32Array: {
                PLUMB_CHECK(count >= 0) << schema.name << ": array field without a count";
                const size_t element = schema.fields[f] == F::kBytes ? 1 : 4;
                const size_t k = static_cast<size_t>(count) * element;
                if (n - pos < k) {
                    return corrupt(
                        fmt::format("{}: array of {} elements at field {} exceeds the {} "
                                    "remaining bytes",
                                    schema.name, count, f, n - pos));
                }
                pos += k;
                count = -1;
                break;
            }
        }
    }
    if (pos != n) {
        return corrupt(fmt::format("{}: {} trailing bytes", schema.name, n - pos));
    }
    return Status::ok();
}

}  // namespace plumb::messages
