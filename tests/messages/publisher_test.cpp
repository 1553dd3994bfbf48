// SPDX-License-Identifier: Apache-2.0
// The device's fragment stream without a backend: bounded queues never block capture, the
// publisher keeps every fragment until acknowledged, limits what is on the wire, and hands what
// is left to the next run through the disk spool.

#include <gtest/gtest.h>

#include <unistd.h>
#include <filesystem>
#include <random>
#include <thread>

#include "device/stream/bounded_queue.hpp"
#include "device/stream/fragment_publisher.hpp"
#include "messages/channels.hpp"
#include "messages/crc32.hpp"
#include "messages/files.hpp"
#include "messages/fragment_assembler.hpp"
#include "tests/messages/lossy_transport.hpp"

namespace plumb::device {
namespace {

TEST(BoundedQueue, TryPushDropsWhenFullAndNeverBlocks) {
    BoundedQueue<int> q(3);
    int dropped = 0;
    for (int i = 0; i < 10; ++i) {
        int v = i;
        if (!q.tryPush(v)) ++dropped;
    }
    EXPECT_EQ(dropped, 7);
    EXPECT_EQ(q.size(), 3u);
    EXPECT_EQ(*q.tryPop(), 0);  // oldest first
    q.close();
    int v = 99;
    EXPECT_FALSE(q.tryPush(v));
    EXPECT_EQ(*q.pop(std::chrono::milliseconds(1)), 1);
    EXPECT_EQ(*q.pop(std::chrono::milliseconds(1)), 2);
    EXPECT_FALSE(q.pop(std::chrono::milliseconds(1)).has_value());
    EXPECT_TRUE(q.drained());
}

TEST(BoundedQueue, PushWaitsForRoomAndCloseWakesIt) {
    BoundedQueue<int> q(1);
    ASSERT_TRUE(q.push(1));
    std::thread consumer([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        (void)q.tryPop();
    });
    EXPECT_TRUE(q.push(2));  // returns once the consumer made room
    consumer.join();
    std::thread closer([&] { q.close(); });
    EXPECT_FALSE(q.push(3));  // full until closed
    closer.join();
}

std::vector<uint8_t> payload(size_t n, uint32_t seed) {
    std::mt19937 rng(seed);
    std::vector<uint8_t> b(n);
    for (auto& x : b) x = static_cast<uint8_t>(rng());
    return b;
}

struct Net {
    explicit Net(messages::testing::LossyConfig c) : hub(c) {}
    messages::testing::LossyHub hub;
    std::unique_ptr<messages::FragmentAssembler> assembler;
    std::map<std::pair<int64_t, uint32_t>, std::vector<uint8_t>> store;
    int max_seen_in_flight = 0;
};

// Routes acks and retransmission requests to `pub`, headers and chunks to `assembler`.
void connect(messages::testing::LossyHub& hub, FragmentPublisher& pub,
             messages::FragmentAssembler& assembler, const double& now) {
    for (const char* ch : {messages::kChannelFragmentAck, messages::kChannelRetransmit})
        (void)hub.subscribe(ch, [&pub, &now](const std::string& c, std::span<const uint8_t> b) {
            pub.onMessage(c, b, now);
        });
    for (const char* ch : {messages::kChannelFragmentHeader, messages::kChannelFragmentChunk})
        (void)hub.subscribe(ch,
                            [&assembler, &now](const std::string& c, std::span<const uint8_t> b) {
                                (void)assembler.onMessage(c, b, now);
                            });
}

// 1000-byte chunks, session `session`, a fresh spool directory named after `name`.
PublisherConfig spoolConfig(const std::string& name, int64_t session) {
    PublisherConfig pc;
    pc.session_id = session;
    pc.sender.chunk_payload_bytes = 1000;
    pc.spool.disk_dir =
        std::filesystem::temp_directory_path() / (name + std::to_string(::getpid()));
    std::filesystem::remove_all(pc.spool.disk_dir);
    return pc;
}

TEST(FragmentPublisher, WindowSpoolAndResumeAcrossRuns) {
    PublisherConfig pc = spoolConfig("plumb_publisher_", 5);
    const auto dir = pc.spool.disk_dir;
    pc.max_in_flight = 2;
    pc.spool.memory_budget_bytes = 8000;  // a cache: every fragment is on disk anyway
    std::vector<std::vector<uint8_t>> sent;
    {
        messages::testing::LossyHub hub;  // nobody listens: nothing is acknowledged
        auto pub = FragmentPublisher::create(pc, hub);
        ASSERT_TRUE(pub.isOk()) << pub.status().toString();
        for (uint32_t i = 0; i < 6; ++i) {
            sent.push_back(payload(3000 + i, i));
            ASSERT_TRUE((*pub)->submit(i, sent.back(), 0.0).isOk());
            EXPECT_LE((*pub)->inFlight(), 2u);
        }
        EXPECT_EQ((*pub)->unacknowledged(), 6u);
        EXPECT_GT((*pub)->spoolBytes(), 8000);
        // Durable as soon as submitted (issue 32, item 2): all six are files already, with the
        // bytes submitted, although no clean exit wrote anything.
        for (uint32_t i = 0; i < 6; ++i) {
            auto on_disk = messages::readFile(dir / messages::fragmentFileName(5, i), 1 << 20);
            ASSERT_TRUE(on_disk.isOk()) << on_disk.status().toString();
            EXPECT_EQ(*on_disk, sent[i]);
        }
    }
    // A new run (new session) finds the six fragments and delivers them to a backend.
    messages::testing::LossyHub hub({.loss = 0.2, .duplicate = 0.1, .reorder = true, .seed = 3});
    pc.session_id = 6;
    auto pub = FragmentPublisher::create(pc, hub);
    ASSERT_TRUE(pub.isOk());
    EXPECT_EQ((*pub)->stats().fragments_resumed, 6u);
    messages::FragmentAssembler assembler({}, hub);
    std::map<uint32_t, std::vector<uint8_t>> store;
    double now = 0.0;
    connect(hub, **pub, assembler, now);
    (*pub)->poll(now);
    for (int step = 0; step < 4000 && (*pub)->unacknowledged() > 0; ++step) {
        hub.deliver();
        for (auto& c : assembler.takeCompleted()) {
            EXPECT_EQ(c.session_id, 5);
            store[c.fragment_id] = c.bytes;
            assembler.acknowledge(c.session_id, c.fragment_id, now);
        }
        now += 0.05;
        (*pub)->poll(now);
        assembler.poll(now);
        EXPECT_LE((*pub)->inFlight(), 2u);
    }
    EXPECT_EQ((*pub)->unacknowledged(), 0u);
    ASSERT_EQ(store.size(), 6u);
    for (uint32_t i = 0; i < 6; ++i) EXPECT_EQ(store[i], sent[i]) << "fragment " << i;
    // Acknowledged fragments leave the disk spool too.
    size_t files = 0;
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir)) ++files;
    EXPECT_EQ(files, 0u);
    std::filesystem::remove_all(dir);
}

// Issue 32, item 8: a fragment the backend rejects for good leaves the spool for its quarantine
// folder, beside the reason; the next run neither resends it nor waits for it.
TEST(FragmentPublisher, RejectedFragmentIsQuarantinedWithItsReason) {
    PublisherConfig pc = spoolConfig("plumb_quarantine_", 9);
    const auto dir = pc.spool.disk_dir;
    messages::testing::LossyHub hub;
    auto pub = FragmentPublisher::create(pc, hub);
    ASSERT_TRUE(pub.isOk()) << pub.status().toString();
    messages::FragmentAssembler assembler({}, hub);
    double now = 0.0;
    connect(hub, **pub, assembler, now);
    std::vector<std::vector<uint8_t>> sent;
    for (uint32_t i = 0; i < 3; ++i) {
        sent.push_back(payload(2000 + i, 40 + i));
        ASSERT_TRUE((*pub)->submit(i, sent.back(), now).isOk());
    }
    for (int step = 0; step < 400 && (*pub)->unacknowledged() > 0; ++step) {
        hub.deliver();
        for (auto& c : assembler.takeCompleted()) {
            if (c.fragment_id == 1) {
                assembler.reject(c.session_id, c.fragment_id, now);  // e.g. it did not decode
            } else {
                assembler.acknowledge(c.session_id, c.fragment_id, now);
            }
        }
        now += 0.05;
        (*pub)->poll(now);
        assembler.poll(now);
    }
    EXPECT_EQ((*pub)->unacknowledged(), 0u);
    EXPECT_EQ((*pub)->stats().fragments_acked, 2u);
    EXPECT_EQ((*pub)->stats().fragments_rejected, 1u);
    ASSERT_EQ((*pub)->quarantined().size(), 1u);
    EXPECT_EQ((*pub)->quarantined()[0].fragment_id, 1u);
    const auto name = messages::fragmentFileName(9, 1);
    auto kept = messages::readFile(dir / "quarantine" / name, 1 << 20);
    ASSERT_TRUE(kept.isOk()) << kept.status().toString();
    EXPECT_EQ(*kept, sent[1]);
    auto reason = messages::readFile(dir / "quarantine" / (name + ".reason"), 1 << 20);
    ASSERT_TRUE(reason.isOk());
    EXPECT_NE(std::string(reason->begin(), reason->end()).find("rejected for good by the backend"),
              std::string::npos);
    EXPECT_FALSE(std::filesystem::exists(dir / name));
    pub = Status(StatusCode::kInternal, "closed");
    pc.session_id = 10;  // the next run
    auto next = FragmentPublisher::create(pc, hub);
    ASSERT_TRUE(next.isOk());
    EXPECT_EQ((*next)->stats().fragments_resumed, 0u);
    EXPECT_EQ((*next)->unacknowledged(), 0u);
    std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace plumb::device
