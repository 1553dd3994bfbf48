// SPDX-License-Identifier: Apache-2.0
#pragma once

// Backend side of the fragment protocol (see fragment_sender.hpp). Collects the chunks of each
// fragment, verifies every chunk's CRC-32 and the whole fragment's CRC-32, ignores duplicates,
// asks for missing chunks (retransmit_request_t) when a fragment stalls or its sender
// re-announces it, and yields each complete fragment exactly once. The owner persists a yielded
// fragment and then calls acknowledge(); only then is the ack published, so nothing acknowledged
// can be lost. Acks are repeated whenever the sender re-announces a fragment already persisted
// (lost acks, backend restarts: see markPersisted()).
//
// Pure: no threads, no clock, no I/O besides Transport::publish; time is passed in (seconds).
// Memory is bounded by max_buffered_bytes (the stalest partial fragment is dropped beyond it; its
// sender's re-announcement brings it back). Not thread-safe.

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "messages/transport.hpp"
#include "messages/wire.hpp"

namespace plumb::messages {

struct FragmentAssemblerConfig {
    /// Largest encoded fragment accepted, bytes; larger announcements are malformed.
    int64_t max_fragment_bytes = int64_t{256} << 20;
    /// Largest chunk payload accepted, bytes (64 KiB).
    int32_t max_chunk_bytes = 65536;
    /// Bytes held in incomplete fragments before the stalest one is dropped.
    int64_t max_buffered_bytes = int64_t{512} << 20;
    /// Incomplete fragments tracked at once; the stalest is dropped beyond it.
    int32_t max_partial_fragments = 64;
    /// A fragment with missing chunks and no news for this long triggers a request, seconds; also
    /// the shortest interval between two requests or repeated acks for one fragment.
    double request_interval_s = 0.2;
    /// Chunk indices per retransmission request (the rest follow in later requests).
    int32_t max_missing_per_request = 4096;
};

struct FragmentAssemblerStats {
    uint64_t chunks_received = 0;        ///< valid chunks stored
    uint64_t duplicate_chunks = 0;       ///< valid chunks already held or of finished fragments
    uint64_t malformed_messages = 0;     ///< undecodable, absurd sizes, wrong geometry
    uint64_t chunk_crc_failures = 0;     ///< chunk payload does not match its CRC-32
    uint64_t fragment_crc_failures = 0;  ///< reassembled fragment does not match its CRC-32
    uint64_t inconsistent_chunks = 0;    ///< disagree with earlier chunks of the same fragment
    uint64_t fragments_completed = 0;    ///< yielded by takeCompleted()
    uint64_t fragments_evicted = 0;      ///< partial fragments dropped for memory
    uint64_t requests_sent = 0;          ///< retransmission requests published
    uint64_t acks_sent = 0;              ///< acknowledgements published (first and repeated)
};

struct CompletedFragment {
    int64_t session_id = 0;
    uint32_t fragment_id = 0;
    uint32_t crc32 = 0;  ///< CRC-32 of `bytes` (verified)
    Bytes bytes;         ///< the encoded fragment, bit-identical to what the sender sent
};

class FragmentAssembler {
  public:
    /// `transport` must outlive the assembler. PLUMB_CHECKs an unusable config.
    FragmentAssembler(FragmentAssemblerConfig config, Transport& transport);

    /// Handles a message from PLUMB_FRAGMENT_HEADER or PLUMB_FRAGMENT_CHUNK (other channels are
    /// ignored). Corrupt for malformed or failed-CRC messages, which are counted and dropped.
    Status onMessage(const std::string& channel, std::span<const uint8_t> bytes, double now_s);

    /// Requests the missing chunks of fragments that have stalled.
    void poll(double now_s);

    /// Fragments completed since the last call; each fragment is returned once.
    std::vector<CompletedFragment> takeCompleted();

    /// The owner persisted a yielded fragment: publish the ack and remember it as done.
    void acknowledge(int64_t session_id, uint32_t fragment_id, double now_s);
    /// The owner refuses a yielded fragment for good (e.g. it does not decode): publish a
    /// rejection so the sender stops; remembered as done.
    void reject(int64_t session_id, uint32_t fragment_id, double now_s);
    /// Persisting failed (e.g. disk full): forget the fragment; it will be received again.
    void release(int64_t session_id, uint32_t fragment_id);
    /// Resume after a restart: the fragment is already persisted (acked when announced again,
    /// never yielded again).
    void markPersisted(int64_t session_id, uint32_t fragment_id, uint32_t crc32);

    bool isPersisted(int64_t session_id, uint32_t fragment_id) const;
    /// Incomplete fragments currently buffered.
    size_t numPartial() const;
    const FragmentAssemblerStats& stats() const { return stats_; }

  private:
    using Key = std::pair<int64_t, uint32_t>;  // (session, fragment id)
    enum class State { kPartial, kYielded, kDone };
    struct Entry {
        State state = State::kPartial;
        int32_t num_chunks = 0;
        int32_t chunk_bytes = 0;
        int64_t total_bytes = 0;
        uint32_t crc = 0;
        int8_t done_status = 0;  ///< fragment_ack_t status once done
        std::vector<Bytes> chunks;
        int32_t received = 0;
        int64_t buffered = 0;
        double last_news_s = 0.0;        ///< last chunk or announcement
        double last_request_s = -1e300;  ///< last request or repeated ack
    };
    struct Geometry {
        int32_t num_chunks;
        int32_t chunk_bytes;
        int64_t total_bytes;
        uint32_t crc;
    };

    Status checkGeometry(const Geometry& g, int32_t fragment_id) const;
    Status onHeader(std::span<const uint8_t> bytes, double now_s);
    Status onChunk(std::span<const uint8_t> bytes, double now_s);
    Entry& partialFor(const Key& key, const Geometry& g, double now_s);
    void requestMissing(const Key& key, Entry& e, double now_s);
    void publishAck(const Key& key, Entry& e, double now_s);
    void makeRoom(int64_t bytes, const Key& keep);
    bool evictStalest(const Key& keep, bool with_data_only);
    void finishIfComplete(const Key& key, Entry& e);

    FragmentAssemblerConfig config_;
    Transport& transport_;
    std::map<Key, Entry> entries_;
    std::vector<CompletedFragment> completed_;
    FragmentAssemblerStats stats_;
    int64_t buffered_bytes_ = 0;
    int64_t seq_ = 0;
};

}  // namespace plumb::messages
