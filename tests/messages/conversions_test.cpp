// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "messages/colour_codec.hpp"
#include "messages/conversions.hpp"

namespace plumb::messages {
namespace {

TEST(Conversions, DeviceStatusRoundTripsAndValidates) {
    DeviceStatus s;
    s.session_id = 99;
    s.fps = 29.97;
    s.tracking = TrackingState::kLost;
    s.frames_processed = 1000;
    s.frames_dropped = 3;
    s.fragments_cut = 20;
    s.fragments_acked = 18;
    s.spool_fragments = 2;
    s.spool_bytes = 3 << 20;
    s.memory_bytes = int64_t{600} << 20;
    auto wire = decodeMessage<plumb::device_status_t>(encodeMessage(toMessage(s, 5, 6)));
    ASSERT_TRUE(wire.isOk());
    EXPECT_EQ(wire->utime, 5);
    EXPECT_EQ(wire->seq, 6);
    auto back = fromMessage(*wire);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(back->tracking, TrackingState::kLost);
    EXPECT_EQ(back->fps, 29.97);
    EXPECT_EQ(back->spool_bytes, 3 << 20);
    EXPECT_EQ(back->memory_bytes, int64_t{600} << 20);
    auto bad = toMessage(s, 0, 0);
    bad.tracking_state = 9;
    EXPECT_FALSE(fromMessage(bad).isOk());
    bad = toMessage(s, 0, 0);
    bad.fps = NAN;
    EXPECT_FALSE(fromMessage(bad).isOk());
    bad = toMessage(s, 0, 0);
    bad.frames_dropped = -1;
    EXPECT_FALSE(fromMessage(bad).isOk());
}

TEST(Conversions, CameraInfoRoundTripsAndValidates) {
    CameraInfo info;
    info.camera = cameraPreset("icl-nuim").value();
    info.depth_scale = 5000.0;
    info.source = "dataset:icl-nuim-office-kt0";
    auto back =
        fromMessage(*decodeMessage<plumb::camera_info_t>(encodeMessage(toMessage(info, 1, 2))));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(back->camera.fy, -480.0);  // negative fy survives
    EXPECT_EQ(back->camera.width, 640);
    EXPECT_EQ(back->depth_scale, 5000.0);
    EXPECT_EQ(back->source, info.source);
    auto bad = toMessage(info, 1, 2);
    bad.fx = 0.0;
    EXPECT_FALSE(fromMessage(bad).isOk());
    bad = toMessage(info, 1, 2);
    bad.depth_scale = -1.0;
    EXPECT_FALSE(fromMessage(bad).isOk());
    bad = toMessage(info, 1, 2);
    bad.width = 1 << 20;
    EXPECT_FALSE(fromMessage(bad).isOk());
}

Depth16Image sampleDepth() {
    // A 160x120 plane with noise and holes, like a small sensor frame.
    Depth16Image d(160, 120);
    std::mt19937 rng(3);
    std::normal_distribution<double> noise(0.0, 2.0);
    for (int v = 0; v < d.height(); ++v) {
        for (int u = 0; u < d.width(); ++u) {
            const double z = 2000.0 + 3.0 * u + 1.5 * v + noise(rng);
            d(u, v) = (u * 7 + v * 13) % 29 == 0 ? 0 : static_cast<uint16_t>(z);
        }
    }
    d(0, 0) = 65535;
    d(1, 0) = 0;  // the largest possible jump both ways
    return d;
}

TEST(Conversions, DepthFramesRoundTripLosslessly) {
    RawDepthFrame f;
    f.utime = 123;
    f.frame_index = 7;
    f.depth_scale = 1000.0;
    f.depth = sampleDepth();
    for (const DepthEncoding enc : {DepthEncoding::kRaw16, DepthEncoding::kDeltaVarint}) {
        auto m = toMessage(f, enc, 1);
        ASSERT_TRUE(m.isOk());
        auto wire = decodeMessage<plumb::depth_frame_t>(encodeMessage(*m));
        ASSERT_TRUE(wire.isOk());
        auto back = fromMessage(*wire);
        ASSERT_TRUE(back.isOk()) << back.status().toString();
        EXPECT_EQ(back->depth, f.depth);
        EXPECT_EQ(back->frame_index, 7);
        if (enc == DepthEncoding::kDeltaVarint) {
            // Smooth depth compresses to well under 2 bytes per pixel.
            EXPECT_LT(m->data.size(), f.depth.size() * 3 / 2);
            RecordProperty("delta_varint_bytes_per_pixel",
                           std::to_string(double(m->data.size()) / f.depth.size()));
        } else {
            EXPECT_EQ(m->data.size(), f.depth.size() * 2);
        }
    }
}

TEST(Conversions, DepthFramesRejectMalformedData) {
    RawDepthFrame f;
    f.depth = sampleDepth();
    const auto good = toMessage(f, DepthEncoding::kDeltaVarint, 1).value();
    auto truncated = good;
    truncated.data.pop_back();
    truncated.size = static_cast<int32_t>(truncated.data.size());
    EXPECT_FALSE(fromMessage(truncated).isOk());
    auto trailing = good;
    trailing.data.push_back(0);
    trailing.size = static_cast<int32_t>(trailing.data.size());
    EXPECT_FALSE(fromMessage(trailing).isOk());
    auto overlong = good;
    overlong.data.assign(good.data.size(), 0xFF);  // never-ending varints
    EXPECT_FALSE(fromMessage(overlong).isOk());
    auto negative = good;
    negative.data[0] = 1;  // first pixel decodes to -1
    EXPECT_FALSE(fromMessage(negative).isOk());
    auto size = good;
    size.width = 0;
    EXPECT_FALSE(fromMessage(size).isOk());
    size = good;
    size.height = kMaxDepthSide + 1;
    EXPECT_FALSE(fromMessage(size).isOk());
    auto enc = good;
    enc.encoding = 5;
    EXPECT_FALSE(fromMessage(enc).isOk());
    auto raw = toMessage(f, DepthEncoding::kRaw16, 1).value();
    raw.data.resize(raw.data.size() - 2);
    raw.size = static_cast<int32_t>(raw.data.size());
    EXPECT_FALSE(fromMessage(raw).isOk());
    RawDepthFrame empty;
    EXPECT_FALSE(toMessage(empty, DepthEncoding::kRaw16, 1).isOk());
}

/// A 160x120 indoor-like colour image: smooth shading, a sharp edge, a textured patch with
/// sensor noise.
ColourImage sampleColour() {
    ColourImage c(160, 120);
    std::mt19937 rng(5);
    std::normal_distribution<double> noise(0.0, 1.5);
    for (int v = 0; v < c.height(); ++v) {
        for (int u = 0; u < c.width(); ++u) {
            const double shade = 90.0 + 0.4 * u + 0.3 * v + noise(rng);
            const bool poster = u > 100 && v > 30 && v < 90;  // a darker object with a pattern
            const double texture = poster ? 40.0 * ((u / 4 + v / 4) % 2) - 50.0 : 0.0;
            const auto clamp = [](double x) {
                return static_cast<uint8_t>(std::lround(std::clamp(x, 0.0, 255.0)));
            };
            c(u, v) = Rgb8{clamp(shade + texture + 20.0), clamp(shade + texture),
                           clamp(0.8 * shade + texture)};
        }
    }
    return c;
}

RawRgbdFrame sampleRgbdFrame() {
    RawRgbdFrame f;
    f.utime = 1234567;
    f.frame_index = 42;
    f.depth_scale = 1000.0;
    f.depth = sampleDepth();
    f.colour = sampleColour();
    return f;
}

TEST(Conversions, RgbdFramesRoundTripLosslesslyInEveryEncoding) {
    const RawRgbdFrame f = sampleRgbdFrame();
    for (const DepthEncoding depth : {DepthEncoding::kRaw16, DepthEncoding::kDeltaVarint}) {
        for (const ColourEncoding colour :
             {ColourEncoding::kNone, ColourEncoding::kRgb8, ColourEncoding::kDeltaRice}) {
            auto m = toMessage(f, depth, colour, 9);
            ASSERT_TRUE(m.isOk()) << m.status().toString();
            const Bytes bytes = encodeMessage(*m);
            auto back = decodeRawFrame(bytes);
            ASSERT_TRUE(back.isOk()) << back.status().toString();
            EXPECT_EQ(back->utime, f.utime);
            EXPECT_EQ(back->frame_index, 42);
            EXPECT_EQ(back->depth_scale, 1000.0);
            EXPECT_EQ(back->depth, f.depth);
            if (colour == ColourEncoding::kNone) {
                EXPECT_TRUE(back->colour.empty());
                EXPECT_TRUE(m->colour_data.empty());
            } else {
                EXPECT_EQ(back->colour, f.colour);
            }
            if (colour == ColourEncoding::kRgb8) {
                EXPECT_EQ(m->colour_data.size(), f.colour.size() * 3);
                EXPECT_EQ(m->colour_data[3 * 161], f.colour(1, 1).r);  // R, G, B order
                EXPECT_EQ(m->colour_data[3 * 161 + 2], f.colour(1, 1).b);
            }
            if (colour == ColourEncoding::kDeltaRice) {
                const double ratio = double(m->colour_data.size()) / (f.colour.size() * 3);
                EXPECT_LT(ratio, 0.6);
                RecordProperty("delta_rice_fraction_of_raw", std::to_string(ratio));
            }
        }
    }
    // A frame without colour goes out as COLOUR_NONE whatever was asked.
    RawRgbdFrame depth_only = f;
    depth_only.colour = ColourImage();
    auto m = toMessage(depth_only, DepthEncoding::kDeltaVarint, ColourEncoding::kDeltaRice, 1);
    ASSERT_TRUE(m.isOk());
    EXPECT_EQ(m->colour_encoding, plumb::depth_frame2_t::COLOUR_NONE);
    auto back = decodeRawFrame(encodeMessage(*m));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_TRUE(back->colour.empty());
}

TEST(Conversions, OldDepthFrameLogsStillDecode) {
    RawDepthFrame old;
    old.utime = 77;
    old.frame_index = 3;
    old.depth_scale = 5000.0;
    old.depth = sampleDepth();
    auto m = toMessage(old, DepthEncoding::kDeltaVarint, 1);
    ASSERT_TRUE(m.isOk());
    auto back = decodeRawFrame(encodeMessage(*m));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(back->depth, old.depth);
    EXPECT_EQ(back->depth_scale, 5000.0);
    EXPECT_EQ(back->frame_index, 3);
    EXPECT_TRUE(back->colour.empty());
    // Neither raw frame type: a specific error, not a guess.
    CameraInfo info;
    info.camera = cameraPreset("ci").value();
    auto wrong = decodeRawFrame(encodeMessage(toMessage(info, 1, 2)));
    ASSERT_FALSE(wrong.isOk());
    EXPECT_EQ(wrong.status().code(), StatusCode::kCorrupt);
    EXPECT_NE(wrong.status().message().find("depth_frame2_t: wrong type"), std::string::npos)
        << wrong.status().message();
}

TEST(Conversions, SessionRgbdFramesCarryTheirSessionAndOlderOnesNone) {
    const RawRgbdFrame f = sampleRgbdFrame();
    auto m = toSessionMessage(f, 1796661477802188, DepthEncoding::kDeltaVarint,
                              ColourEncoding::kDeltaRice, 5);
    ASSERT_TRUE(m.isOk()) << m.status().toString();
    EXPECT_EQ(m->frame.seq, 5);
    auto back = decodeRawFrame(encodeMessage(*m));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(back->session_id, 1796661477802188);
    EXPECT_EQ(back->utime, f.utime);
    EXPECT_EQ(back->frame_index, 42);
    EXPECT_EQ(back->depth, f.depth);
    EXPECT_EQ(back->colour, f.colour);
    // The released depth_frame2_t names no session.
    auto older = decodeRawFrame(encodeMessage(
        toMessage(f, DepthEncoding::kDeltaVarint, ColourEncoding::kDeltaRice, 5).value()));
    ASSERT_TRUE(older.isOk());
    EXPECT_FALSE(older->session_id.has_value());
    EXPECT_EQ(older->colour, f.colour);
    // A frame the inner message refuses is refused inside the new one too; damage is Corrupt.
    RawRgbdFrame bad = f;
    bad.depth_scale = -1.0;
    EXPECT_EQ(toSessionMessage(bad, 1, DepthEncoding::kDeltaVarint, ColourEncoding::kNone, 1)
                  .status()
                  .code(),
              StatusCode::kInvalidArgument);
    std::vector<uint8_t> damaged = encodeMessage(*m);
    damaged.resize(damaged.size() - 7);
    EXPECT_EQ(decodeRawFrame(damaged).status().code(), StatusCode::kCorrupt);
}

TEST(Conversions, RgbdFramesRejectForgedAndTruncatedColour) {
    const RawRgbdFrame f = sampleRgbdFrame();
    const auto rice =
        toMessage(f, DepthEncoding::kDeltaVarint, ColourEncoding::kDeltaRice, 1).value();
    const auto raw = toMessage(f, DepthEncoding::kDeltaVarint, ColourEncoding::kRgb8, 1).value();
    const auto expectCorrupt = [](plumb::depth_frame2_t m, const std::string& fragment) {
        m.colour_size = static_cast<int32_t>(m.colour_data.size());
        auto r = fromMessage(m);
        ASSERT_FALSE(r.isOk()) << fragment;
        EXPECT_EQ(r.status().code(), StatusCode::kCorrupt);
        EXPECT_NE(r.status().message().find(fragment), std::string::npos) << r.status().message();
        // The same through the wire.
        EXPECT_FALSE(decodeRawFrame(encodeMessage(m)).isOk());
    };
    auto m = rice;
    m.colour_data.pop_back();
    expectCorrupt(m, "truncated");
    m = rice;
    m.colour_data.push_back(0);
    expectCorrupt(m, "trailing bytes");
    m = rice;
    m.colour_data[0] = 8;  // Rice parameter of row 0, red
    expectCorrupt(m, "Rice parameter 8 at row 0");
    m = rice;
    std::fill(m.colour_data.begin() + 1, m.colour_data.end(), 0xFF);  // unary codes forever
    expectCorrupt(m, "overlong code");
    m = rice;
    m.colour_data.resize(1);
    expectCorrupt(m, "truncated");
    m = raw;
    m.colour_data.resize(m.colour_data.size() - 3);
    expectCorrupt(m, "colour bytes for 19200 RGB pixels");
    m = raw;
    m.colour_encoding = 3;
    expectCorrupt(m, "unknown colour encoding 3");
    m = raw;
    m.colour_encoding = plumb::depth_frame2_t::COLOUR_NONE;
    expectCorrupt(m, "colour bytes without colour");
    // The size field must agree with the bytes.
    m = raw;
    m.colour_size = 5;
    auto sized = fromMessage(m);
    ASSERT_FALSE(sized.isOk());
    EXPECT_NE(sized.status().message().find("colour size field 5"), std::string::npos);
    // A depth part that is damaged fails as it does in depth_frame_t.
    m = rice;
    m.width = 0;
    EXPECT_FALSE(fromMessage(m).isOk());
    // Colour of another size than the depth is refused before it is sent.
    RawRgbdFrame mismatched = f;
    mismatched.colour = ColourImage(80, 60);
    EXPECT_EQ(
        toMessage(mismatched, DepthEncoding::kRaw16, ColourEncoding::kRgb8, 1).status().code(),
        StatusCode::kInvalidArgument);
    // A forged array count on the wire (colour_size far beyond the message) never allocates.
    Bytes bytes = encodeMessage(raw);
    const size_t colour_count_pos = bytes.size() - raw.colour_data.size() - 4;
    bytes[colour_count_pos] = 0x7F;
    auto forged = decodeRawFrame(bytes);
    ASSERT_FALSE(forged.isOk());
    EXPECT_NE(forged.status().message().find("exceeds"), std::string::npos)
        << forged.status().message();
    // Every prefix of a valid message is refused.
    const Bytes whole = encodeMessage(rice);
    for (size_t len = 0; len < whole.size(); len += 97) {
        EXPECT_FALSE(decodeRawFrame(std::span(whole).first(len)).isOk()) << len;
    }
}

TEST(ColourCodec, NoiseRoundTripsWithinItsWorstCaseAndDamageNeverCrashes) {
    ColourImage noise(64, 48);
    std::mt19937 rng(11);
    for (Rgb8& p : noise.pixels()) {
        p = Rgb8{static_cast<uint8_t>(rng()), static_cast<uint8_t>(rng()),
                 static_cast<uint8_t>(rng())};
    }
    const auto bytes = encodeColourRice(noise);
    auto back = decodeColourRice(bytes, 64, 48);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(*back, noise);
    // At most 9 bits a sample (k = 7) plus a parameter byte per row and channel.
    EXPECT_LE(bytes.size(), (64 * 48 * 3 * 9 + 7) / 8 + 48 * 3);
    const ColourImage flat(64, 48, Rgb8{10, 20, 30});
    const auto flat_bytes = encodeColourRice(flat);
    EXPECT_LT(flat_bytes.size(), 64 * 48 * 3 / 6);  // one bit a sample
    EXPECT_EQ(*decodeColourRice(flat_bytes, 64, 48), flat);
    EXPECT_FALSE(decodeColourRice(flat_bytes, 64, 49).isOk());
    EXPECT_FALSE(decodeColourRice(flat_bytes, 0, 48).isOk());
    // Random damage: an error or an image of the asked size, never a crash.
    const auto good = encodeColourRice(sampleColour());
    for (int trial = 0; trial < 300; ++trial) {
        auto damaged = good;
        for (int i = 0; i < 3; ++i) damaged[rng() % damaged.size()] ^= uint8_t(1u << (rng() % 8));
        if (trial % 3 == 0) damaged.resize(rng() % damaged.size());
        auto r = decodeColourRice(damaged, 160, 120);
        if (r.isOk()) {
            EXPECT_EQ(r->width(), 160);
        } else {
            EXPECT_EQ(r.status().code(), StatusCode::kCorrupt);
        }
    }
}

TEST(Conversions, ConfigSnapshotCarriesToml) {
    const std::string toml = "[fusion]\nvoxel_size_m = 0.01 # metres\n";
    auto back = decodeMessage<plumb::config_snapshot_t>(
        encodeMessage(toMessage("plumb-device", "0.1.0", toml, 10, 11)));
    ASSERT_TRUE(back.isOk());
    EXPECT_EQ(back->program, "plumb-device");
    EXPECT_EQ(back->toml, toml);
}

}  // namespace
}  // namespace plumb::messages
