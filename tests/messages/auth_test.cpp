// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <string>

#include "messages/auth.hpp"
#include "messages/channels.hpp"
#include "messages/fragment_assembler.hpp"
#include "messages/fragment_sender.hpp"
#include "messages/sha256.hpp"
#include "tests/messages/lossy_transport.hpp"

namespace plumb::messages {
namespace {

using testing::LossyConfig;
using testing::LossyHub;

std::span<const uint8_t> asBytes(const std::string& s) {
    return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

std::string hex(std::span<const uint8_t> d) {
    static const char* kDigits = "0123456789abcdef";
    std::string out;
    for (uint8_t b : d) {
        out += kDigits[b >> 4];
        out += kDigits[b & 15];
    }
    return out;
}

Bytes repeat(uint8_t value, size_t n) { return Bytes(n, value); }

// FIPS 180-4 examples (NIST CSRC "SHA256.pdf", "SHA2_Additional.pdf").
TEST(Sha256, FipsVectors) {
    EXPECT_EQ(hex(sha256(asBytes(""))),
              "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
    EXPECT_EQ(hex(sha256(asBytes("abc"))),
              "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    EXPECT_EQ(hex(sha256(asBytes("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"))),
              "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
    EXPECT_EQ(hex(sha256(asBytes("abcdefghbcdefghicdefghijdefghijkefghijklfghijklmghijklmnhijklmn"
                                 "oijklmnopjklmnopqklmnopqrlmnopqrsmnopqrstnopqrstu"))),
              "cf5b16a778af8380036ce59e7b0492370b249b11e8f07a51afac45037afee9d1");
    // One million 'a', fed in uneven pieces to exercise the buffering.
    Sha256 s;
    const Bytes a(1000000, 'a');
    size_t pos = 0, piece = 1;
    while (pos < a.size()) {
        const size_t n = std::min(piece, a.size() - pos);
        s.update(std::span(a).subspan(pos, n));
        pos += n;
        piece = piece * 3 % 1000 + 1;
    }
    EXPECT_EQ(hex(s.finish()), "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

// RFC 4231 test cases 1, 2, 3, 4, 6, 7 (5 truncates the output).
TEST(HmacSha256, Rfc4231Vectors) {
    EXPECT_EQ(hex(hmacSha256(repeat(0x0b, 20), asBytes("Hi There"))),
              "b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7");
    EXPECT_EQ(hex(hmacSha256(asBytes("Jefe"), asBytes("what do ya want for nothing?"))),
              "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843");
    EXPECT_EQ(hex(hmacSha256(repeat(0xaa, 20), repeat(0xdd, 50))),
              "773ea91e36800e46854db8ebd09181a72959098b3ef8c122d9635514ced565fe");
    Bytes key4;
    for (uint8_t i = 1; i <= 25; ++i) key4.push_back(i);
    EXPECT_EQ(hex(hmacSha256(key4, repeat(0xcd, 50))),
              "82558a389a443c0ea4cc819899f2083a85f0faa3e578f8077a2e3ff46729665b");
    EXPECT_EQ(hex(hmacSha256(repeat(0xaa, 131),
                             asBytes("Test Using Larger Than Block-Size Key - Hash Key First"))),
              "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54");
    EXPECT_EQ(hex(hmacSha256(
                  repeat(0xaa, 131),
                  asBytes("This is a test using a larger than block-size key and a larger than "
                          "block-size data. The key needs to be hashed before being used by the "
                          "HMAC algorithm."))),
              "9b09ffa71b942fcb27635fbcd5b0e944bfdc63644f0713938a7f51535c3a35e2");
}

TEST(HmacSha256, ConstantTimeEqual) {
    const Bytes a = {1, 2, 3, 4}, b = {1, 2, 3, 5}, c = {1, 2, 3};
    EXPECT_TRUE(constantTimeEqual(a, a));
    EXPECT_FALSE(constantTimeEqual(a, b));
    EXPECT_FALSE(constantTimeEqual(a, c));
    EXPECT_TRUE(constantTimeEqual(Bytes{}, Bytes{}));
}

// The envelope on the wire must not change with the HMAC implementation (issue 32, item 10):
// these bytes were produced by plumb's own SHA-256/HMAC before libcrypto replaced them.
TEST(Authentication, SealedEnvelopeBytesAreStable) {
    Bytes payload(100);
    for (size_t i = 0; i < payload.size(); ++i) payload[i] = static_cast<uint8_t>(i * 13 + 1);
    const Bytes sealed =
        sealMessage("PLUMB_FRAGMENT_CHUNK", payload, asBytes("0123456789abcdef0123456789abcdef"), 7,
                    0x1122334455667788, 42, 1700000000000000);
    EXPECT_EQ(hex(sealed),
              "8f5f23e4a0e7d1ff00060a24181e4000000000000000002a11223344556677880000000700000064"
              "010e1b2835424f5c697683909daab7c4d1deebf805121f2c394653606d7a8794a1aebbc8d5e2effc"
              "091623303d4a5764717e8b98a5b2bfccd9e6f3000d1a2734414e5b6875828f9ca9b6c3d0ddeaf704"
              "111e2b3845525f6c798693a0adbac7d4e1eefb0800000020d901ddf319ca38d86306994000ca2370"
              "ab6602587ecc9cd2c697438f9a5544af");
}

AuthConfig authConfig(const std::string& key, int64_t sender) {
    AuthConfig c;
    c.key.assign(key.begin(), key.end());
    c.sender_id = sender;
    return c;
}

TEST(Authentication, RejectsAndCountsUnsignedForgedReplayedMessages) {
    const std::string key = "correct horse battery staple";
    LossyHub hub;
    AuthenticatedTransport device(hub, authConfig(key, 1));
    AuthenticatedTransport backend(hub, authConfig(key, 2));
    std::vector<Bytes> received;
    ASSERT_TRUE(backend
                    .subscribe("PLUMB_TEST",
                               [&](const std::string&, std::span<const uint8_t> b) {
                                   received.emplace_back(b.begin(), b.end());
                               })
                    .isOk());
    std::vector<Bytes> wire;
    hub.setTap([&](const std::string&, std::span<const uint8_t> b) {
        wire.emplace_back(b.begin(), b.end());
    });

    const Bytes hello = {'h', 'e', 'l', 'l', 'o'};
    ASSERT_TRUE(device.publish("PLUMB_TEST", hello).isOk());
    hub.deliver();
    ASSERT_EQ(received.size(), 1u);
    EXPECT_EQ(received[0], hello);
    ASSERT_EQ(wire.size(), 1u);
    EXPECT_NE(wire[0], hello);  // it travelled in an envelope

    // Unsigned: raw bytes straight onto the network.
    ASSERT_TRUE(hub.publish("PLUMB_TEST", hello).isOk());
    // Forged: signed with another key.
    const std::string other = "not the right key at all";
    ASSERT_TRUE(
        hub.publish("PLUMB_TEST", sealMessage("PLUMB_TEST", hello, asBytes(other), 1, 66, 1, 0))
            .isOk());
    // Tampered: one payload bit of a genuine envelope flipped.
    Bytes tampered = wire[0];
    tampered[40] ^= 1;
    ASSERT_TRUE(hub.publish("PLUMB_TEST", tampered).isOk());
    // Replayed: the genuine envelope again.
    ASSERT_TRUE(hub.publish("PLUMB_TEST", wire[0]).isOk());
    // Moved: a genuine envelope for another channel.
    ASSERT_TRUE(
        hub.publish("PLUMB_TEST", sealMessage("PLUMB_OTHER", hello, asBytes(key), 1, 1, 500, 0))
            .isOk());
    // Wrong key id.
    ASSERT_TRUE(
        hub.publish("PLUMB_TEST", sealMessage("PLUMB_TEST", hello, asBytes(key), 7, 1, 501, 0))
            .isOk());
    // Truncated envelope.
    ASSERT_TRUE(hub.publish("PLUMB_TEST", std::span(wire[0]).first(wire[0].size() - 3)).isOk());
    hub.deliver();
    EXPECT_EQ(received.size(), 1u);  // nothing else got through
    const AuthStats& st = backend.stats();
    EXPECT_EQ(st.accepted, 1u);
    EXPECT_EQ(st.rejected_unsigned, 2u);  // raw bytes + truncated envelope
    EXPECT_EQ(st.rejected_forged, 3u);    // other key, tampered, moved channel
    EXPECT_EQ(st.rejected_replayed, 1u);
    EXPECT_EQ(st.rejected_wrong_key, 1u);
    EXPECT_EQ(st.rejected(), 7u);

    // Later genuine messages still pass.
    ASSERT_TRUE(device.publish("PLUMB_TEST", hello).isOk());
    hub.deliver();
    EXPECT_EQ(received.size(), 2u);
}

TEST(Authentication, ReplayWindowAcceptsReorderingOnly) {
    ReplayGuard guard(8, 2);
    EXPECT_TRUE(guard.accept(1, 10));
    EXPECT_TRUE(guard.accept(1, 12));
    EXPECT_TRUE(guard.accept(1, 11));   // late but new
    EXPECT_FALSE(guard.accept(1, 11));  // seen
    EXPECT_TRUE(guard.accept(1, 30));
    EXPECT_FALSE(guard.accept(1, 22));  // older than the window
    EXPECT_TRUE(guard.accept(1, 23));
    EXPECT_TRUE(guard.accept(2, 1));   // another sender has its own numbers
    EXPECT_TRUE(guard.accept(1, 31));  // sender 1 heard again
    EXPECT_TRUE(guard.accept(3, 1));   // forgets the least recently heard sender (2)
    EXPECT_FALSE(guard.accept(1, 30));
    EXPECT_FALSE(guard.accept(3, 1));
}

TEST(Authentication, FragmentProtocolRunsOverSignedLossyNetwork) {
    const std::string key = "0123456789abcdef0123456789abcdef";
    LossyHub hub(LossyConfig{0.10, 0.10, true, 4});
    AuthenticatedTransport device(hub, authConfig(key, 1));
    AuthenticatedTransport backend(hub, authConfig(key, 2));
    FragmentSenderConfig sc;
    sc.chunk_payload_bytes = 3000;
    FragmentSender sender(sc, device);
    FragmentAssembler assembler(FragmentAssemblerConfig{}, backend);
    double now = 0.0;
    for (const char* ch : {kChannelFragmentAck, kChannelRetransmit}) {
        ASSERT_TRUE(device
                        .subscribe(ch,
                                   [&](const std::string& c, std::span<const uint8_t> b) {
                                       (void)sender.onMessage(c, b, now);
                                   })
                        .isOk());
    }
    for (const char* ch : {kChannelFragmentHeader, kChannelFragmentChunk}) {
        ASSERT_TRUE(backend
                        .subscribe(ch,
                                   [&](const std::string& c, std::span<const uint8_t> b) {
                                       (void)assembler.onMessage(c, b, now);
                                   })
                        .isOk());
    }
    std::vector<Bytes> payloads;
    for (uint32_t i = 0; i < 5; ++i) {
        Bytes p(20000 + 997 * i);
        for (size_t k = 0; k < p.size(); ++k) p[k] = static_cast<uint8_t>(k * (i + 3));
        payloads.push_back(p);
        ASSERT_TRUE(sender.send(i, p, now).isOk());
    }
    std::map<uint32_t, Bytes> store;
    for (int step = 0; step < 2000 && (sender.numInFlight() > 0 || !hub.idle()); ++step) {
        hub.deliver();
        for (auto& c : assembler.takeCompleted()) {
            EXPECT_TRUE(store.emplace(c.fragment_id, c.bytes).second);
            assembler.acknowledge(c.session_id, c.fragment_id, now);
        }
        now += 0.05;
        sender.poll(now);
        assembler.poll(now);
    }
    EXPECT_EQ(sender.numInFlight(), 0u);
    for (uint32_t i = 0; i < 5; ++i) EXPECT_EQ(store[i], payloads[i]);
    // The hub's duplicates are caught as replays before they reach the protocol.
    EXPECT_GT(backend.stats().rejected_replayed + device.stats().rejected_replayed, 0u);
    EXPECT_EQ(backend.stats().rejected_forged + device.stats().rejected_forged, 0u);
}

}  // namespace
}  // namespace plumb::messages
