// SPDX-License-Identifier: Apache-2.0
#include "messages/fragment_sender.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "messages/channels.hpp"
#include "messages/crc32.hpp"

namespace plumb::messages {

int64_t numChunks(int64_t total_bytes, int64_t chunk_bytes) {
    return (total_bytes + chunk_bytes - 1) / chunk_bytes;
}

int64_t toUtime(double now_s) { return static_cast<int64_t>(std::llround(now_s * 1e6)); }

FragmentSender::FragmentSender(FragmentSenderConfig config, Transport& transport)
    : config_(config), transport_(transport) {
    PLUMB_CHECK(config_.chunk_payload_bytes > 0 && config_.chunk_payload_bytes <= 65536 - 1024)
        << "chunk_payload_bytes " << config_.chunk_payload_bytes << " must leave room in 64 KiB";
    PLUMB_CHECK(config_.retransmit_timeout_s > 0.0 &&
                config_.max_retransmit_timeout_s >= config_.retransmit_timeout_s);
    PLUMB_CHECK(config_.max_fragment_bytes > 0 &&
                numChunks(config_.max_fragment_bytes, config_.chunk_payload_bytes) <= INT32_MAX);
}

void FragmentSender::publishOrCount(const std::string& channel, const Bytes& bytes) {
    if (!transport_.publish(channel, bytes).isOk()) ++stats_.publish_errors;
}

void FragmentSender::publishHeader(uint32_t fragment_id, const Pending& p, int attempt,
                                   double now_s) {
    plumb::fragment_header_t h{};
    h.utime = toUtime(now_s);
    h.seq = ++seq_;
    h.session_id = config_.session_id;
    h.fragment_id = static_cast<int32_t>(fragment_id);
    h.num_chunks = p.num_chunks;
    h.chunk_bytes = config_.chunk_payload_bytes;
    h.total_bytes = static_cast<int64_t>(p.bytes.size());
    h.fragment_crc32 = static_cast<int32_t>(p.crc);
    h.codec_version = 1;
    h.attempt = static_cast<int16_t>(std::min(attempt, 32767));
    ++stats_.headers_sent;
    publishOrCount(kChannelFragmentHeader, encodeMessage(h));
}

void FragmentSender::publishChunk(uint32_t fragment_id, const Pending& p, int32_t index,
                                  double now_s) {
    const size_t begin = static_cast<size_t>(index) * config_.chunk_payload_bytes;
    const size_t end = std::min(p.bytes.size(), begin + config_.chunk_payload_bytes);
    plumb::fragment_chunk_t c{};
    c.utime = toUtime(now_s);
    c.seq = ++seq_;
    c.session_id = config_.session_id;
    c.fragment_id = static_cast<int32_t>(fragment_id);
    c.chunk_index = index;
    c.num_chunks = p.num_chunks;
    c.chunk_bytes = config_.chunk_payload_bytes;
    c.total_bytes = static_cast<int64_t>(p.bytes.size());
    c.fragment_crc32 = static_cast<int32_t>(p.crc);
    c.data.assign(p.bytes.begin() + static_cast<std::ptrdiff_t>(begin),
                  p.bytes.begin() + static_cast<std::ptrdiff_t>(end));
    c.size = static_cast<int32_t>(c.data.size());
    c.chunk_crc32 = static_cast<int32_t>(crc32(c.data));
    publishOrCount(kChannelFragmentChunk, encodeMessage(c));
}

Status FragmentSender::send(uint32_t fragment_id, std::vector<uint8_t> encoded, double now_s) {
    if (fragment_id > static_cast<uint32_t>(INT32_MAX)) {
        return invalidArgument(fmt::format("fragment id {} does not fit the wire", fragment_id));
    }
    if (encoded.empty() || static_cast<int64_t>(encoded.size()) > config_.max_fragment_bytes) {
        return invalidArgument(fmt::format("fragment {}: {} bytes (limit {})", fragment_id,
                                           encoded.size(), config_.max_fragment_bytes));
    }
    const uint32_t crc = crc32(encoded);
    if (auto it = pending_.find(fragment_id); it != pending_.end()) {
        if (it->second.crc == crc && it->second.bytes == encoded) return Status::ok();
        return invalidArgument(
            fmt::format("fragment {} is already in flight with different content", fragment_id));
    }
    Pending p;
    p.num_chunks = static_cast<int32_t>(
        numChunks(static_cast<int64_t>(encoded.size()), config_.chunk_payload_bytes));
    p.crc = crc;
    p.bytes = std::move(encoded);
    p.last_activity_s = now_s;
    const Pending& stored = pending_.emplace(fragment_id, std::move(p)).first->second;
    publishHeader(fragment_id, stored, 0, now_s);
    for (int32_t i = 0; i < stored.num_chunks; ++i) {
        publishChunk(fragment_id, stored, i, now_s);
        ++stats_.chunks_sent;
    }
    return Status::ok();
}

Status FragmentSender::onMessage(const std::string& channel, std::span<const uint8_t> bytes,
                                 double now_s) {
    if (channel == kChannelFragmentAck) {
        auto ack = decodeMessage<plumb::fragment_ack_t>(bytes);
        if (!ack.isOk()) {
            ++stats_.malformed_messages;
            return ack.status();
        }
        if (ack->session_id != config_.session_id || ack->fragment_id < 0) {
            ++stats_.stale_messages;
            return Status::ok();
        }
        const auto id = static_cast<uint32_t>(ack->fragment_id);
        auto it = pending_.find(id);
        if (it == pending_.end()) {
            ++stats_.stale_messages;  // a repeated ack of a fragment already released
            return Status::ok();
        }
        if (static_cast<uint32_t>(ack->fragment_crc32) != it->second.crc ||
            (ack->status != plumb::fragment_ack_t::STATUS_PERSISTED &&
             ack->status != plumb::fragment_ack_t::STATUS_REJECTED)) {
            ++stats_.malformed_messages;
            return corrupt(fmt::format("ack of fragment {}: CRC {:08x} or status {} does not match",
                                       id, static_cast<uint32_t>(ack->fragment_crc32),
                                       ack->status));
        }
        ++stats_.acks_received;
        (ack->status == plumb::fragment_ack_t::STATUS_PERSISTED ? acknowledged_ : rejected_)
            .push_back(id);
        pending_.erase(it);
        return Status::ok();
    }
    if (channel == kChannelFragmentBackoff) return onBackoff(bytes, now_s);
    if (channel == kChannelRetransmit) {
        auto req = decodeMessage<plumb::retransmit_request_t>(bytes);
        if (!req.isOk()) {
            ++stats_.malformed_messages;
            return req.status();
        }
        if (req->session_id != config_.session_id || req->fragment_id < 0) {
            ++stats_.stale_messages;
            return Status::ok();
        }
        auto it = pending_.find(static_cast<uint32_t>(req->fragment_id));
        if (it == pending_.end()) {
            ++stats_.stale_messages;
            return Status::ok();
        }
        Pending& p = it->second;
        for (const int32_t index : req->missing_chunks) {
            if (index < 0 || index >= p.num_chunks) {
                ++stats_.malformed_messages;
                return corrupt(fmt::format("retransmit request for fragment {}: chunk {} of {}",
                                           req->fragment_id, index, p.num_chunks));
            }
        }
        // Each distinct index once, even if the request repeats some.
        std::vector<int32_t> indices = req->missing_chunks;
        std::sort(indices.begin(), indices.end());
        indices.erase(std::unique(indices.begin(), indices.end()), indices.end());
        for (const int32_t index : indices) {
            publishChunk(it->first, p, index, now_s);
            ++stats_.chunks_resent;
        }
        p.last_activity_s = now_s;
        p.attempts = 0;
        return Status::ok();
    }
    return Status::ok();
}

Status FragmentSender::onBackoff(std::span<const uint8_t> bytes, double now_s) {
    auto msg = decodeMessage<plumb::fragment_backoff_t>(bytes);
    if (!msg.isOk()) {
        ++stats_.malformed_messages;
        return msg.status();
    }
    if (!(msg->retry_after_s >= 0.0) ||
        msg->reason != plumb::fragment_backoff_t::REASON_CANNOT_STORE) {
        ++stats_.malformed_messages;
        return corrupt(fmt::format("backoff: retry_after_s {} or reason {} is not valid",
                                   msg->retry_after_s, msg->reason));
    }
    if (msg->session_id != config_.session_id) {
        ++stats_.stale_messages;
        return Status::ok();
    }
    ++stats_.backoffs_received;
    last_backoff_message_ = msg->message;
    // Quiet until then: poll() re-announces once the usual timeout has passed after it.
    const double until = now_s + std::min(msg->retry_after_s, kMaxBackoffS);
    for (auto& [id, p] : pending_) {
        p.last_activity_s = std::max(p.last_activity_s, until);
        p.attempts = 0;
    }
    return Status::ok();
}

void FragmentSender::poll(double now_s) {
    for (auto& [id, p] : pending_) {
        const double timeout = std::min(config_.max_retransmit_timeout_s,
                                        config_.retransmit_timeout_s * std::ldexp(1.0, p.attempts));
        if (now_s - p.last_activity_s < timeout) continue;
        ++p.attempts;
        p.last_activity_s = now_s;
        publishHeader(id, p, p.attempts, now_s);
    }
}

std::vector<uint32_t> FragmentSender::takeAcknowledged() {
    return std::exchange(acknowledged_, {});
}

std::vector<uint32_t> FragmentSender::takeRejected() { return std::exchange(rejected_, {}); }

std::vector<uint32_t> FragmentSender::inFlight() const {
    std::vector<uint32_t> ids;
    ids.reserve(pending_.size());
    for (const auto& [id, p] : pending_) ids.push_back(id);
    return ids;
}

}  // namespace plumb::messages
