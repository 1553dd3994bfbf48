// SPDX-License-Identifier: Apache-2.0
// Fragments from the real device pipeline (simulated living room, tracked and fused) through the
// device's publisher and the backend's ingest, in one process over an in-memory network that
// loses, duplicates and reorders messages: every fragment must arrive bit-identical, a backend
// restart must lose nothing, malformed and forged messages must be rejected and counted, and a
// recorded log must replay to the same store twice.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <lcm/lcm-cpp.hpp>
#include <limits>
#include <mutex>
#include <random>
#include <thread>

#include "backend/app/backend_cli.hpp"
#include "backend/ingest/ingest_run.hpp"
#include "backend/ingest/ingestor.hpp"
#include "backend/ingest/stored_scan.hpp"
#include "common/config/config.hpp"
#include "common/io/ply.hpp"
#include "device/fusion/fuse_frames.hpp"
#include "device/stream/device_config.hpp"
#include "device/stream/device_runner.hpp"
#include "device/stream/fragment_publisher.hpp"
#include "drivers/source.hpp"
#include "messages/auth.hpp"
#include "messages/channels.hpp"
#include "messages/conversions.hpp"
#include "messages/crc32.hpp"
#include "messages/files.hpp"
#include "messages/fragment_codec.hpp"
#include "messages/fragment_files.hpp"
#include "messages/fragment_store.hpp"
#include "messages/wire.hpp"
#include "tests/messages/lossy_transport.hpp"

namespace plumb::backend {
namespace {

namespace fs = std::filesystem;
using messages::testing::LossyConfig;
using messages::testing::LossyHub;

constexpr int64_t kSession = 4242;

/// The simulated living room at the ci intrinsics (160x120), its first `frames` frames.
std::unique_ptr<FrameSource> smallLivingRoom(size_t frames) {
    SourceOptions so;
    so.intrinsics = "ci";
    so.max_frames = frames;
    auto source = openFrameSource("sim:living_room", so);
    PLUMB_CHECK(source.isOk()) << source.status().toString();
    return std::move(source).value();
}

// 40 frames of the simulated living room at 160x120, 8 frames per fragment, encoded.
const std::vector<std::vector<uint8_t>>& deviceFragments() {
    static const std::vector<std::vector<uint8_t>> fragments = [] {
        std::unique_ptr<FrameSource> source = smallLivingRoom(40);
        device::FusionOptions fo;
        fo.frames_per_fragment = 8;
        fo.voxel_size_m = 0.02;
        device::FragmentBuilder builder(source->camera(), device::toFusionConfig(fo));
        std::vector<std::vector<uint8_t>> out;
        device::FuseHooks hooks;
        hooks.on_fragment = [&](Fragment f) {
            auto bytes = messages::encodeFragment(f);
            PLUMB_CHECK(bytes.isOk()) << bytes.status().toString();
            out.push_back(std::move(bytes).value());
            return Status::ok();
        };
        const Result<bool> fused = device::fuseFrames(*source, builder, hooks);
        PLUMB_CHECK(fused.isOk()) << fused.status().toString();
        return out;
    }();
    return fragments;
}

fs::path tempDir(const std::string& name) {
    const fs::path dir =
        fs::temp_directory_path() / ("plumb_stream_" + name + "_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

std::map<std::string, std::vector<uint8_t>> readDir(const fs::path& dir) {
    std::map<std::string, std::vector<uint8_t>> files;
    for (const auto& e : fs::directory_iterator(dir)) {
        if (!e.is_regular_file()) continue;
        auto bytes = messages::readFile(e.path(), int64_t{1} << 30);
        PLUMB_CHECK(bytes.isOk());
        files[e.path().filename().string()] = std::move(bytes).value();
    }
    return files;
}

// Device publisher and backend ingest on one lossy hub; time advances 50 ms per step.
struct Loop {
    Loop(LossyConfig net, fs::path store_dir, const std::vector<uint8_t>& key = {})
        : hub(net), store(std::move(store_dir)) {
        messages::AuthConfig dev_auth, back_auth;
        dev_auth.key = back_auth.key = key;
        dev_auth.sender_id = 1;
        back_auth.sender_id = 2;
        device_net = std::make_unique<messages::AuthenticatedTransport>(hub, dev_auth);
        backend_net = std::make_unique<messages::AuthenticatedTransport>(hub, back_auth);
        device::PublisherConfig pc;
        pc.session_id = kSession;
        pc.sender.chunk_payload_bytes = 8000;
        pc.max_in_flight = 3;
        auto p = device::FragmentPublisher::create(pc, *device_net);
        PLUMB_CHECK(p.isOk());
        publisher = std::move(p).value();
        for (const char* ch : {messages::kChannelFragmentAck, messages::kChannelRetransmit})
            (void)device_net->subscribe(ch,
                                        [this](const std::string& c, std::span<const uint8_t> b) {
                                            publisher->onMessage(c, b, now);
                                        });
        for (const std::string& ch : Ingestor::channels())
            (void)backend_net->subscribe(ch,
                                         [this](const std::string& c, std::span<const uint8_t> b) {
                                             if (recorder) recorder(c, b);
                                             if (ingestor) ingestor->onMessage(c, b, now);
                                         });
        startBackend();
    }

    void startBackend() {
        IngestConfig ic;
        auto in = Ingestor::open(store, {}, ic, *backend_net);
        PLUMB_CHECK(in.isOk()) << in.status().toString();
        ingestor = std::move(in).value();
    }

    void step() {
        hub.deliver();
        now += 0.05;
        publisher->poll(now);
        if (ingestor) ingestor->poll(now);
    }

    // Sends fragments [0, n) spread over time, one every `every` steps.
    void sendAll(const std::vector<std::vector<uint8_t>>& fragments, int every,
                 const std::function<void(size_t)>& after_submit = {}) {
        for (size_t i = 0; i < fragments.size(); ++i) {
            PLUMB_CHECK(publisher->submit(static_cast<uint32_t>(i), fragments[i], now).isOk());
            if (after_submit) after_submit(i);
            for (int s = 0; s < every; ++s) step();
        }
    }

    bool drain(int max_steps) {
        for (int i = 0; i < max_steps; ++i) {
            if (publisher->unacknowledged() == 0 && hub.idle()) return true;
            step();
        }
        return false;
    }

    void expectStoreMatches(const std::vector<std::vector<uint8_t>>& fragments) {
        auto files = readDir(store);
        ASSERT_EQ(files.size(), fragments.size());
        for (size_t i = 0; i < fragments.size(); ++i) {
            const auto name = messages::fragmentFileName(kSession, static_cast<uint32_t>(i));
            ASSERT_TRUE(files.count(name)) << name;
            EXPECT_TRUE(files[name] == fragments[i]) << "fragment " << i << " differs";
        }
    }

    LossyHub hub;
    fs::path store;
    std::unique_ptr<messages::AuthenticatedTransport> device_net, backend_net;
    std::unique_ptr<device::FragmentPublisher> publisher;
    std::unique_ptr<Ingestor> ingestor;
    std::function<void(const std::string&, std::span<const uint8_t>)> recorder;
    double now = 1000.0;
};

TEST(StreamingInProcess, DeviceFragmentsAreNonTrivial) {
    const auto& fragments = deviceFragments();
    ASSERT_EQ(fragments.size(), 5u);
    for (const auto& f : fragments) {
        auto decoded = messages::decodeFragment(f);
        ASSERT_TRUE(decoded.isOk());
        EXPECT_GT(decoded->points_F.size(), 1000u);
        EXPECT_GT(f.size(), 8000u);  // several chunks each
    }
}

TEST(StreamingInProcess, PerfectNetworkEveryFragmentBitIdentical) {
    Loop loop({}, tempDir("perfect"));
    loop.sendAll(deviceFragments(), 2);
    ASSERT_TRUE(loop.drain(2000));
    loop.expectStoreMatches(deviceFragments());
    const auto m = loop.ingestor->metrics(loop.backend_net->stats());
    EXPECT_EQ(m["fragments_received"], 5);
    EXPECT_EQ(m["chunks_lost"], 0);
    fs::remove_all(loop.store);
}

TEST(StreamingInProcess, LossDuplicationReorderStillBitIdentical) {
    Loop loop({.loss = 0.10, .duplicate = 0.10, .reorder = true, .seed = 11}, tempDir("lossy"));
    loop.sendAll(deviceFragments(), 2);
    ASSERT_TRUE(loop.drain(20000));
    loop.expectStoreMatches(deviceFragments());
    const auto m = loop.ingestor->metrics(loop.backend_net->stats());
    std::printf("lossy: dropped %zu of %zu messages, duplicated %zu; metrics %s\n",
                loop.hub.dropped(), loop.hub.published(), loop.hub.duplicated(), m.dump().c_str());
    EXPECT_GT(loop.hub.dropped(), 0u);
    EXPECT_GT(m["chunks_lost"].get<uint64_t>(), 0u);
    EXPECT_EQ(m["chunks_recovered"], m["chunks_lost"]);
    EXPECT_EQ(m["fragments_received"], 5);
    fs::remove_all(loop.store);
}

TEST(StreamingInProcess, BackendRestartMidScanLosesNothing) {
    Loop loop({.loss = 0.05, .duplicate = 0.05, .reorder = true, .seed = 5}, tempDir("restart"));
    loop.sendAll(deviceFragments(), 3, [&](size_t i) {
        if (i == 2) loop.ingestor.reset();  // the backend dies with fragment 2 on the wire
        if (i == 4) loop.startBackend();    // and comes back two fragments later
    });
    ASSERT_TRUE(loop.drain(20000));
    loop.expectStoreMatches(deviceFragments());
    EXPECT_GT(loop.ingestor->counters().fragments_resumed, 0u);
    EXPECT_EQ(
        loop.ingestor->counters().fragments_resumed + loop.ingestor->counters().fragments_received,
        5u);
    fs::remove_all(loop.store);
}

TEST(StreamingInProcess, MalformedAndForgedMessagesRejectedWithoutCrash) {
    const std::vector<uint8_t> key(32, 0x5a);
    Loop loop({}, tempDir("malformed"), key);
    const auto& fragments = deviceFragments();
    loop.sendAll(fragments, 2);
    ASSERT_TRUE(loop.drain(2000));
    // A second, legitimately keyed sender publishes garbage (it passes authentication, so the
    // decoders see it); an attacker without the key publishes unsigned and forged messages.
    messages::AuthConfig evil_auth;
    evil_auth.key = key;
    evil_auth.sender_id = 99;
    messages::AuthenticatedTransport keyed(loop.hub, evil_auth);
    std::mt19937 rng(7);
    plumb::fragment_chunk_t chunk;
    chunk.session_id = kSession;
    chunk.fragment_id = 100;
    chunk.chunk_index = 0;
    chunk.num_chunks = 1;
    chunk.chunk_bytes = 16;
    chunk.total_bytes = 16;
    chunk.data.assign(16, 7);
    chunk.size = 16;
    chunk.chunk_crc32 = static_cast<int32_t>(messages::crc32(chunk.data) ^ 1);  // bad CRC
    chunk.fragment_crc32 = 0;
    const auto bad_crc = messages::encodeMessage(chunk);
    auto truncated = bad_crc;
    truncated.resize(truncated.size() / 2);
    plumb::fragment_header_t header{};
    header.session_id = kSession;
    header.fragment_id = 101;
    header.num_chunks = 1 << 30;  // absurd
    header.chunk_bytes = 60000;
    header.total_bytes = int64_t{1} << 50;
    const auto absurd = messages::encodeMessage(header);
    plumb::device_status_t status{};
    const auto wrong_type = messages::encodeMessage(status);  // a status on the chunk channel
    std::vector<uint8_t> noise(300);
    for (auto& b : noise) b = static_cast<uint8_t>(rng());
    for (const auto& bytes : {bad_crc, truncated, absurd, wrong_type, noise}) {
        (void)keyed.publish(messages::kChannelFragmentChunk, bytes);
        (void)keyed.publish(messages::kChannelFragmentHeader, bytes);
        (void)keyed.publish(messages::kChannelStatus, bytes);
    }
    // Unsigned and forged (wrong key) copies of a valid chunk.
    (void)loop.hub.publish(messages::kChannelFragmentChunk, bad_crc);
    const std::vector<uint8_t> wrong_key(32, 0x11);
    (void)loop.hub.publish(
        messages::kChannelFragmentChunk,
        messages::sealMessage(messages::kChannelFragmentChunk, bad_crc, wrong_key, 1, 77, 1, 0));
    auto sealed = messages::sealMessage(messages::kChannelFragmentChunk, bad_crc, key, 1, 78, 1, 0);
    sealed[sealed.size() / 2] ^= 0x40;  // altered in transit
    (void)loop.hub.publish(messages::kChannelFragmentChunk, sealed);
    for (int i = 0; i < 5; ++i) loop.step();

    const auto m = loop.ingestor->metrics(loop.backend_net->stats());
    std::printf("rejections: %s\n", m["messages_rejected"].dump().c_str());
    const auto& r = m["messages_rejected"];
    EXPECT_GE(r["unsigned"].get<uint64_t>(), 1u);
    EXPECT_GE(r["forged"].get<uint64_t>(), 2u);  // wrong key and altered
    EXPECT_GE(r["chunk_crc"].get<uint64_t>(), 1u);
    EXPECT_GE(r["malformed"].get<uint64_t>(), 10u);
    loop.expectStoreMatches(fragments);  // nothing changed, nothing added
    fs::remove_all(loop.store);
}

TEST(StreamingInProcess, RecordedLogReplaysToTheSameStoreTwice) {
    const fs::path dir = tempDir("log");
    const fs::path log_path = dir / "session.lcmlog";
    {
        lcm::LogFile log(log_path.string(), "w");
        ASSERT_TRUE(log.good());
        Loop loop({.loss = 0.10, .duplicate = 0.05, .reorder = true, .seed = 21}, dir / "live");
        int64_t n = 0;
        loop.recorder = [&](const std::string& channel, std::span<const uint8_t> bytes) {
            // What a logger on the backend's host sees (the inner, unsealed message here).
            lcm::LogEvent e;
            e.eventnum = n++;
            e.timestamp = static_cast<int64_t>(loop.now * 1e6);
            e.channel = channel;
            e.datalen = static_cast<int32_t>(bytes.size());
            e.data = const_cast<uint8_t*>(bytes.data());
            ASSERT_EQ(log.writeEvent(&e), 0);
        };
        loop.sendAll(deviceFragments(), 2);
        ASSERT_TRUE(loop.drain(20000));
    }
    IngestRunOptions a, b;
    a.fragments_dir = dir / "replay_a" / "fragments";
    a.out_dir = dir / "replay_a";
    b.fragments_dir = dir / "replay_b" / "fragments";
    b.out_dir = dir / "replay_b";
    auto ra = runLogIngest(log_path, a, {});
    auto rb = runLogIngest(log_path, b, {});
    ASSERT_TRUE(ra.isOk()) << ra.status().toString();
    ASSERT_TRUE(rb.isOk()) << rb.status().toString();
    EXPECT_TRUE(ra->log_damage.isOk()) << ra->log_damage.toString();  // an intact log
    const auto fa = readDir(a.fragments_dir), fb = readDir(b.fragments_dir);
    EXPECT_EQ(fa.size(), 5u);
    EXPECT_TRUE(fa == fb);
    EXPECT_TRUE(readDir(a.out_dir)["metrics.json"] == readDir(b.out_dir)["metrics.json"]);
    EXPECT_TRUE(fa == readDir(dir / "live"));  // the same store the live backend built
    fs::remove_all(dir);
}

// Issue 32, item 4: a store with fragments of two sessions reconstructs one of them, says which
// and names the other instead of ignoring it without a word.
TEST(StreamingInProcess, ChoosingASessionNamesTheOthers) {
    const fs::path dir = tempDir("sessions");
    auto store = messages::FragmentStore::open(dir);
    ASSERT_TRUE(store.isOk());
    const auto& fragments = deviceFragments();
    for (uint32_t i = 0; i < 3; ++i) ASSERT_TRUE((*store)->put(111, i, fragments[i]).isOk());
    ASSERT_TRUE((*store)->put(222, 0, fragments[3]).isOk());
    std::string note;
    auto newest = chooseSession(**store, {}, &note);
    ASSERT_TRUE(newest.isOk());
    EXPECT_EQ(*newest, 222);
    EXPECT_NE(note.find("holds 2 sessions; reconstructing session 222 (1 fragment(s), the "
                        "newest) and not 111 (3 fragment(s))"),
              std::string::npos)
        << note;
    auto named = chooseSession(**store, {111}, &note);
    ASSERT_TRUE(named.isOk());
    EXPECT_EQ(*named, 111);
    EXPECT_NE(note.find("named by --session) and not 222 (1 fragment(s))"), std::string::npos)
        << note;
    auto loaded = loadStoredFragments(**store, *named);
    ASSERT_TRUE(loaded.isOk());
    EXPECT_EQ(loaded->size(), 3u);
    EXPECT_EQ(chooseSession(**store, {333}, &note).status().code(), StatusCode::kNotFound);
    fs::remove_all(dir);
}

// `plumb reconstruct store:DIR` reads a store a live backend may be writing: opened read-only,
// the store is indexed and left as it is (a write in progress stays, a damaged file stays where
// it is), and nothing can be put.
TEST(StreamingInProcess, AStoreOpenedReadOnlyIsLeftAsItIs) {
    const fs::path dir = tempDir("read_only");
    {
        auto store = messages::FragmentStore::open(dir);
        ASSERT_TRUE(store.isOk());
        for (uint32_t i = 0; i < 2; ++i)
            ASSERT_TRUE((*store)->put(111, i, deviceFragments()[i]).isOk());
    }
    const fs::path in_progress = dir / (messages::fragmentFileName(111, 2) + messages::kTempSuffix);
    std::ofstream(in_progress) << "half a fragment";
    const fs::path damaged = dir / messages::fragmentFileName(111, 3);
    std::vector<uint8_t> bytes = deviceFragments()[3];
    bytes[bytes.size() / 2] ^= 0x5a;
    std::ofstream(damaged, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));

    auto reader = messages::FragmentStore::openReadOnly(dir);
    ASSERT_TRUE(reader.isOk()) << reader.status().toString();
    EXPECT_EQ((*reader)->fragments().size(), 2u);
    ASSERT_EQ((*reader)->quarantined().size(), 1u);
    EXPECT_EQ((*reader)->quarantined()[0], damaged);
    EXPECT_TRUE(fs::exists(in_progress));
    EXPECT_TRUE(fs::exists(damaged));
    EXPECT_EQ((*reader)->put(111, 4, deviceFragments()[4]).status().code(),
              StatusCode::kFailedPrecondition);
    EXPECT_FALSE((*reader)->contains(111, 4));
    EXPECT_EQ(messages::FragmentStore::openReadOnly(dir / "nowhere").status().code(),
              StatusCode::kNotFound);
    EXPECT_FALSE(fs::exists(dir / "nowhere"));

    // The owner's open() clears the interrupted write and moves the damaged file aside.
    auto owner = messages::FragmentStore::open(dir);
    ASSERT_TRUE(owner.isOk());
    EXPECT_FALSE(fs::exists(in_progress));
    EXPECT_FALSE(fs::exists(damaged));
    EXPECT_TRUE(fs::exists(fs::path(damaged.string() + ".corrupt")));
    fs::remove_all(dir);
}

/// A camera that vanishes after `unplug_at` frames for `outage_calls` calls of next() (each
/// waiting `outage_wait` as a driver's read timeout would), then streams on.
class UnpluggingSource final : public FrameSource {
  public:
    UnpluggingSource(std::unique_ptr<FrameSource> inner, int64_t unplug_at, int outage_calls,
                     std::chrono::milliseconds outage_wait)
        : inner_(std::move(inner)),
          unplug_at_(unplug_at),
          outage_left_(outage_calls),
          outage_wait_(outage_wait) {}

    const PinholeCamera& camera() const override { return inner_->camera(); }
    std::string description() const override { return "unplugging " + inner_->description(); }
    /// Known length: capture waits for fusion instead of dropping frames like a live sensor.
    std::optional<size_t> size() const override { return inner_->size(); }
    Result<Frame> next() override {
        if (delivered_ == unplug_at_ && outage_left_ > 0) {
            --outage_left_;
            std::this_thread::sleep_for(outage_wait_);
            return Status(StatusCode::kUnavailable, "camera disconnected");
        }
        Result<Frame> f = inner_->next();
        if (f.isOk()) ++delivered_;
        return f;
    }

  private:
    std::unique_ptr<FrameSource> inner_;
    int64_t unplug_at_;
    int outage_left_;
    std::chrono::milliseconds outage_wait_;
    int64_t delivered_ = 0;
};

/// Keeps every message the device publishes; nothing is ever delivered back (no backend).
class RecordingTransport final : public messages::Transport {
  public:
    Status publish(const std::string& channel, std::span<const uint8_t> bytes) override {
        std::lock_guard<std::mutex> lock(mutex);
        sent.emplace_back(channel, std::vector<uint8_t>(bytes.begin(), bytes.end()));
        return Status::ok();
    }
    Status subscribe(const std::string&, Handler) override { return Status::ok(); }

    std::mutex mutex;
    std::vector<std::pair<std::string, std::vector<uint8_t>>> sent;
};

/// The device's options of these tests: fragments of 8 frames at 2 cm voxels, a short wait for
/// acknowledgements that never come, and `session`.
device::DeviceRunOptions testDeviceOptions(int64_t session) {
    device::DeviceRunOptions options;
    options.config.fusion.frames_per_fragment = 8;
    options.config.fusion.voxel_size_m = 0.02;
    options.config.stream.ack_wait_s = 0.1;
    options.session_id = session;
    return options;
}

/// Runs the device over `source` with every message it publishes kept in `transport`.
Result<device::DeviceRunReport> runRecordedDevice(FrameSource& source,
                                                  const device::DeviceRunOptions& options,
                                                  RecordingTransport& transport) {
    device::DeviceLink link;
    link.transport = &transport;
    link.pump = [](int timeout_ms) {
        std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
        return Status::ok();
    };
    const std::atomic<int> stop{0};
    return device::runDevice(source, options, link, stop);
}

TEST(StreamingInProcess, UnpluggedCameraIsInTheHeartbeatAndTheScanResumes) {
    UnpluggingSource source(smallLivingRoom(24), 10, 30, std::chrono::milliseconds(20));

    device::DeviceRunOptions options = testDeviceOptions(77);
    options.config.stream.status_period_s = 0.05;
    RecordingTransport transport;
    Result<device::DeviceRunReport> report = runRecordedDevice(source, options, transport);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    EXPECT_EQ(report->frames_captured, 24);  // every frame, the ones after the outage too
    EXPECT_EQ(report->frames_processed, 24);
    EXPECT_FALSE(report->source_error) << report->source_message;
    // Fragments: frames 0-7, 8-9 (closed at the unplug), then 10-17 and 18-23 after it.
    EXPECT_EQ(report->fragments_cut, 4);

    std::vector<messages::TrackingState> states;
    for (const auto& [channel, bytes] : transport.sent) {
        if (channel != messages::kChannelStatus) continue;
        auto msg = messages::decodeMessage<plumb::device_status_t>(bytes);
        ASSERT_TRUE(msg.isOk()) << msg.status().toString();
        auto status = messages::fromMessage(*msg);
        ASSERT_TRUE(status.isOk()) << status.status().toString();
        if (states.empty() || states.back() != status->tracking) states.push_back(status->tracking);
    }
    // The heartbeat says the camera is gone during the outage (30 x 20 ms = 0.6 s, heartbeat
    // every 50 ms), then tracking again, and finally stopped.
    const auto gone = std::find(states.begin(), states.end(), messages::TrackingState::kNoCamera);
    ASSERT_NE(gone, states.end());
    EXPECT_NE(std::find(gone, states.end(), messages::TrackingState::kOk), states.end());
    ASSERT_FALSE(states.empty());
    EXPECT_EQ(states.back(), messages::TrackingState::kStopped);
}

/// Gives every frame of another source a colour image, as an RGB-D camera would: pixel (u, v) of
/// frame k is {u + k, v, 200}.
class ColourCamera final : public FrameSourceDecorator {
  public:
    using FrameSourceDecorator::FrameSourceDecorator;
    Result<Frame> next() override {
        auto frame = inner().next();
        if (!frame.isOk()) return frame;
        frame->colour = ColourImage(frame->depth.width(), frame->depth.height());
        for (int v = 0; v < frame->colour.height(); ++v) {
            for (int u = 0; u < frame->colour.width(); ++u) {
                frame->colour(u, v) =
                    Rgb8{static_cast<uint8_t>(u + frame->index), static_cast<uint8_t>(v), 200};
            }
        }
        return frame;
    }
};

/// The first `n` frames of ColourCamera over the small living room, as a device captures them.
std::vector<Frame> colourCameraFrames(size_t n) {
    std::vector<Frame> frames;
    ColourCamera camera(smallLivingRoom(n));
    for (auto f = camera.next(); f.isOk(); f = camera.next()) frames.push_back(*f);
    return frames;
}

TEST(StreamingInProcess, RawFramesCarryColourToTheIngest) {
    // The frames as the camera delivers them, for comparison.
    const std::vector<Frame> expected = colourCameraFrames(16);
    ASSERT_EQ(expected.size(), 16u);
    ColourCamera source(smallLivingRoom(16));

    device::DeviceRunOptions options = testDeviceOptions(78);
    options.config.stream.raw_frame_every = 5;  // frames 0, 5, 10, 15
    RecordingTransport transport;
    auto report = runRecordedDevice(source, options, transport);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    EXPECT_EQ(report->raw_frames_published, 4);
    EXPECT_EQ(report->raw_frames_dropped, 0);  // a recorded source waits for the network thread

    // Each raw frame is the captured frame: depth to the millimetre, colour exactly, with the
    // device's session.
    std::vector<int64_t> indices;
    for (const auto& [channel, bytes] : transport.sent) {
        EXPECT_NE(channel, messages::kChannelRgbd);  // the older message is no longer sent
        if (channel != messages::kChannelRgbdSession) continue;
        auto raw = messages::decodeRawFrame(bytes);
        ASSERT_TRUE(raw.isOk()) << raw.status().toString();
        EXPECT_EQ(raw->session_id, 78);
        ASSERT_LT(raw->frame_index, 16);
        const Frame& original = expected[static_cast<size_t>(raw->frame_index)];
        indices.push_back(raw->frame_index);
        EXPECT_EQ(raw->colour, original.colour) << raw->frame_index;
        EXPECT_EQ(raw->depth, toRaw(original.depth, 1000.0)) << raw->frame_index;
        EXPECT_EQ(raw->utime, messages::toUtime(original.timestamp_s));
    }
    EXPECT_EQ(indices, (std::vector<int64_t>{0, 5, 10, 15}));

    // The backend's ingest (plumb-backend --live/--log, plumb replay) decodes and counts them,
    // and the raw frames of older devices too (depth_frame2_t without a session, depth-only
    // depth_frame_t); a damaged one is counted as malformed.
    const fs::path dir = tempDir("raw_frames");
    LossyHub hub;
    IngestConfig ic;
    auto ingestor = Ingestor::open(dir / "fragments", {}, ic, hub);
    ASSERT_TRUE(ingestor.isOk()) << ingestor.status().toString();
    for (const auto& [channel, bytes] : transport.sent) (*ingestor)->onMessage(channel, bytes, 1.0);
    messages::RawDepthFrame legacy;
    legacy.frame_index = 99;
    legacy.depth = toRaw(expected[3].depth, 1000.0);
    (*ingestor)->onMessage(
        messages::kChannelDepth,
        messages::encodeMessage(
            messages::toMessage(legacy, messages::DepthEncoding::kDeltaVarint, 1).value()),
        2.0);
    ASSERT_TRUE((*ingestor)->lastRawFrame().has_value());
    EXPECT_EQ((*ingestor)->lastRawFrame()->frame_index, 99);
    EXPECT_TRUE((*ingestor)->lastRawFrame()->colour.empty());
    messages::RawRgbdFrame older;
    older.utime = 5000000;
    older.frame_index = 98;
    older.depth = toRaw(expected[4].depth, 1000.0);
    older.colour = expected[4].colour;
    (*ingestor)->onMessage(
        messages::kChannelRgbd,
        messages::encodeMessage(messages::toMessage(older, messages::DepthEncoding::kDeltaVarint,
                                                    messages::ColourEncoding::kDeltaRice, 1)
                                    .value()),
        2.0);
    EXPECT_FALSE((*ingestor)->lastRawFrame()->session_id.has_value());
    auto damaged = transport.sent.front().second;
    for (const auto& [channel, bytes] : transport.sent) {
        if (channel == messages::kChannelRgbdSession) damaged = bytes;
    }
    damaged.resize(damaged.size() - 10);
    (*ingestor)->onMessage(messages::kChannelRgbdSession, damaged, 3.0);
    const auto m = (*ingestor)->metrics({});
    EXPECT_EQ(m["raw_frames"]["received"], 6);
    EXPECT_EQ(m["raw_frames"]["with_colour"], 5);
    EXPECT_EQ((*ingestor)->counters().raw_frames_malformed, 1u);
    EXPECT_GE(m["messages_rejected"]["malformed"].get<uint64_t>(), 1u);
    // Every frame that decoded is kept for the final model, the older ones too; the device's
    // with its session, the older ones without.
    EXPECT_EQ(m["raw_frames"]["kept"], 6);
    EXPECT_EQ(m["raw_frames"]["not_kept"], 0);
    auto kept = listRawFrames(rawFramesDir(dir / "fragments"));
    ASSERT_TRUE(kept.isOk()) << kept.status().toString();
    ASSERT_EQ(kept->size(), 6u);
    for (const StoredRawFrame& f : *kept) {
        if (f.frame_index >= 98)
            EXPECT_FALSE(f.session_id.has_value()) << f.frame_index;
        else
            EXPECT_EQ(f.session_id, 78) << f.frame_index;
    }
    EXPECT_EQ(std::count_if(kept->begin(), kept->end(),
                            [](const StoredRawFrame& f) { return f.frame_index == 99; }),
              1);
    fs::remove_all(dir);
}

TEST(StreamingInProcess, RawFramesOfTheOlderTypeServeBackendsBeforeTheSession) {
    const std::vector<Frame> expected = colourCameraFrames(8);
    ASSERT_EQ(expected.size(), 8u);
    ColourCamera source(smallLivingRoom(8));
    device::DeviceRunOptions options = testDeviceOptions(81);
    options.config.stream.raw_frame_every = 3;  // frames 0, 3, 6
    options.config.stream.raw_frame_type = 2;
    RecordingTransport transport;
    auto report = runRecordedDevice(source, options, transport);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    EXPECT_EQ(report->raw_frames_published, 3);

    // Only depth_frame2_t on PLUMB_RGBD, which a backend before depth_frame3_t subscribes to:
    // the same depth and colour, no session.
    std::vector<int64_t> indices;
    for (const auto& [channel, bytes] : transport.sent) {
        EXPECT_NE(channel, messages::kChannelRgbdSession);
        if (channel != messages::kChannelRgbd) continue;
        plumb::depth_frame2_t msg;
        ASSERT_GT(msg.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
        auto raw = messages::fromMessage(msg);
        ASSERT_TRUE(raw.isOk()) << raw.status().toString();
        EXPECT_FALSE(raw->session_id.has_value());
        ASSERT_LT(raw->frame_index, 8);
        const Frame& original = expected[static_cast<size_t>(raw->frame_index)];
        EXPECT_EQ(raw->colour, original.colour) << raw->frame_index;
        EXPECT_EQ(raw->depth, toRaw(original.depth, 1000.0)) << raw->frame_index;
        indices.push_back(raw->frame_index);
    }
    EXPECT_EQ(indices, (std::vector<int64_t>{0, 3, 6}));

    // This release's ingest keeps them too, without a session.
    const fs::path dir = tempDir("raw_frames_type2");
    LossyHub hub;
    auto ingestor = Ingestor::open(dir / "fragments", {}, IngestConfig{}, hub);
    ASSERT_TRUE(ingestor.isOk()) << ingestor.status().toString();
    for (const auto& [channel, bytes] : transport.sent) (*ingestor)->onMessage(channel, bytes, 1.0);
    auto kept = listRawFrames(rawFramesDir(dir / "fragments"));
    ASSERT_TRUE(kept.isOk()) << kept.status().toString();
    ASSERT_EQ(kept->size(), 3u);
    for (const StoredRawFrame& f : *kept) EXPECT_FALSE(f.session_id.has_value());

    // Any other type is refused by the configuration.
    for (int type : {1, 4}) {
        device::DeviceConfig config;
        config.stream.raw_frame_type = type;
        EXPECT_FALSE(config::validate(config).isOk()) << type;
    }
    fs::remove_all(dir);
}

/// The messages a device publishes for the first `frames` frames of the simulated living room
/// (ci intrinsics) with every raw frame, as session `session`.
std::vector<std::pair<std::string, std::vector<uint8_t>>> deviceMessagesWithRawFrames(
    size_t frames, int64_t session) {
    std::unique_ptr<FrameSource> sim = smallLivingRoom(frames);
    device::DeviceRunOptions options = testDeviceOptions(session);
    options.config.stream.raw_frame_every = 1;
    RecordingTransport transport;
    auto report = runRecordedDevice(*sim, options, transport);
    PLUMB_CHECK(report.isOk()) << report.status().toString();
    PLUMB_CHECK(report->raw_frames_published == static_cast<int64_t>(frames));
    return std::move(transport.sent);
}

/// Ingests `sent` (a device's messages) into the store `store` (the camera info into `info_dir`
/// when given) and returns the ingest's metrics.
nlohmann::json ingestInto(const fs::path& store, const IngestConfig& config,
                          const std::vector<std::pair<std::string, std::vector<uint8_t>>>& sent,
                          const fs::path& info_dir = {}) {
    LossyHub hub;
    auto ingestor = Ingestor::open(store, info_dir, config, hub);
    EXPECT_TRUE(ingestor.isOk()) << ingestor.status().toString();
    if (!ingestor.isOk()) return {};
    for (const auto& [channel, bytes] : sent) (*ingestor)->onMessage(channel, bytes, 1.0);
    (*ingestor)->poll(2.0);
    return (*ingestor)->metrics({});
}

// Raw frames that cannot be written (here the raw frame folder's name is taken by a file) are
// counted and left out, once warned about; the fragments are stored and acknowledged as ever.
TEST(StreamingInProcess, RawFramesThatCannotBeKeptAreCountedAndTheFragmentsStillStored) {
    const auto sent = deviceMessagesWithRawFrames(16, 81);

    const fs::path dir = tempDir("raw_not_kept");
    const fs::path store = dir / "fragments";
    fs::create_directories(store);
    std::ofstream(rawFramesDir(store)) << "in the way\n";
    const nlohmann::json m = ingestInto(store, IngestConfig{}, sent);
    EXPECT_EQ(m["fragments_received"], 2);
    EXPECT_EQ(m["raw_frames"]["received"], 16);
    EXPECT_EQ(m["raw_frames"]["kept"], 0);
    EXPECT_EQ(m["raw_frames"]["not_kept"], 16);
    EXPECT_EQ(m["fragments_received"], 2);
    fs::remove_all(dir);
}

// Short of free space (here: asked for more than any disk has), raw frames are not kept, and the
// fragments, which are acknowledged, are stored as ever; with room they are kept.
TEST(StreamingInProcess, RawFramesLeaveTheDiskToTheFragmentsWhenSpaceIsShort) {
    const auto sent = deviceMessagesWithRawFrames(16, 82);
    const fs::path dir = tempDir("raw_no_space");
    for (const bool short_of_space : {true, false}) {
        const fs::path store = dir / (short_of_space ? "short" : "room");
        IngestConfig config;
        config.raw_frames_min_free_bytes =
            short_of_space ? std::numeric_limits<uint64_t>::max() : 0;
        const nlohmann::json m = ingestInto(store, config, sent);
        EXPECT_EQ(m["fragments_received"], 2);
        EXPECT_EQ(m["raw_frames"]["received"], 16);
        EXPECT_EQ(m["raw_frames"]["kept"], short_of_space ? 0 : 16);
        EXPECT_EQ(m["raw_frames"]["not_kept"], short_of_space ? 16 : 0);
        EXPECT_EQ(m["raw_frames"]["not_kept_disk"], short_of_space ? 16 : 0);
        auto kept = listRawFrames(rawFramesDir(store));
        ASSERT_TRUE(kept.isOk());
        EXPECT_EQ(kept->size(), short_of_space ? 0u : 16u);
    }
    fs::remove_all(dir);
}

std::string readText(const fs::path& p) {
    std::ifstream in(p);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// A store whose raw frames cannot be tracked again as well as the device tracked them says why
// when opened as a scan: one frame in two, without colour.
TEST(StreamingInProcess, AStoredScanSaysWhenItsFramesAreStridedOrWithoutColour) {
    const auto sent = deviceMessagesWithRawFrames(16, 85);
    const fs::path dir = tempDir("raw_strided");
    const fs::path store = dir / "fragments";
    EXPECT_EQ(ingestInto(store, IngestConfig{}, sent, dir)["raw_frames"]["kept"], 16);
    auto every = openStoredScan(store, {});
    ASSERT_TRUE(every.isOk()) << every.status().toString();
    EXPECT_TRUE(every->note.empty()) << every->note;

    auto rewrite = RawFrameStore::open(rawFramesDir(store));
    ASSERT_TRUE(rewrite.isOk());
    auto kept = listRawFrames(rawFramesDir(store));
    ASSERT_TRUE(kept.isOk());
    for (const StoredRawFrame& f : *kept) {
        if (f.frame_index % 2 == 1) {
            fs::remove(f.path);
            continue;
        }
        auto raw = messages::decodeRawFrame(messages::readFile(f.path, 1 << 24).value()).value();
        auto depth_only = messages::toSessionMessage(raw, 85, messages::DepthEncoding::kDeltaVarint,
                                                     messages::ColourEncoding::kNone, 1);
        ASSERT_TRUE((*rewrite)
                        ->put(f.utime, f.frame_index, messages::encodeMessage(*depth_only), 85)
                        .isOk());
    }
    auto strided = openStoredScan(store, {});
    ASSERT_TRUE(strided.isOk()) << strided.status().toString();
    EXPECT_EQ(strided->frames, 8u);
    EXPECT_NE(strided->note.find("one frame in 2 (stream.raw_frame_every = 2)"), std::string::npos)
        << strided->note;
    EXPECT_NE(strided->note.find("the raw frames carry no colour"), std::string::npos)
        << strided->note;
    // Asked for without colour, the frames' lack of it is no news.
    StoredScanOptions no_colour;
    no_colour.colour = false;
    auto depth_only = openStoredScan(store, no_colour);
    ASSERT_TRUE(depth_only.isOk());
    EXPECT_EQ(depth_only->note.find("carry no colour"), std::string::npos) << depth_only->note;
    fs::remove_all(dir);
}

TEST(StreamingInProcess, TheFinalModelReintegratesTheRawFramesTheIngestKept) {
    const auto sent = deviceMessagesWithRawFrames(24, 79);

    // plumb-backend's ingest: fragments into the store, raw frames beside it, the camera info
    // beside both (where the reconstruction of the store looks for it).
    const fs::path dir = tempDir("raw_final");
    const fs::path store = dir / "fragments";
    {
        const nlohmann::json m = ingestInto(store, IngestConfig{}, sent, dir);
        EXPECT_EQ(m["fragments_received"], 3);
        EXPECT_EQ(m["raw_frames"]["kept"], 24);
        auto reader = messages::FragmentStore::openReadOnly(store);
        ASSERT_TRUE(reader.isOk());
        auto fragments = loadStoredFragments(**reader);
        ASSERT_TRUE(fragments.isOk()) << fragments.status().toString();
        auto kept = listRawFrames(rawFramesDir(store));
        ASSERT_TRUE(kept.isOk());
        const RawFrameCoverage coverage = rawFrameCoverage(*kept, *fragments);
        EXPECT_EQ(coverage.tracked_frames, 24u);
        EXPECT_EQ(coverage.matched, 24u);
        EXPECT_EQ(coverage.min_fragment_share, 1.0);
    }
    ASSERT_TRUE(fs::exists(dir / "camera_info.json"));

    // The session's raw frames open as a scan (`plumb reconstruct store:DIR`): the frames the
    // camera delivered, depth to the millimetre, numbered in capture order. Raw frames of other
    // sessions stay out: one whose frames name it, at the same capture times and indices (two
    // runs of the simulator, whose clock starts at 0), with other depth; and one of an older
    // device, whose frames name no session, an hour later.
    {
        auto other = RawFrameStore::open(rawFramesDir(store));
        ASSERT_TRUE(other.isOk());
        for (const auto& [channel, bytes] : sent) {
            if (channel != messages::kChannelRgbdSession) continue;
            auto raw = messages::decodeRawFrame(bytes).value();
            messages::RawRgbdFrame same_time = raw;
            for (size_t k = 0; k < same_time.depth.size(); ++k) {
                uint16_t& d = same_time.depth.data()[k];
                if (d != 0) d = static_cast<uint16_t>(d + 100);
            }
            auto twin =
                messages::toSessionMessage(same_time, 77, messages::DepthEncoding::kDeltaVarint,
                                           messages::ColourEncoding::kDeltaRice, 1);
            ASSERT_TRUE(twin.isOk());
            ASSERT_TRUE((*other)
                            ->put(raw.utime, raw.frame_index, messages::encodeMessage(*twin), 77)
                            .isOk());
            raw.utime += int64_t{3600} * 1000000;
            auto later = messages::toMessage(raw, messages::DepthEncoding::kDeltaVarint,
                                             messages::ColourEncoding::kDeltaRice, 1);
            ASSERT_TRUE(later.isOk());
            ASSERT_TRUE(
                (*other)->put(raw.utime, raw.frame_index, messages::encodeMessage(*later)).isOk());
        }
        auto scan = openStoredScan(store, {});
        ASSERT_TRUE(scan.isOk()) << scan.status().toString();
        EXPECT_EQ(scan->session, 79);
        EXPECT_EQ(scan->frames, 24u);
        EXPECT_EQ(scan->fragment_frames_with_raw, 24u);
        EXPECT_TRUE(scan->note.empty()) << scan->note;
        std::unique_ptr<FrameSource> again = smallLivingRoom(24);
        int64_t k = 0;
        for (auto frame = scan->source->next(); frame.isOk(); frame = scan->source->next(), ++k) {
            auto expected = again->next();
            ASSERT_TRUE(expected.isOk());
            EXPECT_EQ(frame->index, k);
            EXPECT_EQ(toRaw(frame->depth, 1000.0), toRaw(expected->depth, 1000.0)) << k;
            EXPECT_EQ(frame->colour, expected->colour) << k;
        }
        EXPECT_EQ(k, 24);
        StoredScanOptions first_ten;
        first_ten.max_frames = 10;
        first_ten.colour = false;
        auto ten = openStoredScan(store, first_ten);
        ASSERT_TRUE(ten.isOk());
        EXPECT_EQ(ten->frames, 10u);
        auto frame = ten->source->next();
        ASSERT_TRUE(frame.isOk());
        EXPECT_TRUE(frame->colour.empty());
        // Raw frames of this session only: the later copies are no session's in the store.
        StoredScanOptions wrong_session;
        wrong_session.session = 80;
        EXPECT_EQ(openStoredScan(store, wrong_session).status().code(), StatusCode::kNotFound);
        EXPECT_EQ(openStoredScan(dir / "nowhere", {}).status().code(), StatusCode::kNotFound);
        auto all = listRawFrames(rawFramesDir(store));
        ASSERT_TRUE(all.isOk());
        EXPECT_EQ(all->size(), 3u * 24u);  // no session's frames replaced another's
        auto reader = messages::FragmentStore::openReadOnly(store);
        ASSERT_TRUE(reader.isOk());
        auto fragments = loadStoredFragments(**reader, 79);
        ASSERT_TRUE(fragments.isOk());
        const RawFrameCoverage own = rawFrameCoverage(*all, *fragments, 79);
        EXPECT_EQ(own.matched, 24u);
        // Session 77's frames come first at each instant (capture order breaks ties by session).
        for (const StoredRawFrame& f : own.frames) EXPECT_EQ(f.session_id, 79);
        for (const StoredRawFrame& f : *all) {
            if (f.utime > int64_t{3000} * 1000000 || f.session_id == 77) fs::remove(f.path);
        }
    }

    // Reconstructing the store re-integrates the raw frames ...
    ASSERT_EQ(runBackendCommand({"--fragments", store.string(), "--out", (dir / "raw").string()},
                                "plumb-backend"),
              0);
    auto metrics = nlohmann::json::parse(readText(dir / "raw" / "metrics.json"));
    EXPECT_EQ(metrics["final_model"], "raw frames re-integrated");
    // ... unless told not to; a reserve that is not a size is a usage error.
    ASSERT_EQ(runBackendCommand({"--fragments", store.string(), "--out", (dir / "no_raw").string(),
                                 "--no-raw-frames"},
                                "plumb-backend"),
              0);
    EXPECT_EQ(nlohmann::json::parse(readText(dir / "no_raw" / "metrics.json"))["final_model"],
              "fragment surfaces fused");
    for (const char* bad : {"-1", "lots", "nan"}) {
        EXPECT_EQ(runBackendCommand({"--fragments", store.string(), "--out", (dir / "bad").string(),
                                     "--raw-frames-reserve", bad},
                                    "plumb-backend"),
                  2)
            << bad;
    }

    // ... but not when a fragment has too few of its frames among them: frames 8-14 of the
    // second fragment (8-15) are gone, 1 of its 8 is left, under the default share of 20 %.
    auto stored = listRawFrames(rawFramesDir(store));
    ASSERT_TRUE(stored.isOk());
    for (const StoredRawFrame& f : *stored) {
        if (f.frame_index >= 8 && f.frame_index <= 14) fs::remove(f.path);
    }
    ASSERT_EQ(runBackendCommand({"--fragments", store.string(), "--out", (dir / "surf").string()},
                                "plumb-backend"),
              0);
    metrics = nlohmann::json::parse(readText(dir / "surf" / "metrics.json"));
    EXPECT_EQ(metrics["final_model"], "fragment surfaces fused");
    // Allowing one frame in eight, the rest of the raw frames are re-integrated.
    ASSERT_EQ(runBackendCommand({"--fragments", store.string(), "--out", (dir / "eighth").string(),
                                 "--set", "final_model.min_raw_frame_share=0.125"},
                                "plumb-backend"),
              0);
    metrics = nlohmann::json::parse(readText(dir / "eighth" / "metrics.json"));
    EXPECT_EQ(metrics["final_model"], "raw frames re-integrated");
    auto coloured = io::readTriangleMesh(dir / "eighth" / "mesh.ply");
    ASSERT_TRUE(coloured.isOk()) << coloured.status().toString();
    ASSERT_FALSE(coloured->colors.empty());

    // Depth-only raw frames (stream.raw_frame_colour = false) are re-integrated all the same,
    // and the mesh takes the colour of the fragments' points.
    {
        auto rewrite = RawFrameStore::open(rawFramesDir(store));
        ASSERT_TRUE(rewrite.isOk());
        auto kept = listRawFrames(rawFramesDir(store));
        ASSERT_TRUE(kept.isOk());
        for (const StoredRawFrame& f : *kept) {
            std::ifstream in(f.path, std::ios::binary);
            const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                             std::istreambuf_iterator<char>());
            auto raw = messages::decodeRawFrame(bytes);
            ASSERT_TRUE(raw.isOk()) << raw.status().toString();
            ASSERT_EQ(f.session_id, 79);
            auto depth_only =
                messages::toSessionMessage(*raw, 79, messages::DepthEncoding::kDeltaVarint,
                                           messages::ColourEncoding::kNone, 1);
            ASSERT_TRUE(depth_only.isOk());
            ASSERT_TRUE((*rewrite)
                            ->put(f.utime, f.frame_index, messages::encodeMessage(*depth_only), 79)
                            .isOk());
        }
    }
    ASSERT_EQ(runBackendCommand({"--fragments", store.string(), "--out", (dir / "depth").string(),
                                 "--set", "final_model.min_raw_frame_share=0.125"},
                                "plumb-backend"),
              0);
    metrics = nlohmann::json::parse(readText(dir / "depth" / "metrics.json"));
    EXPECT_EQ(metrics["final_model"],
              "raw frames re-integrated, coloured from the fragment points");
    auto from_points = io::readTriangleMesh(dir / "depth" / "mesh.ply");
    ASSERT_TRUE(from_points.isOk()) << from_points.status().toString();
    EXPECT_EQ(from_points->vertices, coloured->vertices);
    ASSERT_EQ(from_points->colors.size(), from_points->vertices.size());
    // The fragments' colours are the frames' colours averaged: vertex by vertex close to the
    // colours the coloured raw frames gave.
    std::vector<int> differences;
    for (size_t v = 0; v < coloured->colors.size(); ++v) {
        int d = 0;
        for (int c = 0; c < 3; ++c)
            d = std::max(d, std::abs(int{coloured->colors[v][c]} - int{from_points->colors[v][c]}));
        differences.push_back(d);
    }
    std::sort(differences.begin(), differences.end());
    EXPECT_LE(differences[differences.size() / 2], 6);
    fs::remove_all(dir);
}

}  // namespace
}  // namespace plumb::backend
