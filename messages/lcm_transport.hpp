// SPDX-License-Identifier: Apache-2.0
#pragma once

// Transport over LCM. `udpm://239.255.76.67:7667?ttl=0` (the default) keeps traffic on the host;
// `memq://` is in-process (tests). No threads: the owner calls handle() to dispatch.
// Not thread-safe: one thread publishes, subscribes and handles.

#include <lcm/lcm-cpp.hpp>

#include <memory>
#include <string>
#include <vector>

#include "messages/channels.hpp"
#include "messages/lcm_url.hpp"  // keepsTrafficOnHost
#include "messages/transport.hpp"

namespace plumb::messages {

class LcmTransport final : public Transport {
  public:
    /// Opens LCM at `url`; NotFound/IoError when LCM cannot be initialised (e.g. no multicast).
    static Result<std::unique_ptr<LcmTransport>> create(const std::string& url = kDefaultLcmUrl);
    ~LcmTransport() override;

    Status publish(const std::string& channel, std::span<const uint8_t> bytes) override;
    /// `channel` must be a plain name (LCM reads it as a regular expression).
    Status subscribe(const std::string& channel, Handler handler) override;

    /// Dispatches messages for up to `timeout_ms` (0: only what is pending). Returns true when at
    /// least one message was handled.
    Result<bool> handle(int timeout_ms);

    /// File descriptor that becomes readable when messages wait (for poll/select).
    int fileno();

    const std::string& url() const { return url_; }

  private:
    explicit LcmTransport(std::string url);

    std::string url_;
    lcm::LCM lcm_;
    std::vector<std::unique_ptr<Handler>> handlers_;
};

}  // namespace plumb::messages
