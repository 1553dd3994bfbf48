// SPDX-License-Identifier: Apache-2.0
#pragma once

// The monitor's HTTP server (cpp-httplib):
//   GET /               the page (index.html; monitor.js, monitor.css beside it), embedded
//   GET /api/state      the MonitorState as JSON
//   GET /api/events     server-sent events: "event: state" with the whole state JSON on connect
//                       and on every change (checked at least every 250 ms), ": keepalive"
//                       comments in between
//   GET /api/health     {"ok": true, "version": N}
// Binds 127.0.0.1 unless told otherwise. With a token set, every request must carry it as
// `?token=T`, `Authorization: Bearer T` or `X-Plumb-Token: T`: the API (401 with a JSON error
// otherwise) and the page and its files (401 with a page saying "token required" otherwise). The
// page is opened as `/?token=T`; it is served with ?token=T on its references to its own files,
// and passes the token on to the API. While
// bound to a loopback address, requests whose Host header names another host are refused (403),
// which keeps web pages elsewhere from reaching the monitor through DNS rebinding.
//
// Thread-safety: start/stop from one thread; requests are served on the server's own threads.

#include <memory>
#include <string>

#include "common/config/schema.hpp"
#include "common/core/status.hpp"
#include "tools/monitor/monitor_state.hpp"

namespace plumb::monitor {

struct ServerConfig {
    /// Address to listen on; 127.0.0.1 keeps the monitor on this machine.
    std::string bind = "127.0.0.1";
    /// TCP port; 0 picks a free one (printed at start).
    int port = 8765;
    /// Access token; empty = none. Set one whenever bind is not a loopback address.
    std::string token;
    /// Seconds between keep-alive comments on an idle event stream.
    double keepalive_s = 10.0;
    /// Event streams served at once (each holds a server thread); more get 503.
    int max_event_streams = 4;
};
void describe(config::Schema& s, ServerConfig& c);

/// True for 127.0.0.0/8, ::1 and "localhost".
bool isLoopbackAddress(const std::string& host);

class MonitorServer {
  public:
    /// Binds and starts serving on a thread. IoError when the address cannot be bound,
    /// InvalidArgument for a bad port or keep-alive.
    static Result<std::unique_ptr<MonitorServer>> start(const ServerConfig& config,
                                                        MonitorState& state);
    ~MonitorServer();

    /// Stops accepting, ends event streams and joins the server thread.
    void stop();
    /// The bound port (the chosen one when config.port was 0).
    int port() const;
    /// "http://<bind>:<port>/", never with the token (it is a secret: `plumb monitor` prints
    /// this URL; whoever set the token adds "?token=..." to open the page).
    std::string url() const;

  private:
    struct Impl;
    explicit MonitorServer(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace plumb::monitor
