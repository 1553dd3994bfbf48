// SPDX-License-Identifier: Apache-2.0
// The monitor's HTTP API: state JSON, token enforcement, host check, static page, server-sent
// events.

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "tests/monitor/monitor_fixtures.hpp"
#include "tools/monitor/server.hpp"
#include "tools/monitor/web_assets.hpp"

// After Eigen: httplib pulls in <resolv.h>, whose _res macro breaks Eigen's headers.
#include <httplib.h>

namespace plumb::monitor {
namespace {

using nlohmann::json;

struct Served {
    MonitorState state;
    std::unique_ptr<MonitorServer> server;
    explicit Served(ServerConfig config = {}) {
        config.port = 0;
        auto s = MonitorServer::start(config, state);
        PLUMB_CHECK(s.isOk()) << s.status().message();
        server = std::move(*s);
    }
    httplib::Client client() const {
        httplib::Client c("127.0.0.1", server->port());
        c.set_read_timeout(10, 0);
        return c;
    }
};

TEST(MonitorServer, StateJsonHasTheRequiredKeys) {
    Served s;
    s.state.addFragment(testing::roomFragment(0), 3, "lcm");
    s.state.addFragment(testing::roomFragment(1), 3, "lcm");
    auto res = s.client().Get("/api/state");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
    EXPECT_EQ(res->get_header_value("Content-Type"), "application/json");
    const json j = json::parse(res->body);
    for (const char* key : {"fragments", "edges", "layout", "device", "coverage", "source"}) {
        EXPECT_TRUE(j.contains(key)) << key;
    }
    ASSERT_EQ(j["fragments"].size(), 2u);
    for (const char* key : {"id", "frames", "pose", "num_points"}) {
        EXPECT_TRUE(j["fragments"][0].contains(key)) << key;
    }
    EXPECT_EQ(j["fragments"][1]["num_points"], testing::roomFragment(1).points_F.size());
    EXPECT_EQ(j["edges"].size(), 1u);

    res = s.client().Get("/api/health");
    ASSERT_TRUE(res);
    EXPECT_EQ(json::parse(res->body)["ok"], true);
}

TEST(MonitorServer, ServesTheEmbeddedPage) {
    Served s;
    auto res = s.client().Get("/");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
    EXPECT_NE(res->get_header_value("Content-Type").find("text/html"), std::string::npos);
    EXPECT_NE(res->body.find("plumb monitor"), std::string::npos);
    EXPECT_EQ(res->body, std::string(findWebAsset("/index.html")->bytes));
    // Nothing is loaded from elsewhere: the page may only reach its own origin.
    EXPECT_NE(res->get_header_value("Content-Security-Policy").find("default-src 'self'"),
              std::string::npos);
    EXPECT_EQ(res->body.find("http://"), res->body.find("http://www.w3.org/2000/svg"));
    EXPECT_EQ(res->body.find("https://"), std::string::npos);
    for (const char* path : {"/monitor.js", "/monitor.css"}) {
        res = s.client().Get(path);
        ASSERT_TRUE(res) << path;
        EXPECT_EQ(res->status, 200) << path;
        EXPECT_GT(res->body.size(), 500u) << path;
    }
    res = s.client().Get("/missing.js");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 404);
}

TEST(MonitorServer, TokenIsRequiredWhenSet) {
    ServerConfig config;
    config.token = "s3cret-token";
    Served s(config);
    auto c = s.client();
    for (const char* path : {"/api/state", "/api/events", "/api/health"}) {
        auto res = c.Get(path);
        ASSERT_TRUE(res) << path;
        EXPECT_EQ(res->status, 401) << path;
        EXPECT_EQ(res->body.find("\"fragments\""), std::string::npos) << path;
    }
    // The page and its files need it too: without it a page that says so and loads nothing.
    for (const char* path : {"/", "/index.html", "/monitor.js", "/monitor.css", "/favicon.svg"}) {
        auto res = c.Get(path);
        ASSERT_TRUE(res) << path;
        EXPECT_EQ(res->status, 401) << path;
        EXPECT_NE(res->get_header_value("Content-Type").find("text/html"), std::string::npos);
        EXPECT_NE(res->body.find(">token required: add ?token="), std::string::npos) << res->body;
        EXPECT_EQ(res->body.find("monitor.js"), std::string::npos) << path;
        EXPECT_EQ(res->get_header_value("Content-Security-Policy").find("default-src 'none'"), 0u);
    }
    auto res = c.Get("/?token=wrong");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 401);
    EXPECT_NE(res->body.find(">token required: the token in the address is wrong<"),
              std::string::npos)
        << res->body;
    res = c.Get("/monitor.js?token=s3cret-toke");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 401);
    // With it, the page comes with the token on every reference to its own files, so that the
    // browser's requests for them pass too; the files themselves are served unchanged.
    res = c.Get("/?token=s3cret-token");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
    for (const char* file : {"monitor.js", "monitor.css", "favicon.svg"}) {
        const std::string name = std::string("\"") + file;
        EXPECT_NE(res->body.find(name + "?token=s3cret-token\""), std::string::npos) << file;
        EXPECT_EQ(res->body.find(name + "\""), std::string::npos) << file;
    }
    for (const char* path : {"/monitor.js?token=s3cret-token", "/favicon.svg?token=s3cret-token"}) {
        res = c.Get(path);
        ASSERT_TRUE(res) << path;
        EXPECT_EQ(res->status, 200) << path;
    }
    EXPECT_EQ(res->body, std::string(findWebAsset("/favicon.svg")->bytes));
    res = c.Get("/", {{"Authorization", "Bearer s3cret-token"}});
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
    res = c.Get("/api/state?token=wrong");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 401);
    res = c.Get("/api/state?token=s3cret-toke");  // a prefix is not the token
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 401);
    res = c.Get("/api/state?token=s3cret-token");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
    res = c.Get("/api/state", {{"Authorization", "Bearer s3cret-token"}});
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
    res = c.Get("/api/state", {{"Authorization", "Bearer nope"}});
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 401);
    res = c.Get("/api/state", {{"X-Plumb-Token", "s3cret-token"}});
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
    // Issue 32, item 9: the URL plumb monitor prints never carries the secret.
    EXPECT_EQ(s.server->url().find("s3cret-token"), std::string::npos) << s.server->url();
}

TEST(MonitorServer, ATokenIsEncodedInThePage) {
    ServerConfig config;
    config.token = "a b&\"<x>/é";
    Served s(config);
    auto res = s.client().Get("/?token=a%20b%26%22%3Cx%3E%2F%C3%A9");
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 200);
    EXPECT_NE(res->body.find("\"monitor.js?token=a%20b%26%22%3Cx%3E%2F%C3%A9\""), std::string::npos)
        << res->body;
    EXPECT_EQ(res->body.find("<x>"), std::string::npos);
    res = s.client().Get("/monitor.js?token=a%20b%26%22%3Cx%3E%2F%C3%A9");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
}

TEST(MonitorServer, RefusesForeignHostNamesOnLoopback) {
    Served s;
    auto res = s.client().Get("/api/state", {{"Host", "evil.example:8765"}});
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 403);
    res = s.client().Get("/api/state", {{"Host", "localhost:8765"}});
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
    EXPECT_TRUE(isLoopbackAddress("127.0.0.1"));
    EXPECT_TRUE(isLoopbackAddress("127.1.2.3"));
    EXPECT_TRUE(isLoopbackAddress("::1"));
    EXPECT_FALSE(isLoopbackAddress("0.0.0.0"));
    EXPECT_FALSE(isLoopbackAddress("192.168.1.1"));
}

TEST(MonitorServer, BusyPortIsAnIoError) {
    Served s;
    MonitorState other;
    ServerConfig config;
    config.port = s.server->port();
    auto r = MonitorServer::start(config, other);
    ASSERT_FALSE(r.isOk());
    EXPECT_EQ(r.status().code(), StatusCode::kIoError);
    config.port = 70000;
    r = MonitorServer::start(config, other);
    ASSERT_FALSE(r.isOk());
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
}

/// Reads server-sent events on a thread and keeps the parsed "state" payloads.
class EventReader {
  public:
    EventReader(int port, std::string path) : client_("127.0.0.1", port) {
        client_.set_read_timeout(30, 0);
        thread_ = std::thread([this, path] {
            auto res = client_.Get(path.c_str(), [this](const char* data, size_t n) {
                std::lock_guard lock(mutex_);
                buffer_.append(data, n);
                size_t end;
                while ((end = buffer_.find("\n\n")) != std::string::npos) {
                    const std::string event = buffer_.substr(0, end);
                    buffer_.erase(0, end + 2);
                    const size_t data_at = event.find("\ndata: ");
                    if (event.find("event: state") != std::string::npos &&
                        data_at != std::string::npos) {
                        states_.push_back(json::parse(event.substr(data_at + 7)));
                    }
                }
                return !stop_.load();
            });
            if (res) status_ = res->status;
        });
    }
    ~EventReader() {
        stop_ = true;
        client_.stop();
        if (thread_.joinable()) thread_.join();
    }
    /// Waits (up to 20 s) until a state satisfying `pred` arrived.
    template <typename Pred>
    bool waitFor(Pred pred) {
        for (int i = 0; i < 2000; ++i) {
            {
                std::lock_guard lock(mutex_);
                for (const json& s : states_) {
                    if (pred(s)) return true;
                }
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        return false;
    }
    size_t count() {
        std::lock_guard lock(mutex_);
        return states_.size();
    }

  private:
    httplib::Client client_;
    std::thread thread_;
    std::mutex mutex_;
    std::string buffer_;
    std::vector<json> states_;
    std::atomic<bool> stop_{false};
    int status_ = 0;
};

TEST(MonitorServer, EventsPushTheStateOnConnectAndOnEveryFragment) {
    Served s;
    EventReader events(s.server->port(), "/api/events");
    ASSERT_TRUE(events.waitFor([](const json& j) { return j["fragments"].empty(); }))
        << "no initial state event";
    for (int k = 0; k < 3; ++k) {
        s.state.addFragment(testing::roomFragment(k), 1, "lcm");
        ASSERT_TRUE(events.waitFor([k](const json& j) {
            return j["fragments"].size() == static_cast<size_t>(k + 1);
        })) << "no event for fragment "
            << k;
    }
    EXPECT_GE(events.count(), 4u);
}

TEST(MonitorServer, EventsNeedTheTokenToo) {
    ServerConfig config;
    config.token = "tok-12345";
    Served s(config);
    EventReader events(s.server->port(), "/api/events?token=tok-12345");
    s.state.addFragment(testing::roomFragment(0), 1, "lcm");
    EXPECT_TRUE(events.waitFor([](const json& j) { return j["fragments"].size() == 1; }));
}

TEST(MonitorServer, StopEndsOpenEventStreams) {
    auto s = std::make_unique<Served>();
    EventReader events(s->server->port(), "/api/events");
    ASSERT_TRUE(events.waitFor([](const json&) { return true; }));
    const int port = s->server->port();
    s->server->stop();  // must return although a stream is open
    httplib::Client c("127.0.0.1", port);
    c.set_connection_timeout(2, 0);
    EXPECT_FALSE(c.Get("/api/health"));  // nobody listens any more
    s.reset();
}

}  // namespace
}  // namespace plumb::monitor
