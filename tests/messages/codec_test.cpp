// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "common/geometry/lie.hpp"
#include "messages/crc32.hpp"
#include "messages/fragment_codec.hpp"

namespace plumb::messages {
namespace {

// Angle between two directions in double precision (float acos cannot resolve 1e-5 rad).
double angle(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
    const Eigen::Vector3d ad = a.cast<double>(), bd = b.cast<double>();
    return std::atan2(ad.cross(bd).norm(), ad.dot(bd));
}

Fragment makeFragment(size_t num_points, double extent_m, bool colors, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> coord(-0.5f * static_cast<float>(extent_m),
                                                0.5f * static_cast<float>(extent_m));
    std::normal_distribution<float> gauss(0.0f, 1.0f);
    Fragment f;
    f.id = 17;
    f.segment = 2;
    f.end = FragmentEnd::kTrackingLost;
    Vector6d xi;
    xi << 0.3, -0.2, 0.1, 1.5, -0.25, 2.0;
    f.T_W_F = lie::expSE3(xi);
    f.voxel_size_m = 0.01;
    f.tracking_quality = 0.875;
    for (int k = 0; k < 50; ++k) {
        FragmentFrame fr;
        fr.frame_index = 1000 + k;
        fr.timestamp_s = 1305031102.175304 + k / 30.0;
        fr.T_F_C = lie::expSE3(xi * (k / 50.0));
        fr.tracking_ok = (k % 7) != 3;
        f.frames.push_back(fr);
    }
    for (size_t i = 0; i < num_points; ++i) {
        f.points_F.points.emplace_back(coord(rng), coord(rng), coord(rng) + 3.0f);
        Eigen::Vector3f n(gauss(rng), gauss(rng), gauss(rng));
        f.points_F.normals.push_back(n.normalized());
        if (colors) {
            f.points_F.colors.emplace_back(static_cast<uint8_t>(rng()), static_cast<uint8_t>(rng()),
                                           static_cast<uint8_t>(rng()));
        }
    }
    return f;
}

TEST(FragmentCodec, RoundTripWithinStatedBounds) {
    const Fragment f = makeFragment(20000, 6.0, true, 1);
    const double step = positionStep(f.points_F.points);
    ASSERT_GT(step, 0.0);
    EXPECT_LE(step, 6.0 / 65535.0 + 1e-12);  // the box side over 65535
    auto bytes = encodeFragment(f);
    ASSERT_TRUE(bytes.isOk()) << bytes.status().toString();
    // 13 bytes per point with colours, plus the fixed part and 113 bytes per frame.
    const size_t fixed = bytes->size() - 13 * f.points_F.size() - 113 * f.frames.size();
    EXPECT_EQ(fixed, 4u + 2 + 2 + 4 + 4 + 1 + 96 + 8 + 8 + 4 + 4 + 24 + 8 + 4);
    auto back = decodeFragment(*bytes);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(back->id, f.id);
    EXPECT_EQ(back->segment, f.segment);
    EXPECT_EQ(back->end, f.end);
    EXPECT_EQ(back->voxel_size_m, f.voxel_size_m);
    EXPECT_EQ(back->tracking_quality, f.tracking_quality);
    EXPECT_TRUE(back->T_W_F.matrix() == f.T_W_F.matrix());  // doubles are exact
    ASSERT_EQ(back->frames.size(), f.frames.size());
    for (size_t k = 0; k < f.frames.size(); ++k) {
        EXPECT_EQ(back->frames[k].frame_index, f.frames[k].frame_index);
        EXPECT_EQ(back->frames[k].timestamp_s, f.frames[k].timestamp_s);
        EXPECT_TRUE(back->frames[k].T_F_C.matrix() == f.frames[k].T_F_C.matrix());
        EXPECT_EQ(back->frames[k].tracking_ok, f.frames[k].tracking_ok);
    }
    ASSERT_EQ(back->points_F.size(), f.points_F.size());
    ASSERT_TRUE(back->points_F.hasNormals());
    ASSERT_TRUE(back->points_F.hasColors());
    double max_pos_err = 0.0, max_angle = 0.0;
    for (size_t i = 0; i < f.points_F.size(); ++i) {
        const Eigen::Vector3d d =
            (back->points_F.points[i] - f.points_F.points[i]).cast<double>().cwiseAbs();
        max_pos_err = std::max(max_pos_err, d.maxCoeff());
        max_angle = std::max(max_angle, angle(back->points_F.normals[i], f.points_F.normals[i]));
        EXPECT_NEAR(back->points_F.normals[i].norm(), 1.0f, 1e-6f);
        EXPECT_EQ(back->points_F.colors[i], f.points_F.colors[i]);
    }
    // Per-axis error <= step / 2, plus float rounding of coordinates up to 3.5 m.
    EXPECT_LE(max_pos_err, step / 2 + 5e-7);
    EXPECT_LT(max_pos_err, 0.25e-3);
    RecordProperty("max_position_error_m", std::to_string(max_pos_err));
    // Stated bound of the octahedral snorm16 normals.
    EXPECT_LT(max_angle, 1.5e-4);
    RecordProperty("max_normal_angle_rad", std::to_string(max_angle));
    // Re-encoding the decoded fragment is stable.
    auto again = encodeFragment(*back);
    ASSERT_TRUE(again.isOk());
    auto back2 = decodeFragment(*again);
    ASSERT_TRUE(back2.isOk());
    EXPECT_TRUE(back2->points_F.points == back->points_F.points);
}

TEST(FragmentCodec, LargeFragmentsStayWithinHalfMillimetreOrFallBack) {
    // 30 m across: uint16 with step 30/65535 = 0.46 mm, error <= 0.23 mm.
    const Fragment wide = makeFragment(2000, 30.0, false, 2);
    const double step = positionStep(wide.points_F.points);
    EXPECT_GT(step, 0.0);
    EXPECT_LE(step, 0.0005);
    auto b = encodeFragment(wide);
    ASSERT_TRUE(b.isOk());
    EXPECT_EQ(b->size() - 113 * 50, 173u + 10 * 2000);  // 10 bytes per point without colours
    auto d = decodeFragment(*b);
    ASSERT_TRUE(d.isOk());
    for (size_t i = 0; i < wide.points_F.size(); ++i) {
        EXPECT_LE((d->points_F.points[i] - wide.points_F.points[i]).cwiseAbs().maxCoeff(),
                  step / 2 + 4e-6);
    }
    // 40 m across exceeds 0.5 mm steps: float32 positions, exact.
    const Fragment huge = makeFragment(500, 40.0, false, 3);
    EXPECT_EQ(positionStep(huge.points_F.points), 0.0);
    auto hb = encodeFragment(huge);
    ASSERT_TRUE(hb.isOk());
    auto hd = decodeFragment(*hb);
    ASSERT_TRUE(hd.isOk());
    EXPECT_TRUE(hd->points_F.points == huge.points_F.points);
}

TEST(FragmentCodec, EdgeCasesRoundTrip) {
    Fragment empty;
    auto b = encodeFragment(empty);
    ASSERT_TRUE(b.isOk());
    auto d = decodeFragment(*b);
    ASSERT_TRUE(d.isOk()) << d.status().toString();
    EXPECT_TRUE(d->points_F.empty());
    EXPECT_TRUE(d->frames.empty());
    // Bare points (no normals) and one point (zero extent).
    Fragment one;
    one.points_F.points.emplace_back(1.25f, -2.5f, 3.75f);
    auto ob = encodeFragment(one);
    ASSERT_TRUE(ob.isOk());
    auto od = decodeFragment(*ob);
    ASSERT_TRUE(od.isOk());
    EXPECT_EQ(od->points_F.points[0], one.points_F.points[0]);
    EXPECT_FALSE(od->points_F.hasNormals());
    // Axis-aligned and antipodal normals survive the octahedral folds exactly enough.
    for (const Eigen::Vector3f& n :
         {Eigen::Vector3f(0, 0, 1), Eigen::Vector3f(0, 0, -1), Eigen::Vector3f(1, 0, 0),
          Eigen::Vector3f(-1, 0, 0), Eigen::Vector3f(0, -1, 0),
          Eigen::Vector3f(1, 1, -1).normalized(), Eigen::Vector3f(-1, -1, -1).normalized()}) {
        const auto [x, y] = encodeOctahedral(n);
        EXPECT_LT(angle(decodeOctahedral(x, y), n), 1.5e-4) << n.transpose();
    }
    // The stated bound over many random directions; the poles and axes are exact.
    std::mt19937 rng(11);
    std::normal_distribution<float> gauss(0.0f, 1.0f);
    double worst = 0.0;
    for (int i = 0; i < 200000; ++i) {
        const Eigen::Vector3f n = Eigen::Vector3f(gauss(rng), gauss(rng), gauss(rng)).normalized();
        const auto [x, y] = encodeOctahedral(n);
        worst = std::max(worst, angle(decodeOctahedral(x, y), n));
    }
    EXPECT_LT(worst, 1.5e-4);
    RecordProperty("worst_normal_angle_rad", std::to_string(worst));
    for (const Eigen::Vector3f& axis : {Eigen::Vector3f(0, 0, -1), Eigen::Vector3f(1, 0, 0)}) {
        const auto [x, y] = encodeOctahedral(axis);
        EXPECT_EQ(decodeOctahedral(x, y), axis);
    }
    // Colours can be dropped by config.
    const Fragment c = makeFragment(100, 2.0, true, 4);
    FragmentCodecConfig no_colors;
    no_colors.include_colors = false;
    auto nb = encodeFragment(c, no_colors);
    ASSERT_TRUE(nb.isOk());
    EXPECT_FALSE(decodeFragment(*nb)->points_F.hasColors());
}

TEST(FragmentCodec, EncoderRejectsBadInput) {
    Fragment f = makeFragment(10, 1.0, false, 5);
    f.points_F.points[3].x() = std::nanf("");
    EXPECT_EQ(encodeFragment(f).status().code(), StatusCode::kInvalidArgument);
    f = makeFragment(10, 1.0, false, 5);
    f.points_F.normals[2].setZero();
    EXPECT_FALSE(encodeFragment(f).isOk());
    f = makeFragment(10, 1.0, false, 5);
    f.points_F.normals.pop_back();
    EXPECT_FALSE(encodeFragment(f).isOk());
    f = makeFragment(10, 1.0, false, 5);
    f.T_W_F.matrix()(0, 0) = 2.0;
    EXPECT_FALSE(encodeFragment(f).isOk());
    f = makeFragment(10, 1.0, false, 5);
    f.frames[4].timestamp_s = INFINITY;
    EXPECT_FALSE(encodeFragment(f).isOk());
}

// Rewrites the CRC trailer so that a deliberate field corruption reaches the field checks.
void fixCrc(std::vector<uint8_t>& b) {
    const uint32_t crc = crc32(std::span(b).first(b.size() - 4));
    std::memcpy(b.data() + b.size() - 4, &crc, 4);
}

TEST(FragmentCodec, DecoderRejectsEveryCorruption) {
    const Fragment f = makeFragment(300, 3.0, true, 6);
    const std::vector<uint8_t> good = encodeFragment(f).value();
    // Every truncation fails.
    for (size_t len = 0; len < good.size(); len += (len < 400 ? 1 : 97)) {
        EXPECT_FALSE(decodeFragment(std::span(good).first(len)).isOk()) << len;
    }
    // Every single-bit flip is caught by the CRC.
    std::mt19937 rng(9);
    for (int trial = 0; trial < 500; ++trial) {
        std::vector<uint8_t> bad = good;
        const size_t bit = rng() % (bad.size() * 8);
        bad[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
        EXPECT_FALSE(decodeFragment(bad).isOk());
    }
    // Field corruptions with a valid CRC: absurd counts, NaN pose, bad enum, unknown flags.
    auto patched = [&](size_t offset, const void* value, size_t n) {
        std::vector<uint8_t> b = good;
        std::memcpy(b.data() + offset, value, n);
        fixCrc(b);
        return decodeFragment(b);
    };
    const uint32_t huge = 0xFFFFFFF0u;
    const size_t frames_offset = 4 + 2 + 2 + 4 + 4 + 1 + 96 + 16;
    EXPECT_FALSE(patched(frames_offset, &huge, 4).isOk());
    const size_t points_offset = frames_offset + 4 + 113 * f.frames.size();
    EXPECT_FALSE(patched(points_offset, &huge, 4).isOk());
    const uint32_t one_more = static_cast<uint32_t>(f.points_F.size() + 1);
    EXPECT_FALSE(patched(points_offset, &one_more, 4).isOk());
    const double nan = std::nan("");
    EXPECT_FALSE(patched(17, &nan, 8).isOk());  // T_W_F(0,0)
    const double two = 2.0;
    EXPECT_FALSE(patched(17, &two, 8).isOk());  // not a rotation
    const uint8_t end = 9;
    EXPECT_FALSE(patched(16, &end, 1).isOk());
    const uint16_t flags = 0x80;
    EXPECT_FALSE(patched(6, &flags, 2).isOk());
    const double zero_step = 0.0;
    EXPECT_FALSE(patched(points_offset + 4 + 24, &zero_step, 8).isOk());
    const uint16_t version = 7;
    EXPECT_EQ(patched(4, &version, 2).status().code(), StatusCode::kUnsupported);
    const uint32_t not_magic = 0x12345678u;
    EXPECT_FALSE(patched(0, &not_magic, 4).isOk());
    // The unpatched bytes still decode (the helper itself is sound).
    std::vector<uint8_t> same = good;
    fixCrc(same);
    EXPECT_TRUE(decodeFragment(same).isOk());
}

/// A symmetric positive definite information matrix, weak along one translation.
Matrix6d corridorInformation() {
    Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Identity();
    A(0, 3) = 0.25;
    A(4, 1) = -0.5;
    Matrix6d H = A * A.transpose() * 1.5e4;
    H.row(5).setZero();
    H.col(5).setZero();
    H(5, 5) = 3.0;  // the slide along z is barely observed
    return H;
}

TEST(FragmentCodec, Version2CarriesTheOdometryInformation) {
    Fragment f = makeFragment(400, 2.0, true, 7);
    const std::vector<uint8_t> v1 = encodeFragment(f).value();
    uint16_t version = 0;
    std::memcpy(&version, v1.data() + 4, 2);
    EXPECT_EQ(version, 1) << "a fragment without odometry information stays version 1";

    f.odometry_information = corridorInformation();
    const std::vector<uint8_t> v2 = encodeFragment(f).value();
    std::memcpy(&version, v2.data() + 4, 2);
    EXPECT_EQ(version, 2);
    EXPECT_EQ(v2.size(), v1.size() + 21 * 8);
    const Fragment back = decodeFragment(v2).value();
    EXPECT_EQ(back.odometry_information, f.odometry_information);  // doubles, exact
    EXPECT_EQ(back.points_F.size(), f.points_F.size());
    EXPECT_EQ(back.frames.size(), f.frames.size());
    EXPECT_TRUE(decodeFragment(v1).value().odometry_information.isZero(0.0));

    // The information flag is not a version-1 flag; corruptions of the matrix are caught.
    std::vector<uint8_t> bad = v2;
    const uint16_t one = 1;
    std::memcpy(bad.data() + 4, &one, 2);
    fixCrc(bad);
    EXPECT_EQ(decodeFragment(bad).status().code(), StatusCode::kCorrupt);
    const size_t info_offset = 4 + 2 + 2 + 4 + 4 + 1 + 96 + 16;
    const double negative = -1.0, nan = std::nan("");
    for (const double* v : {&negative, &nan}) {
        bad = v2;
        std::memcpy(bad.data() + info_offset, v, 8);  // H(0,0)
        fixCrc(bad);
        EXPECT_EQ(decodeFragment(bad).status().code(), StatusCode::kCorrupt);
    }
    f.odometry_information(0, 1) += 1.0;  // not symmetric
    EXPECT_EQ(encodeFragment(f).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace

}  // namespace plumb::messages
