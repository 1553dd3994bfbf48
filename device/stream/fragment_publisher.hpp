// SPDX-License-Identifier: Apache-2.0
#pragma once

// The device's side of the fragment stream: every encoded fragment goes into the spool (on disk
// before submit() returns when there is a spool directory, else in memory) first and leaves it only
// when the backend acknowledges it as persisted; at most `max_in_flight` fragments are on the wire
// at once (messages/fragment_sender.hpp chunks, announces and retransmits them), the others wait in
// the spool. Fragments spooled on disk by an earlier run (other sessions) are sent again first, so
// neither a backend restart nor a device restart loses a fragment.
//
// Pure: no threads, no clock; time is passed in (seconds). The owner routes messages from
// PLUMB_FRAGMENT_ACK, PLUMB_RETRANSMIT and PLUMB_FRAGMENT_BACKOFF to onMessage(). Not
// thread-safe.

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <span>
#include <string>
#include <vector>

#include "device/stream/spool.hpp"
#include "messages/fragment_sender.hpp"
#include "messages/transport.hpp"

namespace plumb::device {

struct PublisherConfig {
    /// This run of the device.
    int64_t session_id = 0;
    /// Chunking and retransmission (session_id is overwritten per session).
    messages::FragmentSenderConfig sender;
    /// Fragments on the wire at once.
    int max_in_flight = 8;
    /// Where unacknowledged fragments wait.
    SpoolConfig spool;
};

struct PublisherStats {
    uint64_t fragments_submitted = 0;  ///< accepted by submit() in this run
    uint64_t fragments_resumed = 0;    ///< found in the disk spool at start (earlier runs)
    uint64_t fragments_acked = 0;      ///< acknowledged as persisted
    uint64_t fragments_rejected = 0;   ///< refused for good by the backend (quarantined)
    uint64_t spool_errors = 0;         ///< spool reads/erases that failed
};

class FragmentPublisher {
  public:
    /// Opens the spool (resuming what an earlier run left on disk). `transport` must outlive
    /// the publisher.
    static Result<std::unique_ptr<FragmentPublisher>> create(PublisherConfig config,
                                                             messages::Transport& transport);

    /// Spools an encoded fragment of this session and sends it when the window allows. IoError
    /// when the spool is full (nothing taken: try again later), InvalidArgument for a fragment id
    /// already submitted with other bytes.
    Status submit(uint32_t fragment_id, std::vector<uint8_t> encoded, double now_s);

    /// Handles a message from PLUMB_FRAGMENT_ACK, PLUMB_RETRANSMIT or PLUMB_FRAGMENT_BACKOFF.
    void onMessage(const std::string& channel, std::span<const uint8_t> bytes, double now_s);

    /// Timers: re-announcements, releasing acknowledged fragments, refilling the window.
    void poll(double now_s);

    /// Fragments not yet acknowledged (spooled or in flight).
    size_t unacknowledged() const { return spool_->size(); }
    /// Fragments the backend refused for good in this run, taken out of the spool into its
    /// quarantine folder (spool directory/quarantine/, each beside a .reason file), ascending.
    const std::vector<messages::FragmentKey>& quarantined() const { return quarantined_; }
    std::filesystem::path quarantineDir() const { return spool_->quarantineDir(); }
    /// Unacknowledged fragments as (session, id), ascending.
    std::vector<messages::FragmentKey> unacknowledgedKeys() const { return spool_->keys(); }
    int64_t spoolBytes() const { return spool_->memoryBytes() + spool_->diskBytes(); }
    size_t inFlight() const { return in_flight_.size(); }
    const PublisherStats& stats() const { return stats_; }
    /// The backend's error from the latest "cannot store" backoff (empty: none).
    std::string lastBackoffMessage() const;
    /// Sender counters summed over sessions.
    messages::FragmentSenderStats senderStats() const;

  private:
    FragmentPublisher(PublisherConfig config, messages::Transport& transport)
        : config_(std::move(config)), transport_(transport) {}
    messages::FragmentSender& senderFor(int64_t session_id);
    void collect();
    void fill(double now_s);

    PublisherConfig config_;
    messages::Transport& transport_;
    std::unique_ptr<Spool> spool_;
    std::map<int64_t, std::unique_ptr<messages::FragmentSender>> senders_;
    std::set<messages::FragmentKey> in_flight_;
    std::set<messages::FragmentKey> rejected_;  ///< refused, but quarantine() failed: not resent
    std::vector<messages::FragmentKey> quarantined_;
    PublisherStats stats_;
};

}  // namespace plumb::device
