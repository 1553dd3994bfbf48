// SPDX-License-Identifier: Apache-2.0
#pragma once

// SHA-256 (FIPS 180-4), HMAC-SHA256 (RFC 2104) and a constant-time comparison for MACs, from
// OpenSSL's libcrypto (Debian's libssl-dev): vetted code rather than our own. Thread-safe as
// objects go: one object per hash, used from one thread at a time.

#include <array>
#include <cstdint>
#include <memory>
#include <span>

namespace plumb::messages {

using Digest256 = std::array<uint8_t, 32>;

/// Incremental SHA-256 (EVP_sha256).
class Sha256 {
  public:
    Sha256();
    ~Sha256();
    Sha256(const Sha256&) = delete;
    Sha256& operator=(const Sha256&) = delete;
    void update(std::span<const uint8_t> data);
    /// The digest; the object must not be updated afterwards.
    Digest256 finish();

  private:
    struct Context;
    std::unique_ptr<Context> ctx_;
};

Digest256 sha256(std::span<const uint8_t> data);

/// Incremental HMAC-SHA256 (EVP_MAC "HMAC" with digest SHA256); any key length (keys longer
/// than the 64-byte block are hashed first, RFC 2104 §2).
class HmacSha256 {
  public:
    explicit HmacSha256(std::span<const uint8_t> key);
    ~HmacSha256();
    HmacSha256(const HmacSha256&) = delete;
    HmacSha256& operator=(const HmacSha256&) = delete;
    void update(std::span<const uint8_t> data);
    /// The MAC; the object must not be updated afterwards.
    Digest256 finish();

  private:
    struct Context;
    std::unique_ptr<Context> ctx_;
};

Digest256 hmacSha256(std::span<const uint8_t> key, std::span<const uint8_t> message);

/// a == b in time that depends only on the lengths (CRYPTO_memcmp: no early exit on the first
/// difference).
bool constantTimeEqual(std::span<const uint8_t> a, std::span<const uint8_t> b);

}  // namespace plumb::messages
