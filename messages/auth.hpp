// SPDX-License-Identifier: Apache-2.0
#pragma once

// Message authentication. With a shared key configured every message travels inside an
// envelope_t carrying the sender id, a strictly increasing sequence number, the key id and
//   mac = HMAC-SHA256(key, u32_be(len(channel)) || channel || envelope encoded with mac empty),
// so a message cannot be forged, altered, moved to another channel or replayed. The receiver keeps
// a sliding replay window per sender; unsigned, forged, wrong-key and replayed messages are
// rejected and counted. Without a key messages pass through unchanged.

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "messages/transport.hpp"
#include "messages/wire.hpp"

namespace plumb::messages {

struct AuthConfig {
    /// Shared secret (at least 16 bytes when set); empty = authentication off.
    std::vector<uint8_t> key;
    /// Identifies `key` (lets a deployment rotate keys); received envelopes must carry it.
    int32_t key_id = 1;
    /// This process's sender id. Choose it fresh per process start (e.g. random or start time in
    /// microseconds): (sender_id, seq) must never repeat under one key.
    int64_t sender_id = 0;
    /// Sequence numbers accepted behind the newest one seen from a sender (reordering tolerance).
    int64_t replay_window = 4096;
    /// Senders remembered for replay protection; the least recently heard is forgotten first
    /// (a forgotten sender's old messages would be accepted again, so keep this above the number
    /// of live senders: one device and one backend per deployment).
    size_t max_senders = 64;
};

struct AuthStats {
    uint64_t sent = 0;                ///< envelopes published
    uint64_t accepted = 0;            ///< envelopes verified and passed on
    uint64_t rejected_unsigned = 0;   ///< not an envelope, or a malformed one
    uint64_t rejected_wrong_key = 0;  ///< envelope names a key id we do not hold
    uint64_t rejected_forged = 0;     ///< MAC mismatch
    uint64_t rejected_replayed = 0;   ///< (sender, seq) seen before or older than the window

    uint64_t rejected() const {
        return rejected_unsigned + rejected_wrong_key + rejected_forged + rejected_replayed;
    }
};

/// Builds the envelope of `payload` for `channel` (pure; for tests, tools and the transport).
Bytes sealMessage(const std::string& channel, std::span<const uint8_t> payload,
                  std::span<const uint8_t> key, int32_t key_id, int64_t sender_id, int64_t seq,
                  int64_t utime);

/// Remembers which (sender, seq) pairs were accepted. Not thread-safe.
class ReplayGuard {
  public:
    ReplayGuard(int64_t window, size_t max_senders) : window_(window), max_senders_(max_senders) {}
    /// True (and remembered) when (sender, seq) is new and inside the window.
    bool accept(int64_t sender_id, int64_t seq);

  private:
    struct Sender {
        int64_t newest = 0;
        std::set<int64_t> seen;  ///< accepted sequence numbers in (newest - window, newest]
        uint64_t last_used = 0;
    };
    int64_t window_;
    size_t max_senders_;
    uint64_t clock_ = 0;
    std::map<int64_t, Sender> senders_;
};

/// Verifies an envelope received on `channel` and returns its payload. Counts the outcome in
/// `stats`. Corrupt for malformed input, InvalidArgument for a wrong key id, FailedPrecondition for
/// a bad MAC or a replay (the message says which).
Result<Bytes> openMessage(const std::string& channel, std::span<const uint8_t> bytes,
                          std::span<const uint8_t> key, int32_t key_id, ReplayGuard& guard,
                          AuthStats& stats);

/// Wraps another transport: publish() seals, subscribe() handlers only see verified payloads.
/// Pass-through when no key is configured. Not thread-safe (like the transports it wraps).
class AuthenticatedTransport final : public Transport {
  public:
    /// `inner` must outlive this object. PLUMB_CHECKs a key shorter than 16 bytes.
    AuthenticatedTransport(Transport& inner, AuthConfig config);

    Status publish(const std::string& channel, std::span<const uint8_t> bytes) override;
    Status subscribe(const std::string& channel, Handler handler) override;

    /// Time stamp written into envelopes, microseconds (the owner's clock; 0 by default).
    void setTime(int64_t utime) { utime_ = utime; }
    bool enabled() const { return !config_.key.empty(); }
    const AuthStats& stats() const { return stats_; }

  private:
    Transport& inner_;
    AuthConfig config_;
    ReplayGuard guard_;
    AuthStats stats_;
    int64_t next_seq_ = 1;
    int64_t utime_ = 0;
};

}  // namespace plumb::messages
