// SPDX-License-Identifier: Apache-2.0
#include "messages/lcm_transport.hpp"

#include <fmt/format.h>

#include <limits>

namespace plumb::messages {
namespace {

void dispatch(const lcm::ReceiveBuffer* buffer, const std::string& channel,
              Transport::Handler* handler) {
    (*handler)(channel, std::span<const uint8_t>(static_cast<const uint8_t*>(buffer->data),
                                                 buffer->data_size));
}

}  // namespace

LcmTransport::LcmTransport(std::string url) : url_(std::move(url)), lcm_(url_) {}

LcmTransport::~LcmTransport() = default;

Result<std::unique_ptr<LcmTransport>> LcmTransport::create(const std::string& url) {
    std::unique_ptr<LcmTransport> t(new LcmTransport(url));
    if (!t->lcm_.good()) {
        return ioError(fmt::format("LCM: cannot open '{}' (no multicast route or bad URL?)", url));
    }
    return t;
}

Status LcmTransport::publish(const std::string& channel, std::span<const uint8_t> bytes) {
    if (bytes.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
        return invalidArgument(
            fmt::format("LCM: message of {} bytes on {}", bytes.size(), channel));
    }
    if (lcm_.publish(channel, bytes.data(), static_cast<unsigned int>(bytes.size())) != 0) {
        return ioError(fmt::format("LCM: publishing {} bytes on {} via {} failed", bytes.size(),
                                   channel, url_));
    }
    return Status::ok();
}

Status LcmTransport::subscribe(const std::string& channel, Handler handler) {
    if (channel.empty() || channel.find_first_of(".*+?[](){}|^$\\") != std::string::npos) {
        return invalidArgument(fmt::format("LCM: channel '{}' is not a plain name", channel));
    }
    handlers_.push_back(std::make_unique<Handler>(std::move(handler)));
    if (lcm_.subscribeFunction(channel, &dispatch, handlers_.back().get()) == nullptr) {
        handlers_.pop_back();
        return ioError(fmt::format("LCM: cannot subscribe to {}", channel));
    }
    return Status::ok();
}

Result<bool> LcmTransport::handle(int timeout_ms) {
    const int r = lcm_.handleTimeout(timeout_ms);
    if (r < 0) return ioError(fmt::format("LCM: handling messages on {} failed", url_));
    return r > 0;
}

int LcmTransport::fileno() { return lcm_.getFileno(); }

}  // namespace plumb::messages
