// SPDX-License-Identifier: Apache-2.0
// The replay of a live camera against measured frame times (device/fusion/live_rate.hpp).

#include "device/fusion/live_rate.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace plumb::device {
namespace {

constexpr double kPeriod = 1000.0 / 30.0;

TEST(LiveRate, FramesFasterThanTheCameraAreAllKept) {
    const std::vector<double> ms(90, 0.9 * kPeriod);
    const LiveRate r = replayLiveCamera(ms, kPeriod, 4);
    EXPECT_EQ(r.frames, 90u);
    EXPECT_EQ(r.kept, 90u);
    EXPECT_EQ(r.longest_drop_run, 0u);
    EXPECT_DOUBLE_EQ(r.keptFraction(), 1.0);
    EXPECT_NEAR(r.max_latency_ms, 0.9 * kPeriod, 1e-9);
}

TEST(LiveRate, WithoutAQueueFramesTakingTwoPeriodsKeepEveryOther) {
    const std::vector<double> ms(31, 2.0 * kPeriod);
    const LiveRate r = replayLiveCamera(ms, kPeriod, 0);
    EXPECT_EQ(r.kept, 16u);  // frames 0, 2, ..., 30
    EXPECT_EQ(r.longest_drop_run, 1u);
}

TEST(LiveRate, OneLongFrameDropsTheFramesItsQueueCannotHold) {
    // Frames of half a period, but frame 10 takes ten periods: frames 11-14 wait in the queue
    // of four, 15-19 find it full and are dropped; a queue of twelve holds all nine.
    std::vector<double> ms(60, 0.5 * kPeriod);
    ms[10] = 10.0 * kPeriod;
    const LiveRate four = replayLiveCamera(ms, kPeriod, 4);
    EXPECT_EQ(four.kept, 55u);
    EXPECT_EQ(four.longest_drop_run, 5u);
    EXPECT_NEAR(four.max_latency_ms, 10.0 * kPeriod, 1e-9);
    const LiveRate twelve = replayLiveCamera(ms, kPeriod, 12);
    EXPECT_EQ(twelve.kept, 60u);
    EXPECT_EQ(twelve.longest_drop_run, 0u);
    EXPECT_NEAR(twelve.max_latency_ms, 10.0 * kPeriod, 1e-9);
}

TEST(LiveRate, AnEmptyRecordKeepsEverything) {
    const LiveRate r = replayLiveCamera({}, kPeriod, 4);
    EXPECT_EQ(r.frames, 0u);
    EXPECT_DOUBLE_EQ(r.keptFraction(), 1.0);
}

}  // namespace
}  // namespace plumb::device
