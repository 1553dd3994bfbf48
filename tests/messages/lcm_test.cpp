// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <random>

#include "messages/auth.hpp"
#include "messages/channels.hpp"
#include "messages/fragment_assembler.hpp"
#include "messages/fragment_sender.hpp"
#include "messages/lcm_link.hpp"
#include "messages/lcm_log.hpp"
#include "messages/lcm_transport.hpp"
#include "messages/lcm_url.hpp"

namespace plumb::messages {
namespace {

TEST(LcmTransport, UrlPolicy) {
    EXPECT_TRUE(keepsTrafficOnHost(kDefaultLcmUrl));
    EXPECT_TRUE(keepsTrafficOnHost("memq://"));
    EXPECT_TRUE(keepsTrafficOnHost("udpm://239.255.76.67:7667?recv_buf_size=100&ttl=0"));
    EXPECT_FALSE(keepsTrafficOnHost("udpm://239.255.76.67:7667?ttl=1"));
    EXPECT_FALSE(keepsTrafficOnHost("udpm://239.255.76.67:7667?ttl=01"));
    EXPECT_FALSE(keepsTrafficOnHost("udpm://239.255.76.67:7667"));
    EXPECT_FALSE(keepsTrafficOnHost("file:///tmp/log?mode=w"));
}

// Issue 32, item 3: LCM 1.3.1 keeps the last value of a repeated option, so the first ttl=0 must
// not make a URL pass; repeated or half-given options are refused with a message saying why.
TEST(LcmUrl, RepeatedOptionsCannotBypassTheOnHostCheck) {
    for (const char* url : {"udpm://239.255.76.67:7807?ttl=0&ttl=255",
                            "udpm://239.255.76.67:7807?ttl=0&recv_buf_size=1&ttl=1",
                            "udpm://239.255.76.67:7807?ttl=1&ttl=0"}) {
        EXPECT_FALSE(keepsTrafficOnHost(url)) << url;
    }
    const Status s = checkStaysOnHost("udpm://239.255.76.67:7807?ttl=0&ttl=255");
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(s.message().find("'ttl' is given more than once"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("'255'"), std::string::npos) << s.message();
    auto parsed = parseLcmUrl("memq://?a=1&a=2");
    ASSERT_FALSE(parsed.isOk());
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument);
}

TEST(LcmUrl, ParsedTheWayLcmDoes) {
    auto u = parseLcmUrl("udpm://239.255.76.67:7667?recv_buf_size=100&&ttl=0&x=a=b");
    ASSERT_TRUE(u.isOk()) << u.status().toString();
    EXPECT_EQ(u->provider, "udpm");
    EXPECT_EQ(u->network, "239.255.76.67:7667");
    EXPECT_EQ(u->options.size(), 3u);
    EXPECT_EQ(u->options.at("ttl"), "0");
    EXPECT_EQ(u->options.at("x"), "a=b");  // split at the first '=' only
    auto nested = parseLcmUrl("udpm://239.255.76.67:7667?a=1?ttl=5");
    ASSERT_TRUE(nested.isOk());
    EXPECT_EQ(nested->options.at("a"), "1?ttl=5");  // only the first '?' separates
    EXPECT_FALSE(keepsTrafficOnHost("udpm://239.255.76.67:7667?a=1?ttl=0"));
    for (const char* bad : {"", "udpm:/239.255.76.67", "udpm://239.255.76.67?ttl=",
                            "udpm://239.255.76.67?=0", "udpm://239.255.76.67?ttl"}) {
        auto r = parseLcmUrl(bad);
        EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument) << bad;
    }
}

TEST(LcmUrl, OnlyMulticastWithTtlZeroOrMemqStayOnHost) {
    EXPECT_FALSE(keepsTrafficOnHost("udpm://?ttl=0"));  // no group named: not judged
    EXPECT_TRUE(keepsTrafficOnHost("udpm://239.255.76.67?ttl=0"));
    EXPECT_TRUE(keepsTrafficOnHost("memq://"));
    // Unicast ignores the multicast ttl; inet_aton would read 0xef/octal forms differently;
    // LCM's option names are case-sensitive.
    for (const char* url : {"udpm://10.0.0.5:7667?ttl=0", "udpm://0xef.255.76.67:7667?ttl=0",
                            "udpm://239.255.076.67:7667?ttl=0", "udpm://239.255.76.67:port?ttl=0",
                            "udpm://239.255.76.67:7667?ttl=0x0", "udpm://239.255.76.67:7667?ttl=-1",
                            "udpm://239.255.76.67:7667?TTL=0", "tcpq://localhost:7700"}) {
        EXPECT_FALSE(keepsTrafficOnHost(url)) << url;
    }
    EXPECT_EQ(checkStaysOnHost("udpm://239.255.76.67:7667?ttl=2").code(),
              StatusCode::kFailedPrecondition);
}

// Runs the fragment protocol (signed when `key` is set) over one LCM instance.
void runOverLcm(const std::string& url, const std::string& key) {
    auto lcm = LcmTransport::create(url);
    ASSERT_TRUE(lcm.isOk()) << lcm.status().toString();
    AuthConfig device_auth, backend_auth;
    device_auth.key.assign(key.begin(), key.end());
    device_auth.sender_id = 1;
    backend_auth.key = device_auth.key;
    backend_auth.sender_id = 2;
    AuthenticatedTransport device(**lcm, device_auth);
    AuthenticatedTransport backend(**lcm, backend_auth);
    FragmentSenderConfig sc;
    sc.session_id = 1234;
    FragmentSender sender(sc, device);  // 60000-byte chunks
    FragmentAssembler assembler(FragmentAssemblerConfig{}, backend);
    double now = 0.0;
    ASSERT_TRUE(device
                    .subscribe(kChannelFragmentAck,
                               [&](const std::string& c, std::span<const uint8_t> b) {
                                   EXPECT_TRUE(sender.onMessage(c, b, now).isOk());
                               })
                    .isOk());
    for (const char* ch : {kChannelFragmentHeader, kChannelFragmentChunk}) {
        ASSERT_TRUE(backend
                        .subscribe(ch,
                                   [&](const std::string& c, std::span<const uint8_t> b) {
                                       EXPECT_TRUE(assembler.onMessage(c, b, now).isOk());
                                   })
                        .isOk());
    }
    std::vector<Bytes> payloads;
    for (uint32_t i = 0; i < 3; ++i) {
        Bytes p(150000 + 12345 * i);
        for (size_t k = 0; k < p.size(); ++k) p[k] = static_cast<uint8_t>((k * 31) ^ (k >> 9) ^ i);
        payloads.push_back(p);
        ASSERT_TRUE(sender.send(i, p, now).isOk());
    }
    std::map<uint32_t, Bytes> store;
    for (int step = 0; step < 400 && sender.numInFlight() > 0; ++step) {
        auto handled = (*lcm)->handle(step == 0 ? 0 : 5);
        ASSERT_TRUE(handled.isOk());
        for (auto& c : assembler.takeCompleted()) {
            EXPECT_TRUE(store.emplace(c.fragment_id, c.bytes).second);
            assembler.acknowledge(c.session_id, c.fragment_id, now);
        }
        now += 0.01;
        sender.poll(now);
        assembler.poll(now);
    }
    EXPECT_EQ(sender.numInFlight(), 0u);
    ASSERT_EQ(store.size(), payloads.size());
    for (uint32_t i = 0; i < payloads.size(); ++i) EXPECT_EQ(store[i], payloads[i]);
    if (!key.empty()) {
        EXPECT_GT(backend.stats().accepted, 0u);
        EXPECT_EQ(backend.stats().rejected(), 0u);
    }
}

namespace fs = std::filesystem;

// A log of `n` events written by LCM's own writer; returns its bytes and each event's offset.
std::vector<uint8_t> writeLog(const fs::path& path, int n, std::vector<size_t>* offsets) {
    {
        lcm::LogFile log(path.string(), "w");
        EXPECT_TRUE(log.good());
        for (int i = 0; i < n; ++i) {
            std::vector<uint8_t> data(100 + 37 * i);
            for (size_t k = 0; k < data.size(); ++k) data[k] = static_cast<uint8_t>(k * 7 + i);
            lcm::LogEvent e;
            e.eventnum = i;
            e.timestamp = 1000 * i;
            e.channel = "PLUMB_TEST_" + std::to_string(i);
            e.datalen = static_cast<int32_t>(data.size());
            e.data = data.data();
            EXPECT_EQ(log.writeEvent(&e), 0);
        }
    }
    std::ifstream in(path, std::ios::binary);
    std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                               std::istreambuf_iterator<char>());
    size_t at = 0;
    for (int i = 0; i < n; ++i) {
        offsets->push_back(at);
        const auto len = [&](size_t p) {
            return (size_t{bytes[p]} << 24) | (size_t{bytes[p + 1]} << 16) |
                   (size_t{bytes[p + 2]} << 8) | bytes[p + 3];
        };
        at += 28 + len(at + 20) + len(at + 24);
    }
    EXPECT_EQ(at, bytes.size());
    return bytes;
}

void writeBytes(const fs::path& path, const std::vector<uint8_t>& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
}

struct LogRead {
    std::vector<std::string> channels;
    LcmLogStats stats;
    Status verdict;
};

LogRead readLog(const fs::path& path) {
    LogRead r;
    auto reader = LcmLogReader::open(path);
    EXPECT_TRUE(reader.isOk()) << reader.status().toString();
    if (!reader.isOk()) return r;
    while (auto e = (*reader)->next()) r.channels.push_back(e->channel);
    r.stats = (*reader)->stats();
    r.verdict = (*reader)->verdict();
    return r;
}

// Issue 32, item 5: empty, random, text, cut and damaged logs are told apart from intact ones,
// and reading goes on after a damaged event (LCM's reader stops there without a word).
TEST(LcmLogReader, CountsDamageTruncationAndGarbage) {
    const fs::path dir = fs::temp_directory_path() / ("plumb_lcmlog_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::vector<size_t> at;
    const std::vector<uint8_t> good = writeLog(dir / "good.lcmlog", 10, &at);
    LogRead r = readLog(dir / "good.lcmlog");
    EXPECT_TRUE(r.verdict.isOk()) << r.verdict.toString();
    ASSERT_EQ(r.channels.size(), 10u);
    EXPECT_EQ(r.channels[9], "PLUMB_TEST_9");

    writeBytes(dir / "empty", {});
    r = readLog(dir / "empty");
    EXPECT_EQ(r.verdict.code(), StatusCode::kCorrupt);
    EXPECT_NE(r.verdict.message().find("is empty"), std::string::npos);

    std::mt19937 rng(32);
    std::vector<uint8_t> noise(200000);
    for (auto& b : noise) b = static_cast<uint8_t>(rng());
    writeBytes(dir / "random", noise);
    const std::string text = "this is a text file, not an LCM log\n";
    writeBytes(dir / "text", std::vector<uint8_t>(text.begin(), text.end()));
    for (const char* name : {"random", "text"}) {
        r = readLog(dir / name);
        EXPECT_EQ(r.stats.events, 0u) << name;
        EXPECT_NE(r.verdict.message().find("is not an LCM log"), std::string::npos) << name;
    }

    // Cut inside the last event.
    writeBytes(dir / "cut", std::vector<uint8_t>(good.begin(), good.begin() + at[9] + 40));
    r = readLog(dir / "cut");
    EXPECT_EQ(r.stats.events, 9u);
    EXPECT_TRUE(r.stats.truncated);
    EXPECT_EQ(r.stats.events_lost, 1u);
    EXPECT_NE(r.verdict.message().find("truncated"), std::string::npos) << r.verdict.message();

    // A damaged data length in event 3, a damaged channel length in event 6: both lost, the
    // others read.
    std::vector<uint8_t> bad = good;
    bad[at[3] + 24] = 0x7f;
    bad[at[6] + 20] = 0;
    bad[at[6] + 23] = 0;
    writeBytes(dir / "damaged", bad);
    r = readLog(dir / "damaged");
    EXPECT_EQ(r.stats.events, 8u);
    EXPECT_EQ(r.stats.damaged_events, 2u);
    EXPECT_EQ(r.stats.events_lost, 2u);
    EXPECT_FALSE(r.stats.truncated);
    EXPECT_EQ(r.channels.back(), "PLUMB_TEST_9");
    EXPECT_EQ(r.verdict.code(), StatusCode::kCorrupt);
    EXPECT_NE(r.verdict.message().find("8 event(s) read intact, 2 lost"), std::string::npos)
        << r.verdict.message();

    // Garbage between events 4 and 5, and event 7 cut out: all events but 7 read, 1 lost.
    bad.assign(good.begin(), good.begin() + at[5]);
    bad.insert(bad.end(), noise.begin(), noise.begin() + 333);
    bad.insert(bad.end(), good.begin() + at[5], good.begin() + at[7]);
    bad.insert(bad.end(), good.begin() + at[8], good.end());
    writeBytes(dir / "garbage", bad);
    r = readLog(dir / "garbage");
    EXPECT_EQ(r.stats.events, 9u);
    EXPECT_EQ(r.stats.damaged_events, 0u);
    EXPECT_EQ(r.stats.events_lost, 1u);
    EXPECT_EQ(r.stats.skipped_bytes, 333u);
    EXPECT_EQ(r.verdict.code(), StatusCode::kCorrupt);
    EXPECT_EQ(LcmLogReader::open(dir / "missing").status().code(), StatusCode::kNotFound);
    fs::remove_all(dir);
}

// Issue 32, item 9: weak keys are refused, and no message repeats what the file holds.
TEST(KeyFile, WeakKeysAreRefusedAndNeverPrinted) {
    const fs::path dir = fs::temp_directory_path() / ("plumb_keys_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    auto write = [&](const std::string& name, const std::string& text) {
        writeBytes(dir / name, std::vector<uint8_t>(text.begin(), text.end()));
        return dir / name;
    };
    std::string repeated;
    for (int i = 0; i < 16; ++i) repeated += "0102";
    const std::vector<std::pair<std::string, std::string>> weak = {
        {std::string(64, '0'), "weak key (all zero)"},
        {std::string(64, 'f'), "weak key (every byte the same)"},
        {repeated, "weak key (only 2 distinct byte values in 32 bytes)"}};
    for (const auto& [text, message] : weak) {
        auto key = readKeyFile(write("weak.key", text + "\n"));
        ASSERT_FALSE(key.isOk()) << message;
        EXPECT_EQ(key.status().code(), StatusCode::kInvalidArgument);
        EXPECT_NE(key.status().message().find(message), std::string::npos)
            << key.status().message();
    }
    auto good = readKeyFile(
        write("good.key", "00112233445566778899aabbccddeeff0123456789abcdef0123456789abcdef\n"));
    ASSERT_TRUE(good.isOk()) << good.status().toString();
    EXPECT_EQ(good->size(), 32u);
    auto passphrase = readKeyFile(write("pass.key", "deadbeef correct horse battery staple"));
    ASSERT_FALSE(passphrase.isOk());
    EXPECT_NE(passphrase.status().message().find("at byte 10"), std::string::npos)
        << passphrase.status().message();
    EXPECT_EQ(passphrase.status().message().find("horse"), std::string::npos);
    EXPECT_EQ(passphrase.status().message().find("0x"), std::string::npos);
    fs::remove_all(dir);
}

// Like ssh: any access for group or others is warned about, naming the mode and the fix.
TEST(KeyFile, LoosePermissionsAreWarnedAbout) {
    EXPECT_EQ(keyFileModeWarning("plumb.key", 0100600), "");
    EXPECT_EQ(keyFileModeWarning("plumb.key", 0100400), "");
    const std::string group = keyFileModeWarning("plumb.key", 0100640);
    EXPECT_NE(group.find("accessible by its group (mode 0640)"), std::string::npos) << group;
    const std::string others = keyFileModeWarning("plumb.key", 0100666);
    EXPECT_NE(others.find("accessible by others (mode 0666)"), std::string::npos) << others;
    EXPECT_NE(others.find("chmod 600 plumb.key"), std::string::npos) << others;
}

TEST(LcmTransport, FragmentsOverMemq) { runOverLcm("memq://", ""); }

TEST(LcmTransport, SignedFragmentsOverMemq) {
    runOverLcm("memq://", "a shared key of thirty-two bytes");
}

TEST(LcmTransport, RejectsRegexChannelNames) {
    auto lcm = LcmTransport::create("memq://");
    ASSERT_TRUE(lcm.isOk());
    EXPECT_FALSE(
        (*lcm)->subscribe("PLUMB_.*", [](const std::string&, std::span<const uint8_t>) {}).isOk());
    EXPECT_FALSE(LcmTransport::create("nonsense://x").isOk());
}

// LinkOptions::recv_buffer_bytes: added to a udpm URL without recv_buf_size (a raw VGA frame is
// 0.7 MB; the system's default buffer loses whole frames), never to one that sets it, nor to
// other providers.
TEST(LcmLink, AsksForTheReceiveBufferOnUdpmUrlsThatSetNone) {
    LinkOptions options;
    options.recv_buffer_bytes = int64_t{4} << 20;
    const std::string port = std::to_string(20000 + ::getpid() % 30000);
    options.url = "udpm://239.255.76.67:" + port + "?ttl=0";
    auto link = LcmLink::open(options);
    ASSERT_TRUE(link.isOk()) << link.status().toString();
    EXPECT_EQ((*link)->url(), options.url + "&recv_buf_size=4194304");
    auto parsed = parseLcmUrl((*link)->url());
    ASSERT_TRUE(parsed.isOk());
    EXPECT_EQ(parsed->options.at("recv_buf_size"), "4194304");
    EXPECT_TRUE(keepsTrafficOnHost((*link)->url()));

    options.url = "udpm://239.255.76.67:" + port + "?recv_buf_size=65536&ttl=0";
    link = LcmLink::open(options);
    ASSERT_TRUE(link.isOk()) << link.status().toString();
    EXPECT_EQ((*link)->url(), options.url);

    options.url = "memq://";
    link = LcmLink::open(options);
    ASSERT_TRUE(link.isOk()) << link.status().toString();
    EXPECT_EQ((*link)->url(), "memq://");

    options.recv_buffer_bytes = 0;  // the system's default
    options.url = "udpm://239.255.76.67:" + port + "?ttl=0";
    link = LcmLink::open(options);
    ASSERT_TRUE(link.isOk()) << link.status().toString();
    EXPECT_EQ((*link)->url(), options.url);
}

}  // namespace
}  // namespace plumb::messages
