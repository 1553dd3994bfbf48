// SPDX-License-Identifier: Apache-2.0
#include "messages/fragment_assembler.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "messages/channels.hpp"
#include "messages/crc32.hpp"
#include "messages/fragment_sender.hpp"

namespace plumb::messages {

FragmentAssembler::FragmentAssembler(FragmentAssemblerConfig config, Transport& transport)
    : config_(config), transport_(transport) {
    PLUMB_CHECK(config_.max_chunk_bytes > 0 && config_.max_fragment_bytes > 0);
    PLUMB_CHECK(config_.max_buffered_bytes >= config_.max_fragment_bytes)
        << "max_buffered_bytes must hold at least one fragment";
    PLUMB_CHECK(config_.request_interval_s > 0.0 && config_.max_missing_per_request > 0 &&
                config_.max_partial_fragments > 0);
}

Status FragmentAssembler::checkGeometry(const Geometry& g, int32_t fragment_id) const {
    const bool ok = fragment_id >= 0 && g.total_bytes > 0 &&
                    g.total_bytes <= config_.max_fragment_bytes && g.chunk_bytes > 0 &&
                    g.chunk_bytes <= config_.max_chunk_bytes &&
                    g.num_chunks == numChunks(g.total_bytes, g.chunk_bytes);
    if (!ok) {
        return corrupt(
            fmt::format("fragment {}: absurd geometry ({} bytes in {} chunks of {} bytes)",
                        fragment_id, g.total_bytes, g.num_chunks, g.chunk_bytes));
    }
    return Status::ok();
}

Status FragmentAssembler::onMessage(const std::string& channel, std::span<const uint8_t> bytes,
                                    double now_s) {
    Status s;
    if (channel == kChannelFragmentHeader) {
        s = onHeader(bytes, now_s);
    } else if (channel == kChannelFragmentChunk) {
        s = onChunk(bytes, now_s);
    }
    return s;
}

FragmentAssembler::Entry& FragmentAssembler::partialFor(const Key& key, const Geometry& g,
                                                        double now_s) {
    if (entries_.find(key) == entries_.end()) {
        while (static_cast<int32_t>(numPartial()) >= config_.max_partial_fragments &&
               evictStalest(key, false)) {
        }
    }
    auto [it, inserted] = entries_.try_emplace(key);
    Entry& e = it->second;
    if (inserted) {
        e.num_chunks = g.num_chunks;
        e.chunk_bytes = g.chunk_bytes;
        e.total_bytes = g.total_bytes;
        e.crc = g.crc;
        e.chunks.resize(static_cast<size_t>(g.num_chunks));
        e.last_news_s = now_s;
    }
    return e;
}

Status FragmentAssembler::onHeader(std::span<const uint8_t> bytes, double now_s) {
    auto h = decodeMessage<plumb::fragment_header_t>(bytes);
    if (!h.isOk()) {
        ++stats_.malformed_messages;
        return h.status();
    }
    const Geometry g{h->num_chunks, h->chunk_bytes, h->total_bytes,
                     static_cast<uint32_t>(h->fragment_crc32)};
    if (Status s = checkGeometry(g, h->fragment_id); !s.isOk()) {
        ++stats_.malformed_messages;
        return s;
    }
    const Key key{h->session_id, static_cast<uint32_t>(h->fragment_id)};
    auto it = entries_.find(key);
    if (it != entries_.end() && it->second.state == State::kDone) {
        // The sender has not heard our ack: say it again (the header is its question).
        publishAck(key, it->second, now_s);
        return Status::ok();
    }
    if (it != entries_.end() && it->second.state == State::kYielded) return Status::ok();
    if (it != entries_.end() &&
        (it->second.num_chunks != g.num_chunks || it->second.chunk_bytes != g.chunk_bytes ||
         it->second.total_bytes != g.total_bytes || it->second.crc != g.crc)) {
        ++stats_.inconsistent_chunks;
        return corrupt(
            fmt::format("fragment {}: announcement disagrees with its chunks", h->fragment_id));
    }
    Entry& e = partialFor(key, g, now_s);
    e.last_news_s = now_s;
    // A re-announcement means the sender waits for us: ask for what is missing right away.
    if (h->attempt > 0) requestMissing(key, e, now_s);
    return Status::ok();
}

Status FragmentAssembler::onChunk(std::span<const uint8_t> bytes, double now_s) {
    auto c = decodeMessage<plumb::fragment_chunk_t>(bytes);
    if (!c.isOk()) {
        ++stats_.malformed_messages;
        return c.status();
    }
    const Geometry g{c->num_chunks, c->chunk_bytes, c->total_bytes,
                     static_cast<uint32_t>(c->fragment_crc32)};
    if (Status s = checkGeometry(g, c->fragment_id); !s.isOk()) {
        ++stats_.malformed_messages;
        return s;
    }
    const int64_t expected_size =
        c->chunk_index >= 0 && c->chunk_index < g.num_chunks
            ? std::min<int64_t>(g.chunk_bytes,
                                g.total_bytes - int64_t{c->chunk_index} * g.chunk_bytes)
            : -1;
    if (expected_size < 0 || c->size != expected_size) {
        ++stats_.malformed_messages;
        return corrupt(fmt::format("fragment {}: chunk {} of {} has {} bytes, expected {}",
                                   c->fragment_id, c->chunk_index, g.num_chunks, c->size,
                                   expected_size));
    }
    if (crc32(c->data) != static_cast<uint32_t>(c->chunk_crc32)) {
        ++stats_.chunk_crc_failures;
        return corrupt(
            fmt::format("fragment {}: chunk {} fails its CRC", c->fragment_id, c->chunk_index));
    }
    const Key key{c->session_id, static_cast<uint32_t>(c->fragment_id)};
    auto it = entries_.find(key);
    if (it != entries_.end() && it->second.state != State::kPartial) {
        ++stats_.duplicate_chunks;
        if (it->second.state == State::kDone &&
            now_s - it->second.last_request_s >= config_.request_interval_s) {
            publishAck(key, it->second, now_s);
        }
        return Status::ok();
    }
    if (it != entries_.end() &&
        (it->second.num_chunks != g.num_chunks || it->second.chunk_bytes != g.chunk_bytes ||
         it->second.total_bytes != g.total_bytes || it->second.crc != g.crc)) {
        ++stats_.inconsistent_chunks;
        return corrupt(fmt::format("fragment {}: chunk {} disagrees with earlier chunks",
                                   c->fragment_id, c->chunk_index));
    }
    if (it != entries_.end() && !it->second.chunks[static_cast<size_t>(c->chunk_index)].empty()) {
        ++stats_.duplicate_chunks;
        it->second.last_news_s = now_s;
        return Status::ok();
    }
    makeRoom(c->size, key);
    Entry& e = partialFor(key, g, now_s);
    e.chunks[static_cast<size_t>(c->chunk_index)] = std::move(c->data);
    ++e.received;
    e.buffered += c->size;
    buffered_bytes_ += c->size;
    e.last_news_s = now_s;
    ++stats_.chunks_received;
    finishIfComplete(key, e);
    return Status::ok();
}

void FragmentAssembler::finishIfComplete(const Key& key, Entry& e) {
    if (e.received != e.num_chunks) return;
    Bytes whole;
    whole.reserve(static_cast<size_t>(e.total_bytes));
    for (Bytes& chunk : e.chunks) {
        whole.insert(whole.end(), chunk.begin(), chunk.end());
        Bytes().swap(chunk);
    }
    buffered_bytes_ -= e.buffered;
    e.buffered = 0;
    if (crc32(whole) != e.crc) {
        // Every chunk passed its CRC, so the sender's announcement itself is wrong (or forged):
        // start over; the next announcement asks for everything again.
        ++stats_.fragment_crc_failures;
        entries_.erase(key);
        return;
    }
    e.state = State::kYielded;
    e.chunks.clear();
    e.chunks.shrink_to_fit();
    ++stats_.fragments_completed;
    completed_.push_back(CompletedFragment{key.first, key.second, e.crc, std::move(whole)});
}

bool FragmentAssembler::evictStalest(const Key& keep, bool with_data_only) {
    auto victim = entries_.end();
    for (auto it = entries_.begin(); it != entries_.end(); ++it) {
        if (it->second.state != State::kPartial || it->first == keep ||
            (with_data_only && it->second.buffered == 0)) {
            continue;
        }
        if (victim == entries_.end() || it->second.last_news_s < victim->second.last_news_s) {
            victim = it;
        }
    }
    if (victim == entries_.end()) return false;
    buffered_bytes_ -= victim->second.buffered;
    entries_.erase(victim);
    ++stats_.fragments_evicted;
    return true;
}

void FragmentAssembler::makeRoom(int64_t bytes, const Key& keep) {
    // Only `keep` left holding data means it fits by construction (max_buffered >= max_fragment).
    while (buffered_bytes_ + bytes > config_.max_buffered_bytes && evictStalest(keep, true)) {
    }
}

void FragmentAssembler::requestMissing(const Key& key, Entry& e, double now_s) {
    plumb::retransmit_request_t req{};
    req.utime = toUtime(now_s);
    req.seq = ++seq_;
    req.session_id = key.first;
    req.fragment_id = static_cast<int32_t>(key.second);
    for (int32_t i = 0; i < e.num_chunks && static_cast<int32_t>(req.missing_chunks.size()) <
                                                config_.max_missing_per_request;
         ++i) {
        if (e.chunks[static_cast<size_t>(i)].empty()) req.missing_chunks.push_back(i);
    }
    if (req.missing_chunks.empty()) return;
    req.num_missing = static_cast<int32_t>(req.missing_chunks.size());
    e.last_request_s = now_s;
    ++stats_.requests_sent;
    (void)transport_.publish(kChannelRetransmit, encodeMessage(req));  // lost = asked again later
}

void FragmentAssembler::publishAck(const Key& key, Entry& e, double now_s) {
    plumb::fragment_ack_t ack{};
    ack.utime = toUtime(now_s);
    ack.seq = ++seq_;
    ack.session_id = key.first;
    ack.fragment_id = static_cast<int32_t>(key.second);
    ack.fragment_crc32 = static_cast<int32_t>(e.crc);
    ack.status = e.done_status;
    e.last_request_s = now_s;
    ++stats_.acks_sent;
    (void)transport_.publish(kChannelFragmentAck, encodeMessage(ack));  // lost = asked again
}

void FragmentAssembler::poll(double now_s) {
    for (auto& [key, e] : entries_) {
        if (e.state != State::kPartial) continue;
        if (now_s - e.last_news_s < config_.request_interval_s ||
            now_s - e.last_request_s < config_.request_interval_s) {
            continue;
        }
        requestMissing(key, e, now_s);
    }
}

std::vector<CompletedFragment> FragmentAssembler::takeCompleted() {
    return std::exchange(completed_, {});
}

void FragmentAssembler::acknowledge(int64_t session_id, uint32_t fragment_id, double now_s) {
    auto it = entries_.find({session_id, fragment_id});
    PLUMB_CHECK(it != entries_.end() && it->second.state != State::kPartial)
        << "acknowledge() of fragment " << fragment_id << " that was never yielded";
    it->second.state = State::kDone;
    it->second.done_status = plumb::fragment_ack_t::STATUS_PERSISTED;
    publishAck(it->first, it->second, now_s);
}

void FragmentAssembler::reject(int64_t session_id, uint32_t fragment_id, double now_s) {
    auto it = entries_.find({session_id, fragment_id});
    PLUMB_CHECK(it != entries_.end() && it->second.state != State::kPartial)
        << "reject() of fragment " << fragment_id << " that was never yielded";
    it->second.state = State::kDone;
    it->second.done_status = plumb::fragment_ack_t::STATUS_REJECTED;
    publishAck(it->first, it->second, now_s);
}

void FragmentAssembler::release(int64_t session_id, uint32_t fragment_id) {
    auto it = entries_.find({session_id, fragment_id});
    if (it != entries_.end() && it->second.state == State::kYielded) entries_.erase(it);
}

void FragmentAssembler::markPersisted(int64_t session_id, uint32_t fragment_id, uint32_t crc) {
    Entry& e = entries_[{session_id, fragment_id}];
    buffered_bytes_ -= e.buffered;
    e = Entry{};
    e.state = State::kDone;
    e.crc = crc;
    e.done_status = plumb::fragment_ack_t::STATUS_PERSISTED;
}

bool FragmentAssembler::isPersisted(int64_t session_id, uint32_t fragment_id) const {
    auto it = entries_.find({session_id, fragment_id});
    return it != entries_.end() && it->second.state == State::kDone &&
           it->second.done_status == plumb::fragment_ack_t::STATUS_PERSISTED;
}

size_t FragmentAssembler::numPartial() const {
    return static_cast<size_t>(std::count_if(entries_.begin(), entries_.end(), [](const auto& kv) {
        return kv.second.state == State::kPartial;
    }));
}

}  // namespace plumb::messages
