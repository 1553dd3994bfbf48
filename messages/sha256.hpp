// SPDX-License-Identifier: Apache-2.0
#pragma once

// SHA-256 (FIPS 180-4) and HMAC-SHA256 (RFC 2104), plus a constant-time comparison for MACs.

#include <array>
#include <cstdint>
#include <span>

namespace plumb::messages {

using Digest256 = std::array<uint8_t, 32>;

/// Incremental SHA-256. Not thread-safe; one object per hash.
class Sha256 {
  public:
    Sha256();
    void update(std::span<const uint8_t> data);
    /// Pads (FIPS 180-4 §5.1.1), returns the digest; the object must not be updated afterwards.
    Digest256 finish();

  private:
    void compress(const uint8_t* block);

    std::array<uint32_t, 8> h_;
    std::array<uint8_t, 64> buffer_{};
    size_t buffered_ = 0;
    uint64_t total_bytes_ = 0;
};

Digest256 sha256(std::span<const uint8_t> data);

/// Incremental HMAC-SHA256: H((K ^ opad) || H((K ^ ipad) || message)), keys longer than the
/// 64-byte block are hashed first (RFC 2104 §2).
class HmacSha256 {
  public:
    explicit HmacSha256(std::span<const uint8_t> key);
    void update(std::span<const uint8_t> data) { inner_.update(data); }
    Digest256 finish();

  private:
    Sha256 inner_;
    std::array<uint8_t, 64> outer_key_{};
};

Digest256 hmacSha256(std::span<const uint8_t> key, std::span<const uint8_t> message);

/// a == b in time that depends only on the lengths (no early exit on the first difference).
bool constantTimeEqual(std::span<const uint8_t> a, std::span<const uint8_t> b);

}  // namespace plumb::messages
