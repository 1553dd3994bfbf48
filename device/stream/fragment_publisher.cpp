// SPDX-License-Identifier: Apache-2.0
#include "device/stream/fragment_publisher.hpp"

#include <fmt/format.h>

#include "messages/channels.hpp"
#include "messages/files.hpp"

namespace plumb::device {

using messages::FragmentKey;

Result<std::unique_ptr<FragmentPublisher>> FragmentPublisher::create(
    PublisherConfig config, messages::Transport& transport) {
    if (config.max_in_flight < 1) return invalidArgument("publisher: max_in_flight must be >= 1");
    std::unique_ptr<FragmentPublisher> p(new FragmentPublisher(std::move(config), transport));
    auto spool = Spool::open(p->config_.spool);
    if (!spool.isOk()) return spool.status();
    p->spool_ = std::move(spool).value();
    p->stats_.fragments_resumed = p->spool_->size();
    return p;
}

messages::FragmentSender& FragmentPublisher::senderFor(int64_t session_id) {
    auto it = senders_.find(session_id);
    if (it == senders_.end()) {
        messages::FragmentSenderConfig sc = config_.sender;
        sc.session_id = session_id;
        it =
            senders_.emplace(session_id, std::make_unique<messages::FragmentSender>(sc, transport_))
                .first;
    }
    return *it->second;
}

Status FragmentPublisher::submit(uint32_t fragment_id, std::vector<uint8_t> encoded, double now_s) {
    const FragmentKey key{config_.session_id, fragment_id};
    PLUMB_RETURN_IF_ERROR(spool_->put(key, std::move(encoded)));
    ++stats_.fragments_submitted;
    fill(now_s);
    return Status::ok();
}

void FragmentPublisher::onMessage(const std::string& channel, std::span<const uint8_t> bytes,
                                  double now_s) {
    if (channel != messages::kChannelFragmentAck && channel != messages::kChannelRetransmit &&
        channel != messages::kChannelFragmentBackoff) {
        return;
    }
    // Acks and requests name their session; every sender ignores other sessions' messages.
    for (auto& [session, sender] : senders_) (void)sender->onMessage(channel, bytes, now_s);
    collect();
    fill(now_s);
}

void FragmentPublisher::collect() {
    for (auto& [session, sender] : senders_) {
        for (uint32_t id : sender->takeAcknowledged()) {
            const FragmentKey key{session, id};
            in_flight_.erase(key);
            if (!spool_->erase(key).isOk()) ++stats_.spool_errors;
            ++stats_.fragments_acked;
        }
        for (uint32_t id : sender->takeRejected()) {
            const FragmentKey key{session, id};
            in_flight_.erase(key);
            ++stats_.fragments_rejected;
            const std::string reason = fmt::format(
                "fragment {} of session {} was rejected for good by the backend (fragment_ack_t "
                "STATUS_REJECTED: it did not decode or conflicts with a stored fragment; the "
                "backend's log names the cause)",
                id, session);
            if (spool_->quarantine(key, reason).isOk()) {
                quarantined_.push_back(key);
            } else {
                rejected_.insert(key);  // kept, but never sent again by this run
                ++stats_.spool_errors;
            }
        }
    }
}

void FragmentPublisher::fill(double now_s) {
    if (static_cast<int>(in_flight_.size()) >= config_.max_in_flight) return;
    for (const FragmentKey& key : spool_->keys()) {
        if (static_cast<int>(in_flight_.size()) >= config_.max_in_flight) break;
        if (in_flight_.count(key) || rejected_.count(key)) continue;
        auto bytes = spool_->get(key);
        if (!bytes.isOk()) {
            ++stats_.spool_errors;
            continue;
        }
        if (senderFor(key.session_id).send(key.fragment_id, std::move(bytes).value(), now_s)) {
            in_flight_.insert(key);
        } else {
            ++stats_.spool_errors;
        }
    }
}

void FragmentPublisher::poll(double now_s) {
    for (auto& [session, sender] : senders_) sender->poll(now_s);
    collect();
    fill(now_s);
}

std::string FragmentPublisher::lastBackoffMessage() const {
    for (const auto& [session, sender] : senders_) {
        if (!sender->lastBackoffMessage().empty()) return sender->lastBackoffMessage();
    }
    return {};
}

messages::FragmentSenderStats FragmentPublisher::senderStats() const {
    messages::FragmentSenderStats sum;
    for (const auto& [session, sender] : senders_) {
        const auto& s = sender->stats();
        sum.headers_sent += s.headers_sent;
        sum.chunks_sent += s.chunks_sent;
        sum.chunks_resent += s.chunks_resent;
        sum.acks_received += s.acks_received;
        sum.stale_messages += s.stale_messages;
        sum.malformed_messages += s.malformed_messages;
        sum.publish_errors += s.publish_errors;
        sum.backoffs_received += s.backoffs_received;
    }
    return sum;
}

}  // namespace plumb::device
