// SPDX-License-Identifier: Apache-2.0
#include "tools/monitor/server.hpp"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <httplib.h>
#include <sys/socket.h>

#include <atomic>
#include <cctype>
#include <chrono>
#include <string_view>
#include <thread>

#include "tools/monitor/web_assets.hpp"

namespace plumb::monitor {

void describe(config::Schema& s, ServerConfig& c) {
    s.field("bind", c.bind, "address to listen on (127.0.0.1 keeps it on this machine)");
    s.field("port", c.port, "TCP port; 0 picks a free one").min(0).max(65535);
    s.field("token", c.token, "access token required on every request; empty = none");
    s.field("keepalive_s", c.keepalive_s, "seconds between keep-alive comments on event streams",
            "s")
        .positive()
        .max(300.0);
    s.field("max_event_streams", c.max_event_streams, "event streams served at once")
        .min(1)
        .max(64);
}

bool isLoopbackAddress(const std::string& host) {
    if (host == "localhost" || host == "::1" || host == "[::1]") return true;
    in_addr a{};
    if (inet_pton(AF_INET, host.c_str(), &a) == 1) return (ntohl(a.s_addr) >> 24) == 127;
    return false;
}

namespace {

/// Compares without an early exit, so response time does not reveal how much of a guess matched.
bool constantTimeEquals(const std::string& a, const std::string& b) {
    unsigned char diff = a.size() == b.size() ? 0 : 1;
    const size_t n = std::max(a.size(), b.size());
    for (size_t i = 0; i < n; ++i) {
        const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
        const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
        diff |= static_cast<unsigned char>(x ^ y);
    }
    return diff == 0;
}

/// The host part of a Host header ("127.0.0.1:8765" -> "127.0.0.1", "[::1]:80" -> "::1").
std::string hostOf(const std::string& header) {
    if (!header.empty() && header.front() == '[') {
        const size_t close = header.find(']');
        return close == std::string::npos ? header : header.substr(1, close - 1);
    }
    const size_t colon = header.find(':');
    return colon == std::string::npos ? header : header.substr(0, colon);
}

void setJsonError(httplib::Response& res, int code, const std::string& message) {
    res.status = code;
    res.set_content(nlohmann::json{{"error", message}}.dump(), "application/json");
}

/// Percent-encodes everything but RFC 3986's unreserved characters, so the result is safe in a
/// query string and inside an HTML attribute.
std::string percentEncode(const std::string& text) {
    std::string out;
    for (const unsigned char c : text) {
        if (std::isalnum(c) != 0 || c == '-' || c == '.' || c == '_' || c == '~') {
            out += static_cast<char>(c);
        } else {
            out += fmt::format("%{:02X}", c);
        }
    }
    return out;
}

/// index.html with every reference to another embedded file ("monitor.js", ...) carrying
/// ?token=<token>, so that the browser's requests for them pass the token check too.
std::string pageWithToken(std::string_view html, const std::string& token) {
    std::string page(html);
    const std::string query = "?token=" + percentEncode(token);
    for (const WebAsset& asset : webAssets()) {
        const std::string_view name = std::string_view(asset.path).substr(1);
        if (name == "index.html") continue;
        const std::string quoted = fmt::format("\"{}\"", name);
        const std::string with = fmt::format("\"{}{}\"", name, query);
        for (size_t at = page.find(quoted); at != std::string::npos;
             at = page.find(quoted, at + with.size())) {
            page.replace(at, quoted.size(), with);
        }
    }
    return page;
}

/// What a browser gets for a page request without the right token: a page that says so and
/// loads nothing (the monitor's own files need the token too).
void setTokenRequiredPage(httplib::Response& res, bool token_given) {
    const char* why = token_given ? "token required: the token in the address is wrong"
                                  : "token required: add ?token=&lt;token&gt; to the address";
    res.status = 401;
    res.set_header("Content-Security-Policy", "default-src 'none'; style-src 'unsafe-inline'");
    res.set_content(
        fmt::format("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n"
                    "<meta charset=\"utf-8\">\n<title>plumb monitor: token required"
                    "</title>\n<link rel=\"icon\" href=\"data:,\">\n</head>\n"
                    "<body style=\"font: 14px system-ui, sans-serif\">\n"
                    "<h1>plumb monitor</h1>\n<p><span id=\"connection\">{}</span></p>\n"
                    "<p>This monitor was started with --token (or PLUMB_MONITOR_TOKEN): "
                    "open its address with ?token=&lt;token&gt; appended.</p>\n"
                    "</body>\n</html>\n",
                    why),
        "text/html; charset=utf-8");
}

}  // namespace

struct MonitorServer::Impl {
    ServerConfig config;
    MonitorState* state = nullptr;
    httplib::Server server;
    std::thread thread;
    int port = 0;
    std::atomic<bool> stopping{false};
    std::atomic<int> streams{0};

    bool authorised(const httplib::Request& req) const {
        if (config.token.empty()) return true;
        if (req.has_param("token") &&
            constantTimeEquals(req.get_param_value("token"), config.token))
            return true;
        const std::string auth = req.get_header_value("Authorization");
        if (auth.rfind("Bearer ", 0) == 0 && constantTimeEquals(auth.substr(7), config.token))
            return true;
        return req.has_header("X-Plumb-Token") &&
               constantTimeEquals(req.get_header_value("X-Plumb-Token"), config.token);
    }

    void install() {
        server.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
            res.set_header("X-Content-Type-Options", "nosniff");
            res.set_header("Cache-Control", "no-store");
            if (isLoopbackAddress(config.bind) &&
                !isLoopbackAddress(hostOf(req.get_header_value("Host")))) {
                setJsonError(res, 403, "the monitor answers only to loopback host names");
                return httplib::Server::HandlerResponse::Handled;
            }
            // With a token, every request needs it: the API, and the page and its files too
            // (the page passes the ?token= it was opened with on to its files and the API).
            if (!authorised(req)) {
                if (req.path.rfind("/api/", 0) == 0) {
                    setJsonError(res, 401,
                                 "access token required: add ?token=<token> to the address, or "
                                 "send 'Authorization: Bearer <token>'");
                } else {
                    setTokenRequiredPage(res, req.has_param("token"));
                }
                return httplib::Server::HandlerResponse::Handled;
            }
            return httplib::Server::HandlerResponse::Unhandled;
        });

        server.Get("/api/state", [this](const httplib::Request&, httplib::Response& res) {
            res.set_content(state->toJsonText(), "application/json");
        });
        server.Get("/api/health", [this](const httplib::Request&, httplib::Response& res) {
            res.set_content(nlohmann::json{{"ok", true}, {"version", state->version()}}.dump(),
                            "application/json");
        });
        server.Get("/api/events", [this](const httplib::Request&, httplib::Response& res) {
            if (streams.fetch_add(1) >= config.max_event_streams) {
                streams.fetch_sub(1);
                setJsonError(res, 503, "too many event streams open");
                return;
            }
            res.set_header("X-Accel-Buffering", "no");
            auto last_sent = std::make_shared<uint64_t>(0);
            auto last_write = std::make_shared<std::chrono::steady_clock::time_point>(
                std::chrono::steady_clock::now());
            res.set_chunked_content_provider(
                "text/event-stream",
                [this, last_sent, last_write](size_t, httplib::DataSink& sink) {
                    if (stopping.load()) return false;
                    const uint64_t now_version =
                        *last_sent == 0
                            ? state->version()
                            : state->waitForChange(*last_sent, std::chrono::milliseconds(250));
                    if (stopping.load()) return false;
                    std::string out;
                    const auto now = std::chrono::steady_clock::now();
                    if (now_version != *last_sent) {
                        uint64_t version = 0;
                        const std::string text = state->toJsonText(&version);
                        out = fmt::format("id: {}\nevent: state\ndata: {}\n\n", version, text);
                        *last_sent = version;
                    } else if (std::chrono::duration<double>(now - *last_write).count() >=
                               config.keepalive_s) {
                        out = ": keepalive\n\n";
                    }
                    if (!out.empty()) {
                        if (!sink.write(out.data(), out.size())) return false;
                        *last_write = now;
                    }
                    return true;
                },
                [this](bool) { streams.fetch_sub(1); });
        });
        server.Get(
            R"(/[A-Za-z0-9_.\-]*)", [this](const httplib::Request& req, httplib::Response& res) {
                const WebAsset* asset = findWebAsset(req.path);
                if (asset == nullptr) {
                    setJsonError(res, 404, "no such page: " + req.path);
                    return;
                }
                res.set_header("Content-Security-Policy",
                               "default-src 'self'; img-src 'self' data:; connect-src 'self'");
                const bool page = std::string_view(asset->path) == "/index.html";
                res.set_content(page && !config.token.empty()
                                    ? pageWithToken(asset->bytes, config.token)
                                    : std::string(asset->bytes),
                                asset->content_type);
            });
    }
};

MonitorServer::MonitorServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Result<std::unique_ptr<MonitorServer>> MonitorServer::start(const ServerConfig& config,
                                                            MonitorState& state) {
    if (config.port < 0 || config.port > 65535) {
        return invalidArgument(fmt::format("monitor: port {} outside [0, 65535]", config.port));
    }
    if (!(config.keepalive_s > 0.0)) return invalidArgument("monitor: keepalive_s must be > 0");
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    impl->state = &state;
    impl->install();
    // httplib's default also sets SO_REUSEPORT, which lets a second server bind the same port
    // and silently share its connections; a busy port must be an error instead.
    impl->server.set_socket_options([](int sock) {
        int yes = 1;
        setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
    });
    if (config.port == 0) {
        impl->port = impl->server.bind_to_any_port(config.bind);
        if (impl->port <= 0) {
            return ioError(fmt::format("monitor: cannot listen on {} (any port)", config.bind));
        }
    } else {
        if (!impl->server.bind_to_port(config.bind, config.port)) {
            return ioError(
                fmt::format("monitor: cannot listen on {}:{} (in use or not an address "
                            "of this machine?)",
                            config.bind, config.port));
        }
        impl->port = config.port;
    }
    Impl* raw = impl.get();
    raw->thread = std::thread([raw] { raw->server.listen_after_bind(); });
    // httplib's stop() does nothing until the listen loop runs: wait for it, so that a stop()
    // right after start() cannot leave the loop running (and join() hanging).
    for (int i = 0; i < 5000 && !raw->server.is_running(); ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return std::unique_ptr<MonitorServer>(new MonitorServer(std::move(impl)));
}

MonitorServer::~MonitorServer() { stop(); }

void MonitorServer::stop() {
    if (!impl_ || impl_->stopping.exchange(true)) return;
    impl_->state->notifyAll();
    impl_->server.stop();
    if (impl_->thread.joinable()) impl_->thread.join();
}

int MonitorServer::port() const { return impl_->port; }

std::string MonitorServer::url() const {
    const std::string& host = impl_->config.bind;
    const std::string shown = host == "0.0.0.0" ? "127.0.0.1" : host;
    return fmt::format("http://{}:{}/", shown, impl_->port);  // never the token: a secret
}

}  // namespace plumb::monitor
