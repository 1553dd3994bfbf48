// SPDX-License-Identifier: Apache-2.0
#pragma once

// Device side of the fragment protocol. LCM 1.3.1 drops a whole message when one UDP fragment of
// it is lost, so an encoded fragment is split into chunks of at most 64 KB, each with its CRC-32,
// announced by a fragment_header_t. The sender keeps every fragment until the backend acknowledges
// it (after persisting it), resends the chunks the backend asks for (retransmit_request_t) and
// re-announces the fragment when nothing was heard for a while (exponential back-off), which makes
// the backend ask for whatever it still misses or acknowledge again.
//
// Pure: no threads, no clock, no I/O besides Transport::publish. Time is passed in by the owner
// (seconds, any monotonic origin), and the owner routes messages from PLUMB_FRAGMENT_ACK and
// PLUMB_RETRANSMIT to onMessage(). Not thread-safe.

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "messages/transport.hpp"
#include "messages/wire.hpp"

namespace plumb::messages {

struct FragmentSenderConfig {
    /// Identifies this run of the device; fragment ids restart per session.
    int64_t session_id = 0;
    /// Payload bytes per chunk. With the 80-byte chunk header and a 76-byte envelope every LCM
    /// message stays below 64 KiB.
    int32_t chunk_payload_bytes = 60000;
    /// First re-announcement of an unacknowledged fragment after this long without news, seconds.
    double retransmit_timeout_s = 0.5;
    /// Back-off doubles the timeout per unanswered re-announcement, up to this, seconds.
    double max_retransmit_timeout_s = 4.0;
    /// Largest encoded fragment accepted by send(), bytes.
    int64_t max_fragment_bytes = int64_t{256} << 20;
};

struct FragmentSenderStats {
    uint64_t headers_sent = 0;        ///< announcements, first and repeated
    uint64_t chunks_sent = 0;         ///< first transmissions
    uint64_t chunks_resent = 0;       ///< retransmissions on request
    uint64_t acks_received = 0;       ///< valid acknowledgements of in-flight fragments
    uint64_t stale_messages = 0;      ///< acks/requests for other sessions or unknown fragments
    uint64_t malformed_messages = 0;  ///< undecodable or inconsistent acks/requests
    uint64_t publish_errors = 0;      ///< transport refused a message (treated as lost)
    uint64_t backoffs_received = 0;   ///< "cannot store" answers (fragment_backoff_t)
};

class FragmentSender {
  public:
    /// `transport` must outlive the sender. PLUMB_CHECKs an unusable config.
    FragmentSender(FragmentSenderConfig config, Transport& transport);

    /// Announces and sends `encoded` (an encoded fragment) and keeps it until acknowledged.
    /// InvalidArgument when empty, too large, or `fragment_id` is in flight with other bytes
    /// (sending identical bytes again is a no-op).
    Status send(uint32_t fragment_id, std::vector<uint8_t> encoded, double now_s);

    /// Handles a message received on PLUMB_FRAGMENT_ACK, PLUMB_RETRANSMIT or
    /// PLUMB_FRAGMENT_BACKOFF (other channels are ignored). A backoff ("the backend cannot store
    /// for now") postpones the next re-announcement of every fragment of this session by its
    /// retry_after_s (at most kMaxBackoffS); a retransmission request still gets its chunks at
    /// once. Corrupt for malformed messages, which are counted and otherwise ignored.
    Status onMessage(const std::string& channel, std::span<const uint8_t> bytes, double now_s);

    /// Re-announces fragments whose retransmission timeout has expired.
    void poll(double now_s);

    /// Fragments acknowledged as persisted since the last call, in acknowledgement order.
    std::vector<uint32_t> takeAcknowledged();
    /// Fragments the backend refused for good since the last call (the owner keeps them).
    std::vector<uint32_t> takeRejected();

    /// Fragment ids sent and not yet acknowledged, ascending.
    std::vector<uint32_t> inFlight() const;
    size_t numInFlight() const { return pending_.size(); }
    /// The backend's error from the latest backoff (empty: none received).
    const std::string& lastBackoffMessage() const { return last_backoff_message_; }
    /// Longest back-off honoured, seconds (a larger retry_after_s is clamped to it).
    static constexpr double kMaxBackoffS = 300.0;
    const FragmentSenderStats& stats() const { return stats_; }
    const FragmentSenderConfig& config() const { return config_; }

  private:
    struct Pending {
        Bytes bytes;
        uint32_t crc = 0;
        int32_t num_chunks = 0;
        double last_activity_s = 0.0;  ///< last send or request
        int attempts = 0;              ///< re-announcements since the last request
    };

    void publishHeader(uint32_t fragment_id, const Pending& p, int attempt, double now_s);
    Status onBackoff(std::span<const uint8_t> bytes, double now_s);
    void publishChunk(uint32_t fragment_id, const Pending& p, int32_t index, double now_s);
    void publishOrCount(const std::string& channel, const Bytes& bytes);

    FragmentSenderConfig config_;
    Transport& transport_;
    std::map<uint32_t, Pending> pending_;
    std::vector<uint32_t> acknowledged_;
    std::vector<uint32_t> rejected_;
    std::string last_backoff_message_;
    FragmentSenderStats stats_;
    int64_t seq_ = 0;
};

/// Number of chunks an encoded fragment of `total_bytes` needs at `chunk_bytes` per chunk.
int64_t numChunks(int64_t total_bytes, int64_t chunk_bytes);

/// Microseconds for the utime field from the owner's clock in seconds.
int64_t toUtime(double now_s);

}  // namespace plumb::messages
