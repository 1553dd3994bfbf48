// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "common/core/progress.hpp"

namespace plumb {
namespace {

// A clock the test moves by hand; safe to read from several threads.
struct FakeClock {
    std::atomic<double> now_s{1000.0};
    std::function<double()> fn() {
        return [this] { return now_s.load(); };
    }
};

std::vector<std::string> lines(const std::string& text) {
    std::vector<std::string> out;
    std::istringstream in(text);
    std::string line;
    while (std::getline(in, line)) out.push_back(line);
    return out;
}

TEST(Progress, FormatsRateAndDuration) {
    EXPECT_EQ(formatRate(0.0), "0.00");
    EXPECT_EQ(formatRate(2.5), "2.50");
    EXPECT_EQ(formatRate(23.94), "23.9");
    EXPECT_EQ(formatRate(99.96), "100");
    EXPECT_EQ(formatRate(1234.4), "1234");
    EXPECT_EQ(formatRate(-1.0), "-");
    EXPECT_EQ(formatDuration(0.0), "0s");
    EXPECT_EQ(formatDuration(4.2), "5s");  // rounded up: never promise too early
    EXPECT_EQ(formatDuration(59.0), "59s");
    EXPECT_EQ(formatDuration(187.0), "3m07s");
    EXPECT_EQ(formatDuration(3600.0 + 5 * 60 + 1), "1h06m");
    EXPECT_EQ(formatDuration(-1.0), "?");
}

TEST(Progress, LiveLineShowsBarCountPercentRateEta) {
    FakeClock clock;
    std::ostringstream out;
    ProgressOptions o;
    o.mode = ProgressOptions::Mode::kLive;
    o.stream = &out;
    o.clock = clock.fn();
    o.bar_width = 10;
    o.unit = "frames";
    Progress p("integrating frames", 240, o);
    // 120 of 240 after 5 s: 24 frames/s, 50%, 120 remaining -> 5 s.
    EXPECT_EQ(p.liveLine(120, 5.0),
              "integrating frames [#####.....] 120/240  50% 24.0 frames/s ETA 5s");
    // 1 of 240 after 0.5 s: 2 frames/s, 0% (floor), 239 remaining -> 119.5 s -> 2m00s.
    EXPECT_EQ(p.liveLine(1, 0.5),
              "integrating frames [..........] 1/240   0% 2.00 frames/s ETA 2m00s");
    EXPECT_EQ(p.liveLine(0, 0.0), "integrating frames [..........] 0/240   0% - frames/s ETA ?");
    EXPECT_EQ(p.liveLine(240, 10.0),
              "integrating frames [##########] 240/240 100% 24.0 frames/s ETA 0s");
    // Percent is floored: 239/240 is 99%, not 100%.
    EXPECT_NE(p.liveLine(239, 10.0).find("[#########.] 239/240  99% "), std::string::npos);
    p.finish();
}

TEST(Progress, LiveModeRedrawsAtMostOncePerIntervalAndEndsTheLine) {
    EXPECT_EQ(ProgressOptions{}.live_interval_s, 0.1);  // about ten redraws per second
    FakeClock clock;
    std::ostringstream out;
    ProgressOptions o;
    o.mode = ProgressOptions::Mode::kLive;
    o.stream = &out;
    o.clock = clock.fn();
    o.bar_width = 4;
    o.live_interval_s = 0.125;  // binary fractions keep the fake times exact
    Progress p("fuse", 64, o);
    // 64 advances 1/32 s apart over 2 s: the first draws, then every fourth (0.125 s later),
    // 16 redraws, plus the final one.
    for (int i = 0; i < 64; ++i) {
        clock.now_s = clock.now_s + 1.0 / 32.0;
        p.advance();
    }
    p.finish();
    const std::string text = out.str();
    EXPECT_EQ(std::count(text.begin(), text.end(), '\r'), 17);
    ASSERT_EQ(text.back(), '\n');
    EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1);
    EXPECT_EQ(text.substr(0, text.find('\r', 1)), "\rfuse [....] 1/64   1% 32.0/s ETA 2s");
    std::string last = text.substr(text.rfind('\r') + 1);
    last.erase(last.find_last_not_of(" \n") + 1);  // padding that clears a longer previous line
    EXPECT_EQ(last, "fuse [####] 64/64 100% 32.0/s done in 2.0s");
}

TEST(Progress, PlainModePrintsAtTheConfiguredIntervalAndAtTheEnd) {
    FakeClock clock;
    std::ostringstream out;
    ProgressOptions o;
    o.mode = ProgressOptions::Mode::kPlain;
    o.stream = &out;
    o.clock = clock.fn();
    o.plain_interval_s = 5.0;
    Progress p("loading", 1000, o);
    // One item every 0.1 s for 12 s: lines due at 5 s and 10 s, then the final line.
    for (int i = 0; i < 120; ++i) {
        clock.now_s = 1000.0 + 0.1 * (i + 1);
        p.advance();
    }
    EXPECT_EQ(p.count(), 120u);
    p.finish();
    p.finish();  // idempotent
    const std::vector<std::string> l = lines(out.str());
    ASSERT_EQ(l.size(), 3u) << out.str();
    EXPECT_EQ(l[0], "loading: 50/1000 (5%) 10.0/s ETA 1m35s");
    EXPECT_EQ(l[1], "loading: 100/1000 (10%) 10.0/s ETA 1m30s");
    EXPECT_EQ(l[2], "loading: 120/1000 (12%) 10.0/s, done in 12.0s");
    EXPECT_EQ(out.str().find('\r'), std::string::npos);
}

TEST(Progress, UnknownTotalShowsCountAndRateOnly) {
    FakeClock clock;
    std::ostringstream out;
    ProgressOptions o;
    o.mode = ProgressOptions::Mode::kPlain;
    o.stream = &out;
    o.clock = clock.fn();
    o.unit = "packets";
    {
        Progress p("receiving", 0, o);
        clock.now_s = clock.now_s + 4.0;
        p.advance(10);
        EXPECT_EQ(p.liveLine(10, 4.0), "receiving 10 2.50 packets/s");
    }  // the destructor finishes
    EXPECT_EQ(out.str(), "receiving: 10 2.50 packets/s, done in 4.0s\n");
}

TEST(Progress, AnAlgorithmsCallbackAdvancesTheProgressItIsConnectedTo) {
    ProgressOptions quiet;
    quiet.mode = ProgressOptions::Mode::kQuiet;
    Progress p("pairs", 10, quiet);
    const ProgressCallback callback = advanceOf(p);
    report(callback);
    report(callback, 4);
    EXPECT_EQ(p.count(), 5u);
    const ProgressCallback nobody;
    report(nobody, 3);  // an empty callback is a no-op
    EXPECT_EQ(p.count(), 5u);
}

TEST(Progress, QuietPrintsNothingAndStillCounts) {
    FakeClock clock;
    std::ostringstream out;
    ProgressOptions o;
    o.mode = ProgressOptions::Mode::kQuiet;
    o.stream = &out;
    o.clock = clock.fn();
    Progress p("silent", 10, o);
    for (int i = 0; i < 10; ++i) {
        clock.now_s = clock.now_s + 10.0;
        p.advance();
    }
    p.finish();
    EXPECT_EQ(p.count(), 10u);
    EXPECT_TRUE(out.str().empty());
}

TEST(Progress, ConcurrentAdvanceFromTwoThreadsCountsExactly) {
    std::ostringstream out;
    ProgressOptions o;
    o.mode = ProgressOptions::Mode::kLive;  // exercise the drawing path under contention
    o.stream = &out;
    o.live_interval_s = 0.001;
    constexpr uint64_t kPerThread = 200000;
    Progress p("count", 2 * kPerThread, o);
    std::vector<std::thread> workers;
    for (int t = 0; t < 2; ++t) {
        workers.emplace_back([&p] {
            for (uint64_t i = 0; i < kPerThread; ++i) p.advance();
        });
    }
    for (std::thread& w : workers) w.join();
    p.finish();
    EXPECT_EQ(p.count(), 2 * kPerThread);
    const std::string text = out.str();
    const std::string last = text.substr(text.rfind('\r') + 1);
    EXPECT_EQ(last.rfind("count [####################] 400000/400000 100% ", 0), 0u) << last;
}

}  // namespace
}  // namespace plumb
