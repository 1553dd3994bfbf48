// SPDX-License-Identifier: Apache-2.0
#pragma once

// The publish/subscribe seam between the protocol classes and the network. The protocol classes
// (FragmentSender, FragmentAssembler, AuthenticatedTransport) only publish; their owner routes
// received messages to them. Implementations: LcmTransport (messages/lcm_transport.hpp), and
// in-memory transports in tests.
//
// Thread-safety: a Transport is used from one thread (the one that publishes and dispatches);
// implementations say where they differ.

#include <cstdint>
#include <functional>
#include <span>
#include <string>

#include "common/core/status.hpp"

namespace plumb::messages {

class Transport {
  public:
    /// Called with the channel and the raw message; the span is valid only during the call.
    using Handler = std::function<void(const std::string& channel, std::span<const uint8_t> bytes)>;

    virtual ~Transport() = default;

    /// Sends `bytes` on `channel`. An error means the message certainly did not go out; success
    /// does not mean it arrived (the chunk/ack protocol handles loss).
    virtual Status publish(const std::string& channel, std::span<const uint8_t> bytes) = 0;

    /// Calls `handler` for every later message on exactly `channel`. Handlers run inside the
    /// transport's own dispatch call (e.g. LcmTransport::handle), on the caller's thread.
    virtual Status subscribe(const std::string& channel, Handler handler) = 0;
};

}  // namespace plumb::messages
