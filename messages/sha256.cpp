// SPDX-License-Identifier: Apache-2.0
#include "messages/sha256.hpp"

#include <openssl/core_names.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/params.h>

#include "common/core/check.hpp"

namespace plumb::messages {
namespace {

// libcrypto fails here only when it cannot allocate or lacks SHA-256 (a broken installation).
void checkOk(int ok, const char* what) {
    PLUMB_CHECK(ok == 1) << "libcrypto: " << what << " failed";
}

/// The HMAC implementation, fetched once per process (EVP_MAC_fetch is thread-safe).
EVP_MAC* hmacAlgorithm() {
    static EVP_MAC* mac = [] {
        EVP_MAC* m = EVP_MAC_fetch(nullptr, "HMAC", nullptr);
        PLUMB_CHECK(m != nullptr) << "libcrypto: no HMAC";
        return m;
    }();
    return mac;
}

}  // namespace

struct Sha256::Context {
    EVP_MD_CTX* md = nullptr;
};

Sha256::Sha256() : ctx_(std::make_unique<Context>()) {
    ctx_->md = EVP_MD_CTX_new();
    PLUMB_CHECK(ctx_->md != nullptr) << "libcrypto: EVP_MD_CTX_new failed";
    checkOk(EVP_DigestInit_ex(ctx_->md, EVP_sha256(), nullptr), "EVP_DigestInit_ex");
}

Sha256::~Sha256() { EVP_MD_CTX_free(ctx_->md); }

void Sha256::update(std::span<const uint8_t> data) {
    if (data.empty()) return;
    checkOk(EVP_DigestUpdate(ctx_->md, data.data(), data.size()), "EVP_DigestUpdate");
}

Digest256 Sha256::finish() {
    Digest256 out{};
    unsigned int n = 0;
    checkOk(EVP_DigestFinal_ex(ctx_->md, out.data(), &n), "EVP_DigestFinal_ex");
    PLUMB_CHECK(n == out.size());
    return out;
}

Digest256 sha256(std::span<const uint8_t> data) {
    Sha256 s;
    s.update(data);
    return s.finish();
}

struct HmacSha256::Context {
    EVP_MAC_CTX* mac = nullptr;
};

HmacSha256::HmacSha256(std::span<const uint8_t> key) : ctx_(std::make_unique<Context>()) {
    ctx_->mac = EVP_MAC_CTX_new(hmacAlgorithm());
    PLUMB_CHECK(ctx_->mac != nullptr) << "libcrypto: EVP_MAC_CTX_new failed";
    char digest[] = "SHA256";
    const OSSL_PARAM params[] = {OSSL_PARAM_construct_utf8_string(OSSL_MAC_PARAM_DIGEST, digest, 0),
                                 OSSL_PARAM_END};
    // An empty key is valid HMAC (RFC 2104 pads it with zeros); libcrypto wants a non-null one.
    static const uint8_t kNoKey = 0;
    checkOk(EVP_MAC_init(ctx_->mac, key.empty() ? &kNoKey : key.data(), key.size(), params),
            "EVP_MAC_init");
}

HmacSha256::~HmacSha256() { EVP_MAC_CTX_free(ctx_->mac); }

void HmacSha256::update(std::span<const uint8_t> data) {
    if (data.empty()) return;
    checkOk(EVP_MAC_update(ctx_->mac, data.data(), data.size()), "EVP_MAC_update");
}

Digest256 HmacSha256::finish() {
    Digest256 out{};
    size_t n = 0;
    checkOk(EVP_MAC_final(ctx_->mac, out.data(), &n, out.size()), "EVP_MAC_final");
    PLUMB_CHECK(n == out.size());
    return out;
}

Digest256 hmacSha256(std::span<const uint8_t> key, std::span<const uint8_t> message) {
    HmacSha256 h(key);
    h.update(message);
    return h.finish();
}

bool constantTimeEqual(std::span<const uint8_t> a, std::span<const uint8_t> b) {
    if (a.size() != b.size()) return false;
    if (a.empty()) return true;
    return CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

}  // namespace plumb::messages
