// SPDX-License-Identifier: Apache-2.0
#include "messages/lcm_link.hpp"

#include <fmt/format.h>

#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <fstream>
#include <random>
#include <set>

#include "common/core/logging.hpp"
#include "messages/files.hpp"

namespace plumb::messages {

std::string weakKeyReason(std::span<const uint8_t> key) {
    if (std::all_of(key.begin(), key.end(), [](uint8_t b) { return b == 0; })) return "all zero";
    std::set<uint8_t> distinct(key.begin(), key.end());
    if (distinct.size() == 1) return "every byte the same";
    if (distinct.size() < kMinDistinctKeyBytes) {
        return fmt::format("only {} distinct byte values in {} bytes", distinct.size(), key.size());
    }
    return {};
}

std::string keyFileModeWarning(const std::filesystem::path& path, unsigned mode) {
    if ((mode & 077u) == 0) return {};
    const char* who = (mode & 007u) != 0 ? "others" : "its group";
    return fmt::format(
        "key file {} is accessible by {} (mode {:04o}); anyone who can read it can forge "
        "messages: chmod 600 {}",
        path.string(), who, mode & 07777u, path.string());
}

Result<std::vector<uint8_t>> readKeyFile(const std::filesystem::path& path) {
    auto bytes = readFile(path, 1 << 16);
    if (!bytes.isOk()) return bytes.status();
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0) {
        const std::string warning = keyFileModeWarning(path, st.st_mode);
        if (!warning.empty()) log::warn("{}", warning);
    }
    std::vector<uint8_t> key;
    int high = -1;
    for (size_t i = 0; i < bytes->size(); ++i) {
        const uint8_t c = (*bytes)[i];
        if (c == ' ' || c == '\n' || c == '\r' || c == '\t') continue;
        const int d = c >= '0' && c <= '9'   ? c - '0'
                      : c >= 'a' && c <= 'f' ? c - 'a' + 10
                      : c >= 'A' && c <= 'F' ? c - 'A' + 10
                                             : -1;
        if (d < 0) {  // the offset only: the file's content is secret
            return invalidArgument(fmt::format(
                "key file {}: expected hexadecimal text, found another character at byte {}",
                path.string(), i));
        }
        if (high < 0) {
            high = d;
        } else {
            key.push_back(static_cast<uint8_t>(high * 16 + d));
            high = -1;
        }
    }
    if (high >= 0) {
        return invalidArgument(fmt::format("key file {}: odd number of hex digits", path.string()));
    }
    if (key.size() < 16) {
        return invalidArgument(fmt::format(
            "key file {}: {} bytes, need at least 16 (32 hex digits)", path.string(), key.size()));
    }
    if (const std::string weak = weakKeyReason(key); !weak.empty()) {
        return invalidArgument(fmt::format(
            "key file {}: a weak key ({}); make a random one: head -c 32 /dev/urandom | xxd -p "
            "-c 64 > plumb.key",
            path.string(), weak));
    }
    return key;
}

/// `url` with recv_buf_size=`bytes` added when it is a udpm URL without one (bytes > 0). Logs
/// when the kernel will cap the request (net.core.rmem_max).
std::string withReceiveBuffer(const std::string& url, int64_t bytes) {
    if (bytes <= 0) return url;
    auto parsed = parseLcmUrl(url);
    if (!parsed.isOk() || parsed->provider != "udpm" || parsed->options.count("recv_buf_size"))
        return url;
    std::ifstream limit_file("/proc/sys/net/core/rmem_max");
    int64_t limit = 0;
    if (limit_file >> limit && limit < bytes) {
        log::debug(
            "LCM: the kernel caps the receive buffer at {} bytes (net.core.rmem_max), "
            "below the {} asked for; raw frames streamed at full rate may be lost "
            "(sysctl -w net.core.rmem_max={} raises it)",
            limit, bytes, bytes);
    }
    return fmt::format("{}{}recv_buf_size={}", url, url.find('?') == std::string::npos ? "?" : "&",
                       bytes);
}

int64_t randomSenderId() {
    std::random_device rd;
    const uint64_t t =
        static_cast<uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
    const uint64_t r = (static_cast<uint64_t>(rd()) << 32) ^ rd() ^ (t * 0x9E3779B97F4A7C15ull);
    const int64_t id = static_cast<int64_t>(r >> 1);
    return id == 0 ? 1 : id;
}

Result<std::unique_ptr<LcmLink>> LcmLink::open(const LinkOptions& options) {
    if (auto parsed = parseLcmUrl(options.url); !parsed.isOk()) return parsed.status();
    if (Status s = checkStaysOnHost(options.url); !options.allow_remote && !s.isOk()) {
        return failedPrecondition(fmt::format(
            "{}; use a udpm:// URL with ttl=0 (the default {}) or memq://, or allow packets to "
            "leave this machine with --allow-remote",
            s.message(), kDefaultLcmUrl));
    }
    AuthConfig auth;
    if (!options.key_file.empty()) {
        auto key = readKeyFile(options.key_file);
        if (!key.isOk()) return key.status();
        auth.key = std::move(key).value();
    }
    auth.key_id = options.key_id;
    auth.sender_id = randomSenderId();
    std::unique_ptr<LcmLink> link(new LcmLink());
    const std::string url = withReceiveBuffer(options.url, options.recv_buffer_bytes);
    auto lcm = LcmTransport::create(url);
    if (!lcm.isOk()) return lcm.status();
    link->lcm_ = std::move(lcm).value();
    link->auth_ = std::make_unique<AuthenticatedTransport>(*link->lcm_, std::move(auth));
    return link;
}

Status LcmLink::pump(int timeout_ms) {
    const auto now = std::chrono::system_clock::now().time_since_epoch();
    auth_->setTime(std::chrono::duration_cast<std::chrono::microseconds>(now).count());
    errno = 0;
    auto r = lcm_->handle(timeout_ms);
    // A signal (SIGINT/SIGTERM, handled by the program) interrupts LCM's select(): not an error.
    if (!r.isOk() && errno == EINTR) return Status::ok();
    if (!r.isOk()) return r.status();
    // Then whatever else is already waiting (bounded, so timers still run under a flood).
    for (int i = 0; i < 256 && *r; ++i) {
        r = lcm_->handle(0);
        if (!r.isOk()) return r.status();
    }
    return Status::ok();
}

}  // namespace plumb::messages
