// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <string>

#include "messages/channels.hpp"
#include "messages/crc32.hpp"
#include "messages/wire.hpp"

namespace plumb::messages {
namespace {

std::span<const uint8_t> asBytes(const std::string& s) {
    return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

TEST(Crc32, MatchesKnownVectors) {
    EXPECT_EQ(crc32(asBytes("")), 0x00000000u);
    EXPECT_EQ(crc32(asBytes("123456789")), 0xCBF43926u);
    EXPECT_EQ(crc32(asBytes("a")), 0xE8B7BE43u);
    EXPECT_EQ(crc32(asBytes("The quick brown fox jumps over the lazy dog")), 0x414FA339u);
    // A long buffer fed in uneven pieces; the value is what plumb's own table-driven CRC gave
    // before zlib's crc32() replaced it (issue 32, item 10).
    std::vector<uint8_t> big(1 << 20);
    for (size_t i = 0; i < big.size(); ++i) big[i] = static_cast<uint8_t>((i * 2654435761u) >> 13);
    uint32_t pieces = 0;
    for (size_t at = 0, n = 1; at < big.size(); at += n, n = n * 7 % 4093 + 1) {
        pieces = crc32(std::span(big).subspan(at, std::min(n, big.size() - at)), pieces);
    }
    EXPECT_EQ(pieces, crc32(big));
    EXPECT_EQ(crc32(big), 0x4091419Du);  // also Python's zlib.crc32
    // Incremental use equals one pass.
    const std::string s = "The quick brown fox jumps over the lazy dog";
    EXPECT_EQ(crc32(asBytes(s.substr(10)), crc32(asBytes(s.substr(0, 10)))), 0x414FA339u);
    // Every single-bit flip of a message changes the CRC.
    std::vector<uint8_t> msg(64);
    for (size_t i = 0; i < msg.size(); ++i) msg[i] = static_cast<uint8_t>(i * 7 + 3);
    const uint32_t base = crc32(msg);
    for (size_t bit = 0; bit < msg.size() * 8; ++bit) {
        msg[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
        EXPECT_NE(crc32(msg), base) << "bit " << bit;
        msg[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
    }
}

plumb::fragment_chunk_t sampleChunk() {
    plumb::fragment_chunk_t c{};
    c.utime = 1'700'000'000'000'000;
    c.seq = 42;
    c.session_id = -7;
    c.fragment_id = 3;
    c.chunk_index = 1;
    c.num_chunks = 2;
    c.chunk_bytes = 5;
    c.total_bytes = 8;
    c.fragment_crc32 = static_cast<int32_t>(0xDEADBEEFu);
    c.data = {1, 2, 255};
    c.size = 3;
    c.chunk_crc32 = static_cast<int32_t>(crc32(c.data));
    return c;
}

TEST(Wire, GeneratedTypesRoundTrip) {
    const plumb::fragment_chunk_t c = sampleChunk();
    const Bytes bytes = encodeMessage(c);
    auto back = decodeMessage<plumb::fragment_chunk_t>(bytes);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(back->utime, c.utime);
    EXPECT_EQ(back->seq, 42);
    EXPECT_EQ(back->session_id, -7);
    EXPECT_EQ(back->fragment_crc32, c.fragment_crc32);
    EXPECT_EQ(back->data, c.data);
    EXPECT_EQ(encodeMessage(*back), bytes);

    plumb::camera_info_t cam{};
    cam.width = 160;
    cam.height = 120;
    cam.fx = 131.25;
    cam.fy = -120.0;
    cam.cx = 79.5;
    cam.cy = 59.5;
    cam.depth_scale = 5000.0;
    cam.source = "sim:room";
    auto cam_back = decodeMessage<plumb::camera_info_t>(encodeMessage(cam));
    ASSERT_TRUE(cam_back.isOk()) << cam_back.status().toString();
    EXPECT_EQ(cam_back->fy, -120.0);
    EXPECT_EQ(cam_back->source, "sim:room");

    plumb::device_status_t st{};
    st.tracking_state = plumb::device_status_t::TRACKING_LOST;
    st.spool_bytes = int64_t{5} << 33;
    auto st_back = decodeMessage<plumb::device_status_t>(encodeMessage(st));
    ASSERT_TRUE(st_back.isOk());
    EXPECT_EQ(st_back->tracking_state, plumb::device_status_t::TRACKING_LOST);
    EXPECT_EQ(st_back->spool_bytes, int64_t{5} << 33);
}

// Every schema must describe its generated type exactly: a populated message passes checkWire
// and any truncation fails.
template <typename T>
void expectSchemaMatches(const T& msg) {
    const Bytes bytes = encodeMessage(msg);
    EXPECT_TRUE(checkWire(wireSchema<T>(), T::getHash(), bytes).isOk()) << wireSchema<T>().name;
    for (size_t len = 0; len < bytes.size(); ++len) {
        EXPECT_FALSE(decodeMessage<T>(std::span(bytes).first(len)).isOk())
            << wireSchema<T>().name << " truncated to " << len;
    }
    Bytes longer = bytes;
    longer.push_back(0);
    EXPECT_FALSE(decodeMessage<T>(longer).isOk()) << wireSchema<T>().name << " trailing byte";
}

TEST(Wire, SchemasMatchGeneratedTypes) {
    plumb::device_status_t status{};
    status.fps = 29.5;
    expectSchemaMatches(status);
    expectSchemaMatches(plumb::fragment_header_t{});
    expectSchemaMatches(sampleChunk());
    expectSchemaMatches(plumb::fragment_ack_t{});
    plumb::retransmit_request_t req{};
    req.missing_chunks = {1, 5, 9};
    req.num_missing = 3;
    expectSchemaMatches(req);
    plumb::fragment_backoff_t backoff{};
    backoff.retry_after_s = 2.0;
    backoff.message = "No space left on device";
    expectSchemaMatches(backoff);
    plumb::camera_info_t cam{};
    cam.source = "x";
    expectSchemaMatches(cam);
    plumb::depth_frame_t depth{};
    depth.data = {0, 1, 2, 3};
    depth.size = 4;
    expectSchemaMatches(depth);
    plumb::depth_frame2_t rgbd{};
    rgbd.data = {0, 1, 2, 3};
    rgbd.size = 4;
    rgbd.colour_data = {7, 8, 9};
    rgbd.colour_size = 3;
    expectSchemaMatches(rgbd);
    plumb::depth_frame3_t session_rgbd{};
    session_rgbd.session_id = 77;
    session_rgbd.frame = rgbd;
    expectSchemaMatches(session_rgbd);
    plumb::config_snapshot_t config{};
    config.program = "plumb-device";
    config.version = "0.1.0";
    config.toml = "[fusion]\nvoxel_size_m = 0.01\n";
    expectSchemaMatches(config);
    plumb::envelope_t env{};
    env.payload = {9, 9};
    env.payload_size = 2;
    env.mac.assign(32, 0xAB);
    env.mac_size = 32;
    expectSchemaMatches(env);
}

void putI32(Bytes& b, size_t pos, int32_t v) {
    const auto u = static_cast<uint32_t>(v);
    b[pos] = static_cast<uint8_t>(u >> 24);
    b[pos + 1] = static_cast<uint8_t>(u >> 16);
    b[pos + 2] = static_cast<uint8_t>(u >> 8);
    b[pos + 3] = static_cast<uint8_t>(u);
}

TEST(Wire, RejectsMalformedMessages) {
    const Bytes good = encodeMessage(sampleChunk());
    // The count field of fragment_chunk_t sits after 8 (hash) + 3*8 + 4*4 + 8 + 2*4 bytes.
    const size_t count_pos = 8 + 24 + 16 + 8 + 8;
    for (const int32_t absurd : {-1, 4, 1 << 30, std::numeric_limits<int32_t>::max(),
                                 std::numeric_limits<int32_t>::min()}) {
        Bytes bad = good;
        putI32(bad, count_pos, absurd);
        const auto r = decodeMessage<plumb::fragment_chunk_t>(bad);
        ASSERT_FALSE(r.isOk()) << absurd;
        EXPECT_EQ(r.status().code(), StatusCode::kCorrupt);
    }
    // Wrong type: a chunk is not an ack, and the message says so.
    const auto wrong = decodeMessage<plumb::fragment_ack_t>(good);
    ASSERT_FALSE(wrong.isOk());
    EXPECT_NE(wrong.status().message().find("wrong type"), std::string::npos);
    // Strings with a zero, negative, huge or unterminated length.
    plumb::config_snapshot_t config{};
    config.program = "p";
    const Bytes cfg = encodeMessage(config);
    for (const int32_t len : {0, -5, 1 << 30}) {
        Bytes bad = cfg;
        putI32(bad, 8 + 16, len);
        EXPECT_FALSE(decodeMessage<plumb::config_snapshot_t>(bad).isOk()) << len;
    }
    Bytes unterminated = cfg;
    unterminated[8 + 16 + 4 + 1] = 'x';
    EXPECT_FALSE(decodeMessage<plumb::config_snapshot_t>(unterminated).isOk());
    // Random garbage behind a valid fingerprint never crashes.
    std::mt19937 rng(7);
    for (int trial = 0; trial < 2000; ++trial) {
        Bytes junk(good.begin(), good.begin() + 8);
        const size_t extra = rng() % 120;
        for (size_t i = 0; i < extra; ++i) junk.push_back(static_cast<uint8_t>(rng()));
        (void)decodeMessage<plumb::fragment_chunk_t>(junk);
        (void)decodeMessage<plumb::envelope_t>(junk);
        (void)decodeMessage<plumb::retransmit_request_t>(junk);
    }
}

}  // namespace
}  // namespace plumb::messages
