// SPDX-License-Identifier: Apache-2.0
#include "backend/ingest/ingestor.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <filesystem>

#include "backend/ingest/raw_frame_store.hpp"
#include "common/core/logging.hpp"
#include "messages/channels.hpp"
#include "messages/files.hpp"
#include "messages/fragment_codec.hpp"
#include "messages/fragment_sender.hpp"  // toUtime
#include "messages/wire.hpp"

namespace plumb::backend {

using Key = std::pair<int64_t, uint32_t>;

// Forwards the assembler's messages and remembers which chunks it asked for again, so the
// metrics can say how many chunks were lost and how many of those were recovered.
class Ingestor::CountingTransport final : public messages::Transport {
  public:
    CountingTransport(messages::Transport& inner, Ingestor& owner) : inner_(inner), owner_(owner) {}
    Status publish(const std::string& channel, std::span<const uint8_t> bytes) override {
        if (channel == messages::kChannelRetransmit) {
            auto req = messages::decodeMessage<plumb::retransmit_request_t>(bytes);
            if (req.isOk() && req->fragment_id >= 0) {
                owner_.noteRequest({req->session_id, static_cast<uint32_t>(req->fragment_id)},
                                   req->missing_chunks);
            }
        }
        return inner_.publish(channel, bytes);
    }
    Status subscribe(const std::string& channel, Handler handler) override {
        return inner_.subscribe(channel, std::move(handler));
    }

  private:
    messages::Transport& inner_;
    Ingestor& owner_;
};

Result<std::unique_ptr<Ingestor>> Ingestor::open(const std::filesystem::path& fragments_dir,
                                                 const std::filesystem::path& sidecar_dir,
                                                 IngestConfig config,
                                                 messages::Transport& transport) {
    std::unique_ptr<Ingestor> in(new Ingestor());
    in->config_ = config;
    in->sidecar_dir_ = sidecar_dir;
    in->raw_frames_dir_ = rawFramesDir(fragments_dir);
    auto store = messages::FragmentStore::open(fragments_dir);
    if (!store.isOk()) return store.status();
    in->store_ = std::move(store).value();
    for (const auto& q : in->store_->quarantined()) {
        log::warn("ingest: damaged file moved aside: {}", q.string());
    }
    in->out_ = std::make_unique<CountingTransport>(transport, *in);
    in->assembler_ = std::make_unique<messages::FragmentAssembler>(config.assembler, *in->out_);
    for (const messages::StoredFragment& f : in->store_->fragments()) {
        in->assembler_->markPersisted(f.session_id, f.fragment_id, f.crc32);
        ++in->counters_.fragments_resumed;
    }
    return in;
}

Ingestor::~Ingestor() = default;

std::vector<std::string> Ingestor::channels() {
    return {messages::kChannelFragmentHeader, messages::kChannelFragmentChunk,
            messages::kChannelStatus,         messages::kChannelCameraInfo,
            messages::kChannelConfig,         messages::kChannelRgbdSession,
            messages::kChannelRgbd,           messages::kChannelDepth};
}

void Ingestor::noteRequest(const Key& key, const std::vector<int32_t>& chunks) {
    auto& set = requested_[key];
    for (int32_t c : chunks) {
        if (set.insert(c).second) ++counters_.chunks_lost;
    }
}

void Ingestor::onMessage(const std::string& channel, std::span<const uint8_t> bytes, double now_s) {
    if (channel == messages::kChannelFragmentChunk) {
        onChunk(bytes, now_s);
    } else if (channel == messages::kChannelFragmentHeader) {
        (void)assembler_->onMessage(channel, bytes, now_s);
    } else if (channel == messages::kChannelStatus) {
        onStatus(bytes, now_s);
    } else if (channel == messages::kChannelCameraInfo) {
        onCameraInfo(bytes);
    } else if (channel == messages::kChannelConfig) {
        onConfig(bytes);
    } else if (channel == messages::kChannelRgbdSession || channel == messages::kChannelRgbd ||
               channel == messages::kChannelDepth) {
        onRawFrame(bytes);
    }
    poll(now_s);
}

void Ingestor::onChunk(std::span<const uint8_t> bytes, double now_s) {
    const uint64_t before = assembler_->stats().chunks_received;
    (void)assembler_->onMessage(messages::kChannelFragmentChunk, bytes, now_s);
    if (assembler_->stats().chunks_received == before || requested_.empty()) return;
    // A new valid chunk: was it one we had asked for?
    auto chunk = messages::decodeMessage<plumb::fragment_chunk_t>(bytes);
    if (!chunk.isOk() || chunk->fragment_id < 0) return;
    auto it = requested_.find({chunk->session_id, static_cast<uint32_t>(chunk->fragment_id)});
    if (it != requested_.end() && it->second.erase(chunk->chunk_index) > 0) {
        ++counters_.chunks_recovered;
    }
}

void Ingestor::onStatus(std::span<const uint8_t> bytes, double now_s) {
    auto msg = messages::decodeMessage<plumb::device_status_t>(bytes);
    if (!msg.isOk()) {
        ++counters_.malformed_other;
        return;
    }
    auto status = messages::fromMessage(*msg);
    if (!status.isOk()) {
        ++counters_.malformed_other;
        return;
    }
    ++counters_.status_messages;
    status_[status->session_id] = *status;
    last_heard_[status->session_id] = now_s;
    if (status->tracking == messages::TrackingState::kStopped) {
        end_of_scan_[status->session_id] = status->fragments_cut;
    }
}

void Ingestor::onRawFrame(std::span<const uint8_t> bytes) {
    auto frame = messages::decodeRawFrame(bytes);
    if (!frame.isOk()) {
        ++counters_.raw_frames_malformed;
        return;
    }
    ++counters_.raw_frames;
    if (!frame->colour.empty()) ++counters_.raw_frames_colour;
    if (config_.keep_raw_frames) keepRawFrame(*frame, bytes);
    last_raw_ = std::move(frame).value();
}

void Ingestor::keepRawFrame(const messages::RawRgbdFrame& frame, std::span<const uint8_t> bytes) {
    Status kept = Status::ok();
    if (raw_store_ == nullptr) {
        auto store = RawFrameStore::open(raw_frames_dir_);
        if (store.isOk()) {
            raw_store_ = std::move(store).value();
        } else {
            kept = store.status();
        }
    }
    if (kept.isOk() && rawFramesShortOfSpace()) {
        ++counters_.raw_frames_not_kept;
        ++counters_.raw_frames_not_kept_disk;
        return;
    }
    if (kept.isOk())
        kept = raw_store_->put(frame.utime, frame.frame_index, bytes, frame.session_id);
    if (kept.isOk()) {
        ++counters_.raw_frames_kept;
        return;
    }
    const bool first_failure =
        counters_.raw_frames_not_kept == counters_.raw_frames_not_kept_disk;  // none yet
    ++counters_.raw_frames_not_kept;
    if (first_failure) {
        log::warn(
            "ingest: {} (raw frames that cannot be kept are counted; the final model "
            "re-integrates the raw frames only where every fragment has enough of them)",
            kept.message());
    }
}

bool Ingestor::rawFramesShortOfSpace() {
    std::error_code ec;
    const std::filesystem::space_info space = std::filesystem::space(raw_frames_dir_, ec);
    const bool short_of_space = !ec && space.available < config_.raw_frames_min_free_bytes;
    if (short_of_space == raw_frames_short_of_space_) return short_of_space;
    raw_frames_short_of_space_ = short_of_space;
    const double free_gb = static_cast<double>(space.available) * 1e-9;
    if (short_of_space) {
        log::warn(
            "ingest: {:.2f} GB free on {}, less than the {:.2f} GB kept for fragments: raw "
            "frames are not kept until space comes back",
            free_gb, raw_frames_dir_.string(),
            static_cast<double>(config_.raw_frames_min_free_bytes) * 1e-9);
    } else {
        log::info("ingest: {:.2f} GB free on {}: raw frames are kept again", free_gb,
                  raw_frames_dir_.string());
    }
    return short_of_space;
}

void Ingestor::onCameraInfo(std::span<const uint8_t> bytes) {
    auto msg = messages::decodeMessage<plumb::camera_info_t>(bytes);
    if (!msg.isOk()) {
        ++counters_.malformed_other;
        return;
    }
    auto info = messages::fromMessage(*msg);
    if (!info.isOk()) {
        ++counters_.malformed_other;
        return;
    }
    const bool changed = !camera_ || camera_->source != info->source ||
                         camera_->camera.toString() != info->camera.toString() ||
                         camera_->depth_scale != info->depth_scale;
    camera_ = *info;
    if (changed && !sidecar_dir_.empty()) {
        const PinholeCamera& c = info->camera;
        nlohmann::json j = {{"width", c.width},
                            {"height", c.height},
                            {"fx", c.fx},
                            {"fy", c.fy},
                            {"cx", c.cx},
                            {"cy", c.cy},
                            {"depth_scale", info->depth_scale},
                            {"source", info->source}};
        const std::string text = j.dump(2) + "\n";
        const Status s = messages::writeFileAtomic(
            sidecar_dir_ / "camera_info.json",
            std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
        if (!s.isOk()) log::warn("ingest: {}", s.toString());
    }
}

void Ingestor::onConfig(std::span<const uint8_t> bytes) {
    auto msg = messages::decodeMessage<plumb::config_snapshot_t>(bytes);
    if (!msg.isOk()) {
        ++counters_.malformed_other;
        return;
    }
    if (msg->program != "plumb-device" || msg->toml == device_config_) return;
    device_config_ = msg->toml;
    if (!sidecar_dir_.empty()) {
        const Status s = messages::writeFileAtomic(
            sidecar_dir_ / "device_config.toml",
            std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(device_config_.data()),
                                     device_config_.size()));
        if (!s.isOk()) log::warn("ingest: {}", s.toString());
    }
}

void Ingestor::poll(double now_s) {
    assembler_->poll(now_s);
    for (messages::CompletedFragment& c : assembler_->takeCompleted()) {
        const Key key{c.session_id, c.fragment_id};
        requested_.erase(key);
        if (config_.verify_decode) {
            auto decoded = messages::decodeFragment(c.bytes);
            if (!decoded.isOk()) {
                log::warn("ingest: fragment {} of session {} rejected: {}", c.fragment_id,
                          c.session_id, decoded.status().toString());
                ++counters_.fragments_rejected;
                rejected_.insert(key);
                assembler_->reject(c.session_id, c.fragment_id, now_s);
                continue;
            }
        }
        auto put = store_->put(c.session_id, c.fragment_id, c.bytes);
        if (!put.isOk()) {
            if (put.status().code() == StatusCode::kIoError) {
                onCannotStore(c, put.status(), now_s);
                assembler_->release(c.session_id, c.fragment_id);
            } else {
                log::warn("ingest: fragment {} of session {} rejected: {}", c.fragment_id,
                          c.session_id, put.status().toString());
                ++counters_.fragments_rejected;
                rejected_.insert(key);
                assembler_->reject(c.session_id, c.fragment_id, now_s);
            }
            continue;
        }
        onStored();
        if (*put) {
            ++counters_.fragments_received;
            log::debug("ingest: fragment {} of session {} stored ({} bytes)", c.fragment_id,
                       c.session_id, c.bytes.size());
        } else {
            ++counters_.fragments_duplicate;
        }
        assembler_->acknowledge(c.session_id, c.fragment_id, now_s);
    }
}

void Ingestor::onCannotStore(const messages::CompletedFragment& c, const Status& error,
                             double now_s) {
    ++counters_.persist_errors;
    ++failed_since_stored_;
    backoff_s_ = backoff_s_ == 0.0 ? config_.cannot_store_backoff_s
                                   : std::min(2.0 * backoff_s_, config_.max_cannot_store_backoff_s);
    if (failed_since_stored_ == 1 || now_s - last_error_log_s_ >= 60.0) {
        log::error(
            "ingest: cannot store fragment {} of session {}: {}; asking the device to wait {:.0f} "
            "s ({} failed attempt(s) since the last fragment stored)",
            c.fragment_id, c.session_id, error.message(), backoff_s_, failed_since_stored_);
        last_error_log_s_ = now_s;
    }
    plumb::fragment_backoff_t b{};
    b.utime = messages::toUtime(now_s);
    b.seq = ++backoff_seq_;
    b.session_id = c.session_id;
    b.fragment_id = static_cast<int32_t>(c.fragment_id);
    b.reason = plumb::fragment_backoff_t::REASON_CANNOT_STORE;
    b.retry_after_s = backoff_s_;
    b.message = error.message();
    if (out_->publish(messages::kChannelFragmentBackoff, messages::encodeMessage(b)).isOk()) {
        ++counters_.backoffs_sent;
    }
}

void Ingestor::onStored() {
    if (failed_since_stored_ > 0) {
        log::info("ingest: storing again after {} failed attempt(s)", failed_since_stored_);
    }
    failed_since_stored_ = 0;
    backoff_s_ = 0.0;
}

bool Ingestor::sessionComplete(int64_t session) const {
    auto end = end_of_scan_.find(session);
    if (end == end_of_scan_.end()) return false;
    for (int32_t id = 0; id < end->second; ++id) {
        const Key key{session, static_cast<uint32_t>(id)};
        if (!store_->contains(session, key.second) && rejected_.count(key) == 0) return false;
    }
    return true;
}

bool Ingestor::scanComplete(const std::set<int64_t>& wanted, double now_s, double silence_s) const {
    if (!wanted.empty()) {
        return std::all_of(wanted.begin(), wanted.end(),
                           [&](int64_t s) { return sessionComplete(s); });
    }
    bool any = false;
    for (const auto& [session, heard_s] : last_heard_) {
        if (sessionComplete(session)) {
            any = true;
        } else if (now_s - heard_s < silence_s) {
            return false;  // a live device still scanning or sending
        }
    }
    return any;
}

std::vector<SessionReport> Ingestor::sessions() const {
    std::map<int64_t, SessionReport> by_id;
    for (const messages::StoredFragment& f : store_->fragments()) {
        ++by_id[f.session_id].fragments_stored;
    }
    for (const auto& [session, heard_s] : last_heard_) {
        by_id[session].heard = true;
        by_id[session].last_heard_s = heard_s;
    }
    for (const auto& [session, count] : end_of_scan_) by_id[session].fragments_announced = count;
    std::vector<SessionReport> out;
    for (auto& [session, r] : by_id) {
        r.session_id = session;
        r.complete = sessionComplete(session);
        out.push_back(r);
    }
    return out;
}

nlohmann::json Ingestor::metrics(const messages::AuthStats& auth) const {
    const messages::FragmentAssemblerStats& a = assembler_->stats();
    int64_t sent = 0;
    nlohmann::json devices = nlohmann::json::array();
    for (const auto& [session, s] : status_) {
        sent += s.fragments_cut;
        devices.push_back({{"session_id", session},
                           {"frames_processed", s.frames_processed},
                           {"frames_dropped", s.frames_dropped},
                           {"fragments_cut", s.fragments_cut},
                           {"fragments_acked", s.fragments_acked},
                           {"spool_fragments", s.spool_fragments},
                           {"spool_bytes", s.spool_bytes},
                           {"scan_complete", end_of_scan_.count(session) > 0}});
    }
    nlohmann::json j;
    j["fragments_sent"] = sent;  // as reported by the devices' heartbeats
    j["fragments_received"] = counters_.fragments_received;
    j["fragments_resumed"] = counters_.fragments_resumed;
    j["fragments_in_store"] = store_->fragments().size();
    j["fragments_duplicate"] = counters_.fragments_duplicate;
    j["fragments_rejected"] = counters_.fragments_rejected;
    j["fragments_incomplete"] = assembler_->numPartial();
    j["persist_errors"] = counters_.persist_errors;
    j["backoffs_sent"] = counters_.backoffs_sent;
    j["chunks_received"] = a.chunks_received;
    j["chunks_duplicate"] = a.duplicate_chunks;
    j["chunks_lost"] = counters_.chunks_lost;
    j["chunks_recovered"] = counters_.chunks_recovered;
    j["retransmit_requests"] = a.requests_sent;
    j["acks_sent"] = a.acks_sent;
    j["raw_frames"] = {{"received", counters_.raw_frames},
                       {"with_colour", counters_.raw_frames_colour},
                       {"kept", counters_.raw_frames_kept},
                       {"not_kept", counters_.raw_frames_not_kept},
                       {"not_kept_disk", counters_.raw_frames_not_kept_disk}};
    j["messages_accepted"] = auth.accepted;
    j["messages_rejected"] = {
        {"unsigned", auth.rejected_unsigned},
        {"wrong_key", auth.rejected_wrong_key},
        {"forged", auth.rejected_forged},
        {"replayed", auth.rejected_replayed},
        {"malformed",
         a.malformed_messages + counters_.malformed_other + counters_.raw_frames_malformed},
        {"chunk_crc", a.chunk_crc_failures},
        {"fragment_crc", a.fragment_crc_failures},
        {"inconsistent", a.inconsistent_chunks},
    };
    j["devices"] = devices;
    nlohmann::json sessions = nlohmann::json::array();
    for (const SessionReport& r : this->sessions()) {
        sessions.push_back(
            {{"session_id", r.session_id},
             {"fragments_stored", r.fragments_stored},
             {"fragments_announced", r.fragments_announced ? nlohmann::json(*r.fragments_announced)
                                                           : nlohmann::json(nullptr)},
             {"heard", r.heard},
             {"complete", r.complete}});
    }
    j["sessions"] = sessions;
    return j;
}

Result<int64_t> chooseSession(const messages::FragmentStore& store, const std::set<int64_t>& wanted,
                              std::string* note) {
    std::map<int64_t, size_t> counts;
    for (const messages::StoredFragment& f : store.fragments()) ++counts[f.session_id];
    if (counts.empty()) return notFound("no fragments in " + store.dir().string());
    auto list = [&](int64_t except) {
        std::string text;
        for (const auto& [session, n] : counts) {
            if (session == except) continue;
            text += fmt::format("{}{} ({} fragment(s))", text.empty() ? "" : ", ", session, n);
        }
        return text;
    };
    int64_t chosen = counts.rbegin()->first;
    if (!wanted.empty()) {
        chosen = *wanted.rbegin();
        if (counts.count(chosen) == 0) {
            return notFound(fmt::format("no fragments of session {} in {} (it holds {})", chosen,
                                        store.dir().string(), list(chosen)));
        }
    }
    if (note != nullptr) {
        note->clear();
        if (counts.size() > 1) {
            *note = fmt::format(
                "{} holds {} sessions; reconstructing session {} ({} fragment(s), {}) and not "
                "{}; choose with --session ID",
                store.dir().string(), counts.size(), chosen, counts[chosen],
                wanted.empty() ? "the newest" : "named by --session", list(chosen));
        }
    }
    return chosen;
}

Result<std::vector<Fragment>> loadStoredFragments(const messages::FragmentStore& store,
                                                  std::optional<int64_t> session_id) {
    const auto all = store.fragments();
    if (all.empty()) return notFound("no fragments in " + store.dir().string());
    const int64_t session = session_id ? *session_id : all.back().session_id;
    std::vector<Fragment> out;
    for (const messages::StoredFragment& f : all) {
        if (f.session_id != session) continue;
        auto bytes = store.get(f.session_id, f.fragment_id);
        if (!bytes.isOk()) return bytes.status();
        auto fragment = messages::decodeFragment(*bytes);
        if (!fragment.isOk()) {
            return corrupt(fmt::format("{}: {}", f.path.string(), fragment.status().message()));
        }
        out.push_back(std::move(fragment).value());
    }
    if (out.empty()) return notFound(fmt::format("no fragments of session {}", session));
    return out;
}

Result<PinholeCamera> readCameraInfo(const std::vector<std::filesystem::path>& candidates) {
    for (const auto& path : candidates) {
        if (!std::filesystem::is_regular_file(path)) continue;
        auto bytes = messages::readFile(path, 1 << 20);
        if (!bytes.isOk()) return bytes.status();
        try {
            const auto j = nlohmann::json::parse(bytes->begin(), bytes->end());
            PinholeCamera c{j.at("width").get<int>(), j.at("height").get<int>(),
                            j.at("fx").get<double>(), j.at("fy").get<double>(),
                            j.at("cx").get<double>(), j.at("cy").get<double>()};
            PLUMB_RETURN_IF_ERROR(c.validate());
            return c;
        } catch (const std::exception& e) {
            return corrupt(fmt::format("{}: {}", path.string(), e.what()));
        }
    }
    return notFound("no camera_info.json (the device's camera info) was found");
}

}  // namespace plumb::backend
