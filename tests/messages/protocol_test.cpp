// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <map>
#include <random>

#include "messages/channels.hpp"
#include "messages/crc32.hpp"
#include "messages/fragment_assembler.hpp"
#include "messages/fragment_sender.hpp"
#include "tests/messages/lossy_transport.hpp"

namespace plumb::messages {
namespace {

using testing::LossyConfig;
using testing::LossyHub;

std::vector<Bytes> makePayloads(size_t count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::vector<Bytes> out;
    for (size_t i = 0; i < count; ++i) {
        Bytes b(1 + rng() % 50000);  // 1 byte to ~13 chunks of 4000 bytes
        for (auto& x : b) x = static_cast<uint8_t>(rng());
        out.push_back(std::move(b));
    }
    return out;
}

// Device and backend on one hub; the backend "persists" into `store` (fragment id -> bytes).
struct Link {
    explicit Link(LossyConfig net, int64_t session = 77) : hub(net) {
        FragmentSenderConfig sc;
        sc.session_id = session;
        sc.chunk_payload_bytes = 4000;
        sender = std::make_unique<FragmentSender>(sc, hub);
        newBackend();
        for (const char* ch : {kChannelFragmentAck, kChannelRetransmit}) {
            (void)hub.subscribe(ch, [this](const std::string& c, std::span<const uint8_t> b) {
                (void)sender->onMessage(c, b, now);
            });
        }
        for (const char* ch : {kChannelFragmentHeader, kChannelFragmentChunk}) {
            (void)hub.subscribe(ch, [this](const std::string& c, std::span<const uint8_t> b) {
                if (assembler) (void)assembler->onMessage(c, b, now);
            });
        }
    }

    // A (re)started backend resumes from the store.
    void newBackend() {
        assembler = std::make_unique<FragmentAssembler>(FragmentAssemblerConfig{}, hub);
        for (const auto& [id, bytes] : store) assembler->markPersisted(77, id, crc32(bytes));
    }

    // One step of simulated time: deliver, persist and acknowledge, poll timers.
    void step(double dt = 0.05) {
        hub.deliver();
        if (assembler) {
            for (CompletedFragment& c : assembler->takeCompleted()) {
                ++yields[c.fragment_id];
                store[c.fragment_id] = c.bytes;
                assembler->acknowledge(c.session_id, c.fragment_id, now);
            }
        }
        for (uint32_t id : sender->takeAcknowledged()) acked.push_back(id);
        now += dt;
        sender->poll(now);
        if (assembler) assembler->poll(now);
    }

    bool runUntilDone(int max_steps) {
        for (int i = 0; i < max_steps; ++i) {
            step();
            if (sender->numInFlight() == 0 && hub.idle()) return true;
        }
        return false;
    }

    LossyHub hub;
    double now = 0.0;
    std::unique_ptr<FragmentSender> sender;
    std::unique_ptr<FragmentAssembler> assembler;
    std::map<uint32_t, Bytes> store;
    std::map<uint32_t, int> yields;
    std::vector<uint32_t> acked;
};

TEST(FragmentProtocol, PerfectNetworkNeedsNoRetransmission) {
    Link link(LossyConfig{});
    const auto payloads = makePayloads(5, 1);
    for (uint32_t i = 0; i < payloads.size(); ++i) {
        ASSERT_TRUE(link.sender->send(i, payloads[i], link.now).isOk());
    }
    ASSERT_TRUE(link.runUntilDone(20));
    for (uint32_t i = 0; i < payloads.size(); ++i) EXPECT_EQ(link.store[i], payloads[i]);
    EXPECT_EQ(link.sender->stats().chunks_resent, 0u);
    EXPECT_EQ(link.assembler->stats().requests_sent, 0u);
    EXPECT_EQ(link.acked.size(), payloads.size());
}

// The acceptance scenario: 10 % of all messages (chunks, headers, acks, requests) lost, the rest
// duplicated 10 % of the time and reordered; every fragment arrives bit-identical, exactly once.
TEST(FragmentProtocol, LossyReorderingDuplicatingNetworkDeliversEverythingExactlyOnce) {
    for (uint32_t seed : {1u, 2u, 3u, 4u, 5u}) {
        Link link(LossyConfig{0.10, 0.10, true, seed});
        const auto payloads = makePayloads(12, 100 + seed);
        for (uint32_t i = 0; i < payloads.size(); ++i) {
            ASSERT_TRUE(link.sender->send(i, payloads[i], link.now).isOk());
        }
        ASSERT_TRUE(link.runUntilDone(2000)) << "seed " << seed;
        for (uint32_t i = 0; i < payloads.size(); ++i) {
            EXPECT_EQ(link.store[i], payloads[i]) << "seed " << seed << " fragment " << i;
            EXPECT_EQ(link.yields[i], 1) << "seed " << seed << " fragment " << i;
        }
        std::sort(link.acked.begin(), link.acked.end());
        EXPECT_EQ(link.acked.size(), payloads.size());
        EXPECT_GT(link.hub.dropped(), 0u);
        EXPECT_GT(link.hub.duplicated(), 0u);
        EXPECT_GT(link.sender->stats().chunks_resent, 0u);
        EXPECT_GT(link.assembler->stats().duplicate_chunks, 0u);
        EXPECT_EQ(link.assembler->stats().chunk_crc_failures, 0u);
    }
}

TEST(FragmentProtocol, SurvivesHeavyLoss) {
    Link link(LossyConfig{0.40, 0.2, true, 9});
    const auto payloads = makePayloads(6, 9);
    for (uint32_t i = 0; i < payloads.size(); ++i) {
        ASSERT_TRUE(link.sender->send(i, payloads[i], link.now).isOk());
    }
    ASSERT_TRUE(link.runUntilDone(5000));
    for (uint32_t i = 0; i < payloads.size(); ++i) {
        EXPECT_EQ(link.store[i], payloads[i]);
        EXPECT_EQ(link.yields[i], 1);
    }
}

TEST(FragmentProtocol, BackendRestartLosesNothingAndDuplicatesNothing) {
    Link link(LossyConfig{0.10, 0.05, true, 21});
    const auto payloads = makePayloads(10, 21);
    for (uint32_t i = 0; i < 5; ++i) ASSERT_TRUE(link.sender->send(i, payloads[i], 0.0).isOk());
    for (int s = 0; s < 6; ++s) link.step();
    const size_t persisted_before = link.store.size();
    // The backend dies (losing partial fragments and unsent acks) while the device keeps sending.
    link.assembler.reset();
    for (uint32_t i = 5; i < 10; ++i) {
        ASSERT_TRUE(link.sender->send(i, payloads[i], link.now).isOk());
    }
    for (int s = 0; s < 20; ++s) link.step();
    EXPECT_EQ(link.store.size(), persisted_before);  // nobody listening
    EXPECT_GT(link.sender->numInFlight(), 0u);
    // Restart: resume from the store, then everything completes.
    link.newBackend();
    ASSERT_TRUE(link.runUntilDone(3000));
    for (uint32_t i = 0; i < payloads.size(); ++i) {
        EXPECT_EQ(link.store[i], payloads[i]) << i;
        EXPECT_EQ(link.yields[i], 1) << i;  // fragments stored before the restart are not redone
    }
    EXPECT_EQ(link.acked.size(), payloads.size());
}

TEST(FragmentProtocol, RejectsMalformedChunksAndKeepsWorking) {
    LossyHub hub;
    FragmentAssembler assembler(FragmentAssemblerConfig{}, hub);
    FragmentSenderConfig sc;
    sc.session_id = 5;
    sc.chunk_payload_bytes = 1000;
    // Capture what a real sender emits, then tamper with it.
    std::vector<std::pair<std::string, Bytes>> sent;
    hub.setTap([&](const std::string& c, std::span<const uint8_t> b) {
        sent.emplace_back(c, Bytes(b.begin(), b.end()));
    });
    FragmentSender sender(sc, hub);
    const Bytes payload = makePayloads(1, 3)[0];
    ASSERT_TRUE(sender.send(0, payload, 0.0).isOk());
    hub.deliver();  // nobody subscribed: the captured copies are all we use
    ASSERT_GE(sent.size(), 2u);
    const Bytes chunk0 = sent[1].second;

    auto feed = [&](const Bytes& b) { return assembler.onMessage(kChannelFragmentChunk, b, 0.0); };
    // Truncated, wrong type, random junk, bad chunk CRC.
    EXPECT_FALSE(feed(Bytes(chunk0.begin(), chunk0.begin() + 30)).isOk());
    EXPECT_FALSE(feed(sent[0].second).isOk());  // a header on the chunk channel
    EXPECT_FALSE(feed(Bytes(100, 0xAB)).isOk());
    auto c = decodeMessage<plumb::fragment_chunk_t>(chunk0).value();
    auto bad_crc = c;
    bad_crc.data[0] ^= 1;
    EXPECT_EQ(feed(encodeMessage(bad_crc)).code(), StatusCode::kCorrupt);
    // Absurd sizes: 1 TB fragment, negative index, index beyond the end, wrong chunk count.
    auto absurd = c;
    absurd.total_bytes = int64_t{1} << 40;
    EXPECT_FALSE(feed(encodeMessage(absurd)).isOk());
    auto negative = c;
    negative.chunk_index = -1;
    EXPECT_FALSE(feed(encodeMessage(negative)).isOk());
    auto beyond = c;
    beyond.chunk_index = c.num_chunks;
    EXPECT_FALSE(feed(encodeMessage(beyond)).isOk());
    auto wrong_count = c;
    wrong_count.num_chunks = c.num_chunks + 3;
    EXPECT_FALSE(feed(encodeMessage(wrong_count)).isOk());
    const auto& st = assembler.stats();
    EXPECT_EQ(st.chunk_crc_failures, 1u);
    EXPECT_EQ(st.malformed_messages, 7u);
    EXPECT_EQ(assembler.numPartial(), 0u);
    // A chunk that passes its CRC but disagrees with the fragment it joins.
    ASSERT_TRUE(feed(chunk0).isOk());
    auto liar = decodeMessage<plumb::fragment_chunk_t>(sent[2].second).value();
    liar.fragment_crc32 ^= 0x55;
    EXPECT_FALSE(feed(encodeMessage(liar)).isOk());
    EXPECT_EQ(assembler.stats().inconsistent_chunks, 1u);
    // The genuine chunks still complete the fragment, bit-identical, exactly once.
    for (size_t i = 1; i < sent.size(); ++i) {
        ASSERT_TRUE(assembler.onMessage(sent[i].first, sent[i].second, 0.0).isOk());
        ASSERT_TRUE(assembler.onMessage(sent[i].first, sent[i].second, 0.0).isOk());  // duplicate
    }
    auto done = assembler.takeCompleted();
    ASSERT_EQ(done.size(), 1u);
    EXPECT_EQ(done[0].bytes, payload);
    EXPECT_TRUE(assembler.takeCompleted().empty());
}

TEST(FragmentProtocol, WholeFragmentChecksumIsVerified) {
    // Chunks that are individually valid but announce a wrong whole-fragment CRC never complete.
    LossyHub hub;
    FragmentAssembler assembler(FragmentAssemblerConfig{}, hub);
    std::vector<Bytes> chunks;
    hub.setTap([&](const std::string& ch, std::span<const uint8_t> b) {
        if (ch == kChannelFragmentChunk) chunks.emplace_back(b.begin(), b.end());
    });
    FragmentSenderConfig sc;
    sc.chunk_payload_bytes = 1000;
    FragmentSender sender(sc, hub);
    ASSERT_TRUE(sender.send(3, makePayloads(1, 4)[0], 0.0).isOk());
    for (const Bytes& b : chunks) {
        auto c = decodeMessage<plumb::fragment_chunk_t>(b).value();
        c.fragment_crc32 = 12345;
        ASSERT_TRUE(assembler.onMessage(kChannelFragmentChunk, encodeMessage(c), 0.0).isOk());
    }
    EXPECT_TRUE(assembler.takeCompleted().empty());
    EXPECT_EQ(assembler.stats().fragment_crc_failures, 1u);
}

TEST(FragmentProtocol, SenderRejectsBadAcksAndRequests) {
    LossyHub hub;
    FragmentSenderConfig sc;
    sc.session_id = 9;
    sc.chunk_payload_bytes = 1000;
    FragmentSender sender(sc, hub);
    const Bytes payload = makePayloads(1, 5)[0];
    ASSERT_TRUE(sender.send(1, payload, 0.0).isOk());
    EXPECT_TRUE(sender.send(1, payload, 0.0).isOk());                 // same bytes: no-op
    EXPECT_FALSE(sender.send(1, makePayloads(1, 6)[0], 0.0).isOk());  // other bytes
    EXPECT_FALSE(sender.send(2, {}, 0.0).isOk());                     // empty
    plumb::fragment_ack_t ack{};
    ack.session_id = 9;
    ack.fragment_id = 1;
    ack.status = plumb::fragment_ack_t::STATUS_PERSISTED;
    ack.fragment_crc32 = static_cast<int32_t>(crc32(payload) ^ 1);  // wrong CRC
    EXPECT_FALSE(sender.onMessage(kChannelFragmentAck, encodeMessage(ack), 0.1).isOk());
    ack.session_id = 8;  // other session: ignored
    EXPECT_TRUE(sender.onMessage(kChannelFragmentAck, encodeMessage(ack), 0.1).isOk());
    EXPECT_EQ(sender.numInFlight(), 1u);
    plumb::retransmit_request_t req{};
    req.session_id = 9;
    req.fragment_id = 1;
    req.missing_chunks = {0, 1000000};
    req.num_missing = 2;
    EXPECT_FALSE(sender.onMessage(kChannelRetransmit, encodeMessage(req), 0.1).isOk());
    EXPECT_FALSE(sender.onMessage(kChannelRetransmit, Bytes(7, 1), 0.1).isOk());
    EXPECT_EQ(sender.stats().chunks_resent, 0u);
    EXPECT_EQ(sender.stats().malformed_messages, 3u);
    // A valid ack releases the fragment.
    ack.session_id = 9;
    ack.fragment_crc32 = static_cast<int32_t>(crc32(payload));
    EXPECT_TRUE(sender.onMessage(kChannelFragmentAck, encodeMessage(ack), 0.2).isOk());
    EXPECT_EQ(sender.numInFlight(), 0u);
    EXPECT_EQ(sender.takeAcknowledged(), std::vector<uint32_t>{1});
}

// Re-announcements after 0.5 s, doubling up to 4 s.
FragmentSenderConfig backOffConfig(int64_t session_id) {
    FragmentSenderConfig sc;
    sc.session_id = session_id;
    sc.retransmit_timeout_s = 0.5;
    sc.max_retransmit_timeout_s = 4.0;
    return sc;
}

TEST(FragmentProtocol, RetransmissionBacksOffWithoutBackend) {
    LossyHub hub;
    FragmentSender sender(backOffConfig(0), hub);
    ASSERT_TRUE(sender.send(0, Bytes(10, 1), 0.0).isOk());
    const uint64_t first = sender.stats().headers_sent;
    // Timeouts 0.5, 1, 2, 4, 4, 4 ... => announcements at 0.5, 1.5, 3.5, 7.5, 11.5, 15.5, 19.5.
    for (double t = 0.0; t <= 20.0; t += 0.01) sender.poll(t);
    EXPECT_EQ(sender.stats().headers_sent - first, 7u);
    EXPECT_EQ(sender.numInFlight(), 1u);  // kept until acknowledged, whatever happens
}

// Issue 32, item 7: "cannot store" (fragment_backoff_t) keeps the sender quiet for retry_after_s;
// a retransmission request is still answered; other sessions' and malformed backoffs change
// nothing.
TEST(FragmentProtocol, BackoffPostponesReannouncements) {
    LossyHub hub;
    FragmentSender sender(backOffConfig(9), hub);
    ASSERT_TRUE(sender.send(0, Bytes(10, 1), 0.0).isOk());
    plumb::fragment_backoff_t b{};
    b.session_id = 9;
    b.fragment_id = 0;
    b.reason = plumb::fragment_backoff_t::REASON_CANNOT_STORE;
    b.retry_after_s = 20.0;
    b.message = "No space left on device";
    ASSERT_TRUE(sender.onMessage(kChannelFragmentBackoff, encodeMessage(b), 0.1).isOk());
    EXPECT_EQ(sender.lastBackoffMessage(), "No space left on device");
    const uint64_t first = sender.stats().headers_sent;
    for (double t = 0.1; t < 20.0; t += 0.01) sender.poll(t);
    EXPECT_EQ(sender.stats().headers_sent, first);  // quiet (without it: 5 announcements)
    for (double t = 20.0; t <= 21.0; t += 0.01) sender.poll(t);
    EXPECT_EQ(sender.stats().headers_sent, first + 1);  // the usual timeout after the back-off
    b.session_id = 8;                                   // another session's
    ASSERT_TRUE(sender.onMessage(kChannelFragmentBackoff, encodeMessage(b), 21.0).isOk());
    b.session_id = 9;
    b.retry_after_s = -1.0;
    EXPECT_FALSE(sender.onMessage(kChannelFragmentBackoff, encodeMessage(b), 21.0).isOk());
    EXPECT_EQ(sender.stats().backoffs_received, 1u);
    b.retry_after_s = 1e9;  // clamped to kMaxBackoffS
    ASSERT_TRUE(sender.onMessage(kChannelFragmentBackoff, encodeMessage(b), 21.0).isOk());
    plumb::retransmit_request_t req{};
    req.session_id = 9;
    req.fragment_id = 0;
    req.missing_chunks = {0};
    req.num_missing = 1;
    ASSERT_TRUE(sender.onMessage(kChannelRetransmit, encodeMessage(req), 22.0).isOk());
    EXPECT_EQ(sender.stats().chunks_resent, 1u);  // the backend asked: answered at once
    EXPECT_EQ(sender.numInFlight(), 1u);
}

TEST(FragmentProtocol, AssemblerMemoryIsBounded) {
    LossyHub hub;
    FragmentAssemblerConfig ac;
    ac.max_fragment_bytes = 20000;
    ac.max_buffered_bytes = 50000;
    ac.max_partial_fragments = 4;
    FragmentAssembler assembler(ac, hub);
    FragmentSenderConfig sc;
    sc.chunk_payload_bytes = 1000;
    std::vector<std::pair<std::string, Bytes>> sent;
    hub.setTap([&](const std::string& c, std::span<const uint8_t> b) {
        sent.emplace_back(c, Bytes(b.begin(), b.end()));
    });
    FragmentSender sender(sc, hub);
    // Ten 15 kB fragments, each missing its last chunk: never complete, must not pile up.
    for (uint32_t i = 0; i < 10; ++i) ASSERT_TRUE(sender.send(i, Bytes(15000, 7), 0.0).isOk());
    double t = 0.0;
    for (const auto& [ch, b] : sent) {
        if (ch == kChannelFragmentChunk &&
            decodeMessage<plumb::fragment_chunk_t>(b)->chunk_index == 14) {
            continue;
        }
        ASSERT_TRUE(assembler.onMessage(ch, b, t += 0.001).isOk());
    }
    EXPECT_LE(assembler.numPartial(), 4u);
    EXPECT_GE(assembler.stats().fragments_evicted, 6u);
}

}  // namespace
}  // namespace plumb::messages
