// SPDX-License-Identifier: Apache-2.0
#pragma once

// What plumb-device and plumb-backend need to talk: an LCM transport at a URL that by default
// must keep traffic on this host (ttl=0 or memq), wrapped in message authentication when a shared
// key file is given. Not thread-safe: use from one thread.
//
// Key file: the shared secret as hexadecimal text (at least 32 hex digits = 16 bytes; whitespace
// ignored), e.g. made with `head -c 32 /dev/urandom | xxd -p -c 64 > plumb.key; chmod 600
// plumb.key`.

#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "messages/auth.hpp"
#include "messages/channels.hpp"
#include "messages/lcm_transport.hpp"

namespace plumb::messages {

struct LinkOptions {
    /// LCM URL (default: multicast that stays on this host).
    std::string url = kDefaultLcmUrl;
    /// Shared key file; empty = no authentication.
    std::filesystem::path key_file;
    /// Identifier of the key (both ends must agree).
    int32_t key_id = 1;
    /// Allow a URL that can send packets off this machine (udpm with ttl > 0, udp, tcpq).
    bool allow_remote = false;
    /// udpm URLs without a recv_buf_size option get this one, bytes (0: the system's default,
    /// often 208 KiB). A raw VGA frame is about 0.7 MB in 64 KiB datagrams, so a buffer smaller
    /// than a few frames loses whole messages under load. The kernel caps the request at
    /// net.core.rmem_max; LcmLink::open logs when that is below it.
    int64_t recv_buffer_bytes = 0;
};

/// A key needs at least this many distinct byte values (16 random bytes have about 15).
inline constexpr size_t kMinDistinctKeyBytes = 8;

/// Reads a key file (hex text). InvalidArgument for non-hex content (the message gives the
/// offset, never the content), fewer than 16 bytes, or a weak key (weakKeyReason);
/// NotFound/IoError for an unreadable file. Logs a warning (keyFileModeWarning) when group or
/// others may access the file, as ssh does for private keys. Never logs key material.
Result<std::vector<uint8_t>> readKeyFile(const std::filesystem::path& path);

/// Why `key` is too weak to authenticate with: all zero, every byte the same, or fewer than
/// kMinDistinctKeyBytes distinct byte values. Empty when it is acceptable.
std::string weakKeyReason(std::span<const uint8_t> key);

/// The warning for a key file whose permission bits are `mode` (st_mode): non-empty when its
/// group or others have any access.
std::string keyFileModeWarning(const std::filesystem::path& path, unsigned mode);

/// A fresh sender id for this process (random, non-zero).
int64_t randomSenderId();

class LcmLink {
  public:
    /// Opens LCM (and authentication). InvalidArgument for a URL parseLcmUrl refuses (e.g. a
    /// repeated option), whatever allow_remote says; FailedPrecondition for a URL that can leave
    /// the host (checkStaysOnHost) without allow_remote.
    static Result<std::unique_ptr<LcmLink>> open(const LinkOptions& options);

    /// Publish and subscribe here (authenticated when a key is configured).
    Transport& transport() { return *auth_; }
    /// Dispatches received messages for up to `timeout_ms`.
    Status pump(int timeout_ms);
    bool authenticated() const { return auth_->enabled(); }
    const AuthStats& authStats() const { return auth_->stats(); }
    const std::string& url() const { return lcm_->url(); }

  private:
    LcmLink() = default;
    std::unique_ptr<LcmTransport> lcm_;
    std::unique_ptr<AuthenticatedTransport> auth_;
};

}  // namespace plumb::messages
