// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <cmath>
#include <random>

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
