// SPDX-License-Identifier: Apache-2.0
#include "messages/auth.hpp"

#include <fmt/format.h>

#include <limits>

#include "messages/sha256.hpp"

namespace plumb::messages {
namespace {

Digest256 computeMac(const std::string& channel, const plumb::envelope_t& unsigned_envelope,
                     std::span<const uint8_t> key) {
    HmacSha256 mac(key);
    const auto n = static_cast<uint32_t>(channel.size());
    const uint8_t len[4] = {static_cast<uint8_t>(n >> 24), static_cast<uint8_t>(n >> 16),
                            static_cast<uint8_t>(n >> 8), static_cast<uint8_t>(n)};
    mac.update(len);
    mac.update({reinterpret_cast<const uint8_t*>(channel.data()), channel.size()});
    mac.update(encodeMessage(unsigned_envelope));
    return mac.finish();
}

}  // namespace

Bytes sealMessage(const std::string& channel, std::span<const uint8_t> payload,
                  std::span<const uint8_t> key, int32_t key_id, int64_t sender_id, int64_t seq,
                  int64_t utime) {
    plumb::envelope_t env{};
    env.utime = utime;
    env.seq = seq;
    env.sender_id = sender_id;
    env.key_id = key_id;
    env.payload.assign(payload.begin(), payload.end());
    env.payload_size = static_cast<int32_t>(env.payload.size());
    env.mac_size = 0;
    const Digest256 mac = computeMac(channel, env, key);
    env.mac.assign(mac.begin(), mac.end());
    env.mac_size = static_cast<int32_t>(env.mac.size());
    return encodeMessage(env);
}

bool ReplayGuard::accept(int64_t sender_id, int64_t seq) {
    auto it = senders_.find(sender_id);
    if (it == senders_.end()) {
        if (senders_.size() >= max_senders_) {
            auto oldest = senders_.begin();
            for (auto s = senders_.begin(); s != senders_.end(); ++s) {
                if (s->second.last_used < oldest->second.last_used) oldest = s;
            }
            senders_.erase(oldest);
        }
        it = senders_.emplace(sender_id, Sender{seq, {}, 0}).first;
    }
    Sender& s = it->second;
    s.last_used = ++clock_;
    if (seq <= s.newest - window_ || s.seen.count(seq) > 0) return false;
    s.seen.insert(seq);
    if (seq > s.newest) {
        s.newest = seq;
        s.seen.erase(s.seen.begin(), s.seen.upper_bound(s.newest - window_));
    }
    return true;
}

Result<Bytes> openMessage(const std::string& channel, std::span<const uint8_t> bytes,
                          std::span<const uint8_t> key, int32_t key_id, ReplayGuard& guard,
                          AuthStats& stats) {
    auto env = decodeMessage<plumb::envelope_t>(bytes);
    if (!env.isOk()) {
        ++stats.rejected_unsigned;
        return corrupt(
            fmt::format("{}: unsigned or malformed message: {}", channel, env.status().message()));
    }
    if (env->key_id != key_id) {
        ++stats.rejected_wrong_key;
        return invalidArgument(fmt::format("{}: message signed with key id {}, expected {}",
                                           channel, env->key_id, key_id));
    }
    std::vector<uint8_t> received_mac = std::move(env->mac);
    env->mac.clear();
    env->mac_size = 0;
    const Digest256 expected = computeMac(channel, *env, key);
    if (!constantTimeEqual(received_mac, expected)) {
        ++stats.rejected_forged;
        return failedPrecondition(
            fmt::format("{}: forged message (bad MAC) from sender {}", channel, env->sender_id));
    }
    if (!guard.accept(env->sender_id, env->seq)) {
        ++stats.rejected_replayed;
        return failedPrecondition(fmt::format("{}: replayed message (sender {}, seq {})", channel,
                                              env->sender_id, env->seq));
    }
    ++stats.accepted;
    return std::move(env->payload);
}

AuthenticatedTransport::AuthenticatedTransport(Transport& inner, AuthConfig config)
    : inner_(inner),
      config_(std::move(config)),
      guard_(config_.replay_window, config_.max_senders) {
    PLUMB_CHECK(config_.key.empty() || config_.key.size() >= 16)
        << "a shared key needs at least 16 bytes, got " << config_.key.size();
    PLUMB_CHECK(config_.replay_window > 0 && config_.max_senders > 0);
}

Status AuthenticatedTransport::publish(const std::string& channel, std::span<const uint8_t> bytes) {
    if (!enabled()) return inner_.publish(channel, bytes);
    if (bytes.size() > kMaxMessageBytes) {
        return invalidArgument(
            fmt::format("{}: message of {} bytes is too large to sign", channel, bytes.size()));
    }
    const Bytes sealed = sealMessage(channel, bytes, config_.key, config_.key_id, config_.sender_id,
                                     next_seq_++, utime_);
    ++stats_.sent;
    return inner_.publish(channel, sealed);
}

Status AuthenticatedTransport::subscribe(const std::string& channel, Handler handler) {
    if (!enabled()) return inner_.subscribe(channel, std::move(handler));
    return inner_.subscribe(channel, [this, handler = std::move(handler)](
                                         const std::string& ch, std::span<const uint8_t> bytes) {
        auto payload = openMessage(ch, bytes, config_.key, config_.key_id, guard_, stats_);
        if (payload.isOk()) handler(ch, *payload);
    });
}

}  // namespace plumb::messages
