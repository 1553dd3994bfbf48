// SPDX-License-Identifier: Apache-2.0
#pragma once

// The backend's receiving end of the fragment stream, shared by `plumb-backend --live`,
// `plumb-backend --log` and `plumb replay`: reassembles fragments from their chunks
// (messages/fragment_assembler.hpp), verifies them (chunk and fragment CRC-32, then a full
// decode), persists each one atomically into the fragment store (messages/fragment_store.hpp)
// and only then acknowledges it; one it cannot store (a full disk) is answered with a
// fragment_backoff_t, so the device waits instead of re-sending at once. On open() it resumes
// from the store: fragments already there are
// acknowledged again when announced and never stored twice. It also keeps the device's latest
// heartbeat, camera info and configuration snapshot, and notices the end of a scan (a heartbeat
// with TRACKING_STOPPED carries the final fragment count). Raw frames (depth_frame3_t on
// PLUMB_RGBD3, with colour and session; depth_frame2_t on PLUMB_RGBD and depth_frame_t on
// PLUMB_DEPTH from older devices) are decoded,
// counted and kept in `<fragments_dir>/raw_frames` (backend/ingest/raw_frame_store.hpp), where the
// final model finds them; the latest one is also kept in memory.
//
// Pure apart from the store: no threads, no clock (time is passed in, seconds), no LCM; the owner
// routes messages (already authenticated) to onMessage() and calls poll(). Not thread-safe.

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "backend/ingest/raw_frame_store.hpp"
#include "common/fragment/fragment.hpp"
#include "messages/auth.hpp"
#include "messages/conversions.hpp"
#include "messages/fragment_assembler.hpp"
#include "messages/fragment_store.hpp"
#include "messages/transport.hpp"

namespace plumb::backend {

struct IngestConfig {
    /// Reassembly limits and the retransmission request interval.
    messages::FragmentAssemblerConfig assembler;
    /// Decode every reassembled fragment before persisting it (rejects undecodable ones).
    bool verify_decode = true;
    /// A fragment that cannot be stored (e.g. a full disk) is answered with a fragment_backoff_t
    /// asking the device to wait this long before re-sending, seconds; doubled per further
    /// failure up to max_cannot_store_backoff_s, reset by the next fragment stored.
    double cannot_store_backoff_s = 2.0;
    double max_cannot_store_backoff_s = 30.0;
    /// Keep the raw frames that decode in `<fragments_dir>/raw_frames`, for the final model
    /// (about 0.7 MB a VGA frame with colour). A frame that cannot be written is counted
    /// (raw_frames.not_kept) and left out; raw frames are never acknowledged. plumb-backend
    /// --no-raw-frames sets it false.
    bool keep_raw_frames = true;
    /// Raw frames are not kept while the raw frame folder's file system has less free space
    /// than this, bytes (counted raw_frames.not_kept_disk, warned about once; kept again when
    /// space comes back): the fragments, which are acknowledged and must be stored, keep their
    /// room. 2 GiB holds the fragments of about 10 minutes of a 30 Hz VGA scan (6.7 MB each).
    /// plumb-backend --raw-frames-reserve GIB sets it.
    uint64_t raw_frames_min_free_bytes = uint64_t{2} << 30;
};

struct IngestCounters {
    uint64_t fragments_received = 0;        ///< new fragments persisted by this process
    uint64_t fragments_resumed = 0;         ///< already in the store at open()
    uint64_t fragments_duplicate = 0;       ///< reassembled again although stored (ignored)
    uint64_t fragments_rejected = 0;        ///< reassembled but undecodable or conflicting
    uint64_t persist_errors = 0;            ///< disk errors (the fragment is received again)
    uint64_t backoffs_sent = 0;             ///< "cannot store" answers (fragment_backoff_t)
    uint64_t chunks_lost = 0;               ///< distinct chunks requested again (lost or late)
    uint64_t chunks_recovered = 0;          ///< of these, received afterwards
    uint64_t status_messages = 0;           ///< device heartbeats
    uint64_t malformed_other = 0;           ///< undecodable status, camera info or config messages
    uint64_t raw_frames = 0;                ///< raw frames decoded (depth_frame3_t, 2_t and _t)
    uint64_t raw_frames_colour = 0;         ///< of these, with colour
    uint64_t raw_frames_malformed = 0;      ///< raw frames that did not decode
    uint64_t raw_frames_kept = 0;           ///< raw frames written to the raw frame store
    uint64_t raw_frames_not_kept = 0;       ///< raw frames not written (disk full, write failed)
    uint64_t raw_frames_not_kept_disk = 0;  ///< of those, for want of free space
};

/// What the ingest knows about one device session (a run of plumb-device).
struct SessionReport {
    int64_t session_id = 0;
    size_t fragments_stored = 0;  ///< in the store (this process or earlier ones)
    /// The fragment count of its end-of-scan heartbeat (TRACKING_STOPPED); none: not announced.
    std::optional<int32_t> fragments_announced;
    bool heard = false;         ///< it sent heartbeats to this process (a live device)
    double last_heard_s = 0.0;  ///< time of its latest heartbeat
    bool complete = false;      ///< end announced and every fragment stored or rejected
};

class Ingestor {
  public:
    /// Opens (creating) the store in `fragments_dir`; sidecar files (camera_info.json,
    /// device_config.toml) go to `sidecar_dir` when not empty. Acks and retransmission requests
    /// are published on `transport`, which must outlive the ingestor.
    static Result<std::unique_ptr<Ingestor>> open(const std::filesystem::path& fragments_dir,
                                                  const std::filesystem::path& sidecar_dir,
                                                  IngestConfig config,
                                                  messages::Transport& transport);

    ~Ingestor();

    /// The channels onMessage() wants.
    static std::vector<std::string> channels();

    /// Handles one (authenticated) message; bad messages are counted, never fatal.
    void onMessage(const std::string& channel, std::span<const uint8_t> bytes, double now_s);
    /// Persists and acknowledges completed fragments, requests stalled chunks.
    void poll(double now_s);

    /// Whether the scans being finished are complete. With `wanted` sessions: each of them
    /// announced its end (TRACKING_STOPPED) and has every fragment stored (or rejected for good).
    /// Without: at least one session did, and so did every session that sent heartbeats, except
    /// those silent for `silence_s` (a device that died: SessionReport says so). Sessions seen
    /// only through resent fragments (a spool of a crashed run) are never waited for.
    bool scanComplete(const std::set<int64_t>& wanted, double now_s, double silence_s) const;
    /// Every session in the store or heard from, ascending.
    std::vector<SessionReport> sessions() const;
    /// Fragments in the store.
    size_t fragmentsInStore() const { return store_->fragments().size(); }
    const messages::FragmentStore& store() const { return *store_; }
    const IngestCounters& counters() const { return counters_; }
    const messages::FragmentAssemblerStats& assemblerStats() const { return assembler_->stats(); }
    const std::optional<messages::CameraInfo>& cameraInfo() const { return camera_; }
    const std::string& deviceConfigToml() const { return device_config_; }
    /// Latest heartbeat per device session.
    const std::map<int64_t, messages::DeviceStatus>& deviceStatus() const { return status_; }
    /// The latest raw frame that decoded (colour empty for depth_frame_t or a colourless frame).
    const std::optional<messages::RawRgbdFrame>& lastRawFrame() const { return last_raw_; }

    /// The metrics.json document (deterministic for a given message sequence).
    nlohmann::json metrics(const messages::AuthStats& auth) const;

  private:
    class CountingTransport;
    Ingestor() = default;
    void onChunk(std::span<const uint8_t> bytes, double now_s);
    void onStatus(std::span<const uint8_t> bytes, double now_s);
    void onCannotStore(const messages::CompletedFragment& c, const Status& error, double now_s);
    void onStored();
    bool sessionComplete(int64_t session) const;
    void onCameraInfo(std::span<const uint8_t> bytes);
    void onConfig(std::span<const uint8_t> bytes);
    void onRawFrame(std::span<const uint8_t> bytes);
    void keepRawFrame(const messages::RawRgbdFrame& frame, std::span<const uint8_t> bytes);
    /// True while the raw frames' file system has less free space than
    /// IngestConfig::raw_frames_min_free_bytes (the fragments, acknowledged once stored, keep
    /// their room); logs each change.
    bool rawFramesShortOfSpace();
    void noteRequest(const std::pair<int64_t, uint32_t>& key, const std::vector<int32_t>& chunks);

    IngestConfig config_;
    std::filesystem::path sidecar_dir_;
    std::unique_ptr<messages::FragmentStore> store_;
    std::unique_ptr<CountingTransport> out_;
    std::unique_ptr<messages::FragmentAssembler> assembler_;
    IngestCounters counters_;
    std::map<std::pair<int64_t, uint32_t>, std::set<int32_t>> requested_;
    std::set<std::pair<int64_t, uint32_t>> rejected_;
    std::map<int64_t, messages::DeviceStatus> status_;
    std::map<int64_t, int32_t> end_of_scan_;  ///< session -> final fragment count
    std::map<int64_t, double> last_heard_;    ///< session -> time of its latest heartbeat
    double backoff_s_ = 0.0;                  ///< current "cannot store" back-off (0: storing)
    uint64_t failed_since_stored_ = 0;        ///< persist failures since the last success
    double last_error_log_s_ = 0.0;
    int64_t backoff_seq_ = 0;
    std::optional<messages::CameraInfo> camera_;
    std::optional<messages::RawRgbdFrame> last_raw_;
    std::filesystem::path raw_frames_dir_;
    std::unique_ptr<RawFrameStore> raw_store_;  ///< opened at the first raw frame
    bool raw_frames_short_of_space_ = false;    ///< the last raw frame was not kept for space
    std::string device_config_;
};

/// The session to reconstruct from `store`: the one `wanted` names (the newest of them when it
/// names several), else the newest in the store. `note` (when not null) is set to a warning
/// listing the store's other sessions and their fragment counts when there are any (empty
/// otherwise). NotFound for an empty store or a wanted session without fragments there.
Result<int64_t> chooseSession(const messages::FragmentStore& store, const std::set<int64_t>& wanted,
                              std::string* note);

/// Loads every fragment of one session from a store (the newest session, or `session_id` when
/// set), decoded, in id order. NotFound for an empty store, Corrupt for a damaged fragment.
Result<std::vector<Fragment>> loadStoredFragments(const messages::FragmentStore& store,
                                                  std::optional<int64_t> session_id = {});

/// The intrinsics from the first readable camera_info.json among `candidates` (written by the
/// ingest from the device's camera info). NotFound when none exists, Corrupt when unreadable.
Result<PinholeCamera> readCameraInfo(const std::vector<std::filesystem::path>& candidates);

}  // namespace plumb::backend
