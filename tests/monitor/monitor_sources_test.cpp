// SPDX-License-Identifier: Apache-2.0
// The monitor's feeds: LCM messages (live or replayed) and output directories.

#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>
#include <thread>

#include "common/io/trajectory.hpp"
#include "common/layout/layout_json.hpp"
#include "messages/fragment_files.hpp"
#include "messages/fragment_store.hpp"
#include "tests/monitor/monitor_fixtures.hpp"
#include "tests/monitor/session_log.hpp"
#include "tools/monitor/sources.hpp"

namespace plumb::monitor {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

fs::path freshDir(const std::string& name) {
    const fs::path dir =
        fs::temp_directory_path() / ("plumb_monitor_" + name + "_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

std::vector<Fragment> roomFragments(int n) {
    std::vector<Fragment> out;
    for (int k = 0; k < n; ++k) out.push_back(testing::roomFragment(k));
    return out;
}

TEST(MessageIngest, ReassemblesFragmentsAndHeartbeatsWithoutPublishing) {
    const auto fragments = roomFragments(3);
    // Small chunks: every fragment needs several.
    auto msgs = testing::sessionMessages(fragments, 42, 0.5, 2000);
    ASSERT_TRUE(msgs.isOk()) << msgs.status().message();
    size_t chunks = 0;
    for (const auto& m : *msgs) chunks += m.channel == messages::kChannelFragmentChunk;
    ASSERT_GT(chunks, 3u * 2u);

    MonitorState state;
    MessageIngest ingest(state);
    for (const auto& m : *msgs) ingest.onMessage(m.channel, m.bytes, m.time_s);
    EXPECT_EQ(ingest.fragmentsDecoded(), 3u);
    EXPECT_EQ(ingest.malformed(), 0u);
    // The acks the assembler wanted to send went nowhere: the monitor only listens.
    EXPECT_EQ(ingest.suppressedPublications(), 3u);
    const json j = state.toJson();
    ASSERT_EQ(j["fragments"].size(), 3u);
    for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(j["fragments"][k]["id"], k);
        EXPECT_EQ(j["fragments"][k]["session"], 42);
        EXPECT_EQ(j["fragments"][k]["num_points"], fragments[k].points_F.size());
        EXPECT_EQ(j["fragments"][k]["origin"], "lcm");
    }
    EXPECT_EQ(j["device"]["session_id"], 42);
    EXPECT_EQ(j["device"]["fragments_cut"], 3);
    EXPECT_EQ(j["device"]["tracking"], "ok");
    EXPECT_EQ(j["link"]["fragments_completed"], 3);
    EXPECT_EQ(j["link"]["chunks_received"], chunks);
}

TEST(MessageIngest, CorruptChunksAreCountedAndTheResendCompletes) {
    const auto fragments = roomFragments(1);
    auto msgs = testing::sessionMessages(fragments, 1, 0.5, 2000);
    ASSERT_TRUE(msgs.isOk());
    MonitorState state;
    MessageIngest ingest(state);
    // First pass: flip a payload byte of every chunk (CRC mismatch) and truncate the heartbeat.
    for (auto m : *msgs) {
        if (m.channel == messages::kChannelFragmentChunk) m.bytes[m.bytes.size() - 1] ^= 0x5a;
        if (m.channel == messages::kChannelStatus) m.bytes.resize(m.bytes.size() / 2);
        ingest.onMessage(m.channel, m.bytes, m.time_s);
    }
    EXPECT_EQ(state.numFragments(), 0u);
    json j = state.toJson();
    EXPECT_TRUE(j["device"].is_null());
    EXPECT_GT(j["link"]["chunk_crc_failures"].get<int>(), 0);
    EXPECT_FALSE(j["errors"].empty());
    // Second pass: the sender's retransmission arrives intact.
    for (const auto& m : *msgs) ingest.onMessage(m.channel, m.bytes, m.time_s + 1.0);
    EXPECT_EQ(state.numFragments(), 1u);
    // Garbage on every channel never crashes.
    const std::vector<uint8_t> junk = {1, 2, 3};
    for (const std::string& ch : MessageIngest::channels()) ingest.onMessage(ch, junk, 3.0);
    ingest.onMessage("OTHER", junk, 3.0);
    EXPECT_EQ(state.numFragments(), 1u);
}

TEST(LogReplaySource, PlaysALogIntoTheState) {
    const fs::path dir = freshDir("replay");
    auto msgs = testing::sessionMessages(roomFragments(4), 5, 0.01);
    ASSERT_TRUE(msgs.isOk());
    ASSERT_TRUE(testing::writeLcmLog(dir / "scan.lcm", *msgs).isOk());
    MonitorState state;
    auto replay = LogReplaySource::start(dir / "scan.lcm", 0.0, state);
    ASSERT_TRUE(replay.isOk()) << replay.status().message();
    for (int i = 0; i < 1000 && !(*replay)->finished(); ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ASSERT_TRUE((*replay)->finished());
    const json j = state.toJson();
    EXPECT_EQ(j["fragments"].size(), 4u);
    EXPECT_EQ(j["source"]["replay"]["finished"], true);
    EXPECT_EQ(j["source"]["replay"]["messages"], msgs->size());
    EXPECT_EQ(j["edges"].size(), 3u);  // provisional odometry 0-1, 1-2, 2-3
    fs::remove_all(dir);
}

TEST(LogReplaySource, BadInputIsASpecificError) {
    MonitorState state;
    auto r = LogReplaySource::start("/nonexistent/x.lcm", 1.0, state);
    ASSERT_FALSE(r.isOk());
    EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
    const fs::path dir = freshDir("badlog");
    { std::ofstream(dir / "junk.lcm") << "this is not an LCM log"; }
    r = LogReplaySource::start(dir / "junk.lcm", -1.0, state);
    ASSERT_FALSE(r.isOk());
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    // A file that is not a log plays nothing (LCM finds no event sync word) and finishes.
    r = LogReplaySource::start(dir / "junk.lcm", 0.0, state);
    if (r.isOk()) {
        for (int i = 0; i < 500 && !(*r)->finished(); ++i) {
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        EXPECT_TRUE((*r)->finished());
        EXPECT_EQ(state.numFragments(), 0u);
    } else {
        EXPECT_EQ(r.status().code(), StatusCode::kIoError);
    }
    fs::remove_all(dir);
}

TEST(DirectoryWatcher, ReadsTheOutputContractAndFollowsChanges) {
    const fs::path dir = freshDir("dir");
    auto store = messages::FragmentStore::open(dir / "fragments");
    ASSERT_TRUE(store.isOk());
    for (int k = 0; k < 3; ++k) {
        auto bytes = messages::encodeFragment(testing::roomFragment(k));
        ASSERT_TRUE(bytes.isOk());
        ASSERT_TRUE((*store)->put(9, static_cast<uint32_t>(k), *bytes).isOk());
    }
    { std::ofstream(dir / "pose_graph.json") << testing::poseGraphJsonText(4); }
    ASSERT_TRUE(io::writeLayoutJson(dir / "layout.json", testing::roomLayout()).isOk());
    io::Trajectory traj;
    for (int i = 0; i < 5; ++i) {
        io::StampedPose p;
        p.timestamp_s = i;
        p.T_W_C.translation() = Eigen::Vector3d(0.1 * i, 0, 0);
        traj.push_back(p);
    }
    ASSERT_TRUE(io::writeTumTrajectory(dir / "trajectory.txt", traj).isOk());

    MonitorState state;
    DirectoryWatcher watcher(dir, state);
    EXPECT_EQ(watcher.scanOnce(), 3 + 1 + 1 + 1);
    json j = state.toJson();
    ASSERT_EQ(j["fragments"].size(), 3u);
    EXPECT_EQ(j["fragments"][0]["origin"], "store");
    EXPECT_EQ(j["fragments"][0]["session"], 9);
    EXPECT_EQ(j["fragments"][0]["pose_source"], "pose_graph");
    EXPECT_FALSE(j["layout"].is_null());
    EXPECT_EQ(j["trajectory_V"].size(), 5u);
    // Graph edges among present fragments, with the loop (0 -> 3) referring to a future one.
    EXPECT_EQ(j["edges"].size(), 5u);

    EXPECT_EQ(watcher.scanOnce(), 0);  // nothing changed

    // A new fragment arrives; the watcher never touches the store's files.
    auto bytes = messages::encodeFragment(testing::roomFragment(3));
    ASSERT_TRUE((*store)->put(9, 3, *bytes).isOk());
    EXPECT_EQ(watcher.scanOnce(), 1);
    EXPECT_EQ(state.numFragments(), 4u);

    // A pose graph caught half-written is not applied; the old one stays until it is whole.
    const std::string text = testing::poseGraphJsonText(5);
    { std::ofstream(dir / "pose_graph.json") << text.substr(0, text.size() / 2); }
    EXPECT_EQ(watcher.scanOnce(), 0);
    EXPECT_EQ(state.toJson()["edges"].size(), 5u);
    { std::ofstream(dir / "pose_graph.json") << text; }
    EXPECT_EQ(watcher.scanOnce(), 1);

    // A damaged fragment file is reported (after repeated attempts), not fatal, and left alone.
    const fs::path damaged = dir / "fragments" / messages::fragmentFileName(9, 7);
    { std::ofstream(damaged) << "garbage that fails the CRC trailer"; }
    for (int i = 0; i < 3; ++i) watcher.scanOnce();
    j = state.toJson();
    EXPECT_EQ(j["fragments"].size(), 4u);
    bool reported = false;
    for (const json& e : j["errors"])
        reported |= e.get<std::string>().find("CRC") != std::string::npos;
    EXPECT_TRUE(reported) << j["errors"].dump();
    EXPECT_TRUE(fs::exists(damaged));
    fs::remove_all(dir);
}

TEST(DirectoryWatcher, MetricsJsonSaysTheRunHasEnded) {
    const fs::path dir = freshDir("dirstatus");
    MonitorState state;
    DirectoryWatcher watcher(dir, state);
    EXPECT_EQ(watcher.scanOnce(), 0);
    // While the backend writes the folder there is no metrics.json: the run is not over.
    EXPECT_TRUE(state.toJson()["source"]["run_status"].is_null());
    {
        std::ofstream(dir / "metrics.json")
            << R"({"format": "plumb-metrics-1", "status": "complete"})";
    }
    EXPECT_EQ(watcher.scanOnce(), 1);
    EXPECT_EQ(state.toJson()["source"]["run_status"], "complete");
    EXPECT_EQ(watcher.scanOnce(), 0);
    {
        std::ofstream(dir / "metrics.json")
            << R"({"status": "interrupted", "format": "plumb-metrics-1"})";
    }
    EXPECT_EQ(watcher.scanOnce(), 1);
    EXPECT_EQ(state.toJson()["source"]["run_status"], "interrupted");
    // A run started again in the folder removes it.
    fs::remove(dir / "metrics.json");
    EXPECT_EQ(watcher.scanOnce(), 1);
    EXPECT_TRUE(state.toJson()["source"]["run_status"].is_null());
    // A damaged one is reported, not taken for an ended run.
    { std::ofstream(dir / "metrics.json") << R"({"status": )"; }
    for (int i = 0; i < 3; ++i) watcher.scanOnce();
    const json j = state.toJson();
    EXPECT_TRUE(j["source"]["run_status"].is_null());
    ASSERT_FALSE(j["errors"].empty());
    EXPECT_NE(j["errors"].back().get<std::string>().find("metrics.json: invalid JSON"),
              std::string::npos);
    fs::remove_all(dir);
}

TEST(DirectoryWatcher, ThreadPicksUpNewFragments) {
    const fs::path dir = freshDir("dirthread");
    MonitorState state;
    DirectoryWatcherConfig config;
    config.poll_interval_s = 0.05;
    DirectoryWatcher watcher(dir, state, config);
    watcher.start();
    auto store = messages::FragmentStore::open(dir / "fragments");
    ASSERT_TRUE(store.isOk());
    auto bytes = messages::encodeFragment(testing::roomFragment(0));
    ASSERT_TRUE((*store)->put(1, 0, *bytes).isOk());
    for (int i = 0; i < 500 && state.numFragments() == 0; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    EXPECT_EQ(state.numFragments(), 1u);
    watcher.stop();
    fs::remove_all(dir);
}

}  // namespace
}  // namespace plumb::monitor
