// SPDX-License-Identifier: Apache-2.0
#pragma once

// Writes what plumb-device sends during a scan into an LCM log (lcm-logger format): a heartbeat
// before every fragment, then the fragment's header and chunks exactly as FragmentSender
// publishes them, fragments `interval_s` apart in log time.

#include <lcm/lcm-cpp.hpp>

#include <filesystem>
#include <string>
#include <vector>

#include "common/core/status.hpp"
#include "common/fragment/fragment.hpp"
#include "messages/channels.hpp"
#include "messages/conversions.hpp"
#include "messages/fragment_codec.hpp"
#include "messages/fragment_sender.hpp"
#include "messages/wire.hpp"

namespace plumb::monitor::testing {

/// Collects what a protocol class publishes, with the log time of each message.
class RecordingTransport final : public messages::Transport {
  public:
    struct Message {
        std::string channel;
        messages::Bytes bytes;
        double time_s;
    };
    Status publish(const std::string& channel, std::span<const uint8_t> bytes) override {
        messages_.push_back({channel, messages::Bytes(bytes.begin(), bytes.end()), now_s});
        return Status::ok();
    }
    Status subscribe(const std::string&, Handler) override { return Status::ok(); }
    double now_s = 0.0;
    std::vector<Message>& messages() { return messages_; }

  private:
    std::vector<Message> messages_;
};

/// The messages of a scan: per fragment a heartbeat, then header and chunks.
inline Result<std::vector<RecordingTransport::Message>> sessionMessages(
    const std::vector<Fragment>& fragments, int64_t session_id, double interval_s,
    int32_t chunk_payload_bytes = 60000) {
    RecordingTransport transport;
    messages::FragmentSenderConfig config;
    config.session_id = session_id;
    config.chunk_payload_bytes = chunk_payload_bytes;
    messages::FragmentSender sender(config, transport);
    int64_t seq = 0;
    for (size_t i = 0; i < fragments.size(); ++i) {
        transport.now_s = interval_s * static_cast<double>(i + 1);
        messages::DeviceStatus status;
        status.session_id = session_id;
        status.fps = 30.0;
        status.tracking = messages::TrackingState::kOk;
        status.frames_processed = static_cast<int64_t>(10 * (i + 1));
        status.fragments_cut = static_cast<int32_t>(i + 1);
        status.fragments_acked = static_cast<int32_t>(i);
        status.spool_fragments = 1;
        status.spool_bytes = 100000;
        status.memory_bytes = 50 << 20;
        const auto msg = messages::toMessage(status, messages::toUtime(transport.now_s), seq++);
        PLUMB_RETURN_IF_ERROR(
            transport.publish(messages::kChannelStatus, messages::encodeMessage(msg)));
        auto encoded = messages::encodeFragment(fragments[i]);
        if (!encoded.isOk()) return encoded.status();
        PLUMB_RETURN_IF_ERROR(sender.send(fragments[i].id, std::move(*encoded), transport.now_s));
    }
    return std::move(transport.messages());
}

/// Writes the messages into an LCM log at `path` (timestamps from `start_utime` on).
inline Status writeLcmLog(const std::filesystem::path& path,
                          const std::vector<RecordingTransport::Message>& messages,
                          int64_t start_utime = 1700000000000000) {
    lcm::LogFile log(path.string(), "w");
    if (!log.good()) return ioError(path.string() + ": cannot create the LCM log");
    int64_t n = 0;
    for (const auto& m : messages) {
        lcm::LogEvent ev;
        ev.eventnum = n++;
        ev.timestamp = start_utime + static_cast<int64_t>(m.time_s * 1e6);
        ev.channel = m.channel;
        ev.datalen = static_cast<int32_t>(m.bytes.size());
        ev.data = const_cast<uint8_t*>(m.bytes.data());
        if (log.writeEvent(&ev) != 0) return ioError(path.string() + ": write failed");
    }
    return Status::ok();
}

}  // namespace plumb::monitor::testing
