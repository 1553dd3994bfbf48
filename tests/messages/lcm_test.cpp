// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <map>

#include "messages/auth.hpp"
#include "messages/channels.hpp"
#include "messages/fragment_assembler.hpp"
#include "messages/fragment_sender.hpp"
#include "messages/lcm_transport.hpp"

namespace plumb::messages {
namespace {

TEST(LcmTransport, UrlPolicy) {
    EXPECT_TRUE(keepsTrafficOnHost(kDefaultLcmUrl));
    EXPECT_TRUE(keepsTrafficOnHost("memq://"));
    EXPECT_TRUE(keepsTrafficOnHost("udpm://239.255.76.67:7667?recv_buf_size=100&ttl=0"));
    EXPECT_FALSE(keepsTrafficOnHost("udpm://239.255.76.67:7667?ttl=1"));
    EXPECT_FALSE(keepsTrafficOnHost("udpm://239.255.76.67:7667?ttl=01"));
    EXPECT_FALSE(keepsTrafficOnHost("udpm://239.255.76.67:7667"));
    EXPECT_FALSE(keepsTrafficOnHost("file:///tmp/log?mode=w"));
}

// Runs the fragment protocol (signed when `key` is set) over one LCM instance.
void runOverLcm(const std::string& url, const std::string& key) {
    auto lcm = LcmTransport::create(url);
    ASSERT_TRUE(lcm.isOk()) << lcm.status().toString();
    AuthConfig device_auth, backend_auth;
    device_auth.key.assign(key.begin(), key.end());
    device_auth.sender_id = 1;
    backend_auth.key = device_auth.key;
    backend_auth.sender_id = 2;
    AuthenticatedTransport device(**lcm, device_auth);
    AuthenticatedTransport backend(**lcm, backend_auth);
    FragmentSenderConfig sc;
    sc.session_id = 1234;
    FragmentSender sender(sc, device);  // 60000-byte chunks
    FragmentAssembler assembler(FragmentAssemblerConfig{}, backend);
    double now = 0.0;
    ASSERT_TRUE(device
                    .subscribe(kChannelFragmentAck,
                               [&](const std::string& c, std::span<const uint8_t> b) {
                                   EXPECT_TRUE(sender.onMessage(c, b, now).isOk());
                               })
                    .isOk());
    for (const char* ch : {kChannelFragmentHeader, kChannelFragmentChunk}) {
        ASSERT_TRUE(backend
                        .subscribe(ch,
                                   [&](const std::string& c, std::span<const uint8_t> b) {
                                       EXPECT_TRUE(assembler.onMessage(c, b, now).isOk());
                                   })
                        .isOk());
    }
    std::vector<Bytes> payloads;
    for (uint32_t i = 0; i < 3; ++i) {
        Bytes p(150000 + 12345 * i);
        for (size_t k = 0; k < p.size(); ++k) p[k] = static_cast<uint8_t>((k * 31) ^ (k >> 9) ^ i);
        payloads.push_back(p);
        ASSERT_TRUE(sender.send(i, p, now).isOk());
    }
    std::map<uint32_t, Bytes> store;
    for (int step = 0; step < 400 && sender.numInFlight() > 0; ++step) {
        auto handled = (*lcm)->handle(step == 0 ? 0 : 5);
        ASSERT_TRUE(handled.isOk());
        for (auto& c : assembler.takeCompleted()) {
            EXPECT_TRUE(store.emplace(c.fragment_id, c.bytes).second);
            assembler.acknowledge(c.session_id, c.fragment_id, now);
        }
        now += 0.01;
        sender.poll(now);
        assembler.poll(now);
    }
    EXPECT_EQ(sender.numInFlight(), 0u);
    ASSERT_EQ(store.size(), payloads.size());
    for (uint32_t i = 0; i < payloads.size(); ++i) EXPECT_EQ(store[i], payloads[i]);
    if (!key.empty()) {
        EXPECT_GT(backend.stats().accepted, 0u);
        EXPECT_EQ(backend.stats().rejected(), 0u);
    }
}

TEST(LcmTransport, FragmentsOverMemq) { runOverLcm("memq://", ""); }

TEST(LcmTransport, SignedFragmentsOverMemq) {
    runOverLcm("memq://", "a shared key of thirty-two bytes");
}

TEST(LcmTransport, RejectsRegexChannelNames) {
    auto lcm = LcmTransport::create("memq://");
    ASSERT_TRUE(lcm.isOk());
    EXPECT_FALSE(
        (*lcm)->subscribe("PLUMB_.*", [](const std::string&, std::span<const uint8_t>) {}).isOk());
    EXPECT_FALSE(LcmTransport::create("nonsense://x").isOk());
}

}  // namespace
}  // namespace plumb::messages
