// SPDX-License-Identifier: Apache-2.0
#include "messages/lcm_url.hpp"

#include <fmt/format.h>

#include <string_view>
#include <vector>

namespace plumb::messages {
namespace {

std::vector<std::string_view> split(std::string_view text, char separator) {
    std::vector<std::string_view> parts;
    while (true) {
        const size_t at = text.find(separator);
        parts.push_back(text.substr(0, at));
        if (at == std::string_view::npos) return parts;
        text.remove_prefix(at + 1);
    }
}

/// A decimal number in [0, max] without sign or leading zeros (so inet_aton and strtol agree).
bool parsePlainDecimal(std::string_view text, int max, int* out) {
    if (text.empty() || text.size() > 5 || (text.size() > 1 && text[0] == '0')) return false;
    int v = 0;
    for (char c : text) {
        if (c < '0' || c > '9') return false;
        v = v * 10 + (c - '0');
    }
    if (v > max) return false;
    *out = v;
    return true;
}

/// Ok when `network` ("a.b.c.d[:port]") names an IPv4 multicast group: packets to a unicast
/// address ignore the multicast ttl.
Status checkMulticastGroup(const std::string& url, std::string_view network) {
    const size_t colon = network.find(':');
    const std::string_view address = network.substr(0, colon);
    int port = 0;
    if (colon != std::string_view::npos &&
        !parsePlainDecimal(network.substr(colon + 1), 65535, &port)) {
        return failedPrecondition(
            fmt::format("LCM URL '{}': port '{}' is not a decimal number in [0, 65535]", url,
                        network.substr(colon + 1)));
    }
    const std::vector<std::string_view> bytes = split(address, '.');
    int first = -1, v = 0;
    bool dotted = bytes.size() == 4;
    for (size_t i = 0; dotted && i < bytes.size(); ++i) {
        dotted = parsePlainDecimal(bytes[i], 255, &v);
        if (i == 0) first = v;
    }
    if (!dotted || first < 224 || first > 239) {
        return failedPrecondition(
            fmt::format("LCM URL '{}': '{}' is not an IPv4 multicast group in dotted decimal "
                        "(224.0.0.0 to 239.255.255.255); packets to other addresses ignore ttl",
                        url, address));
    }
    return Status::ok();
}

}  // namespace

Result<LcmUrl> parseLcmUrl(const std::string& url) {
    if (url.empty()) {
        return invalidArgument("empty LCM URL (LCM would use $LCM_DEFAULT_URL instead)");
    }
    const size_t scheme = url.find("://");
    if (scheme == std::string::npos) {
        return invalidArgument(fmt::format("LCM URL '{}' has no 'provider://'", url));
    }
    LcmUrl out;
    out.provider = url.substr(0, scheme);
    const std::string_view rest = std::string_view(url).substr(scheme + 3);
    const size_t question = rest.find('?');
    out.network = std::string(rest.substr(0, question));
    if (question == std::string_view::npos) return out;
    for (std::string_view option : split(rest.substr(question + 1), '&')) {
        if (option.empty()) continue;  // "a=1&&b=2": LCM skips it too
        const size_t eq = option.find('=');
        if (eq == 0 || eq == std::string_view::npos || eq + 1 == option.size()) {
            return invalidArgument(fmt::format(
                "LCM URL '{}': option '{}' needs a key and a value (LCM would ignore it)", url,
                option));
        }
        const std::string key(option.substr(0, eq));
        const std::string value(option.substr(eq + 1));
        if (!out.options.emplace(key, value).second) {
            return invalidArgument(fmt::format(
                "LCM URL '{}': option '{}' is given more than once (LCM would use the last "
                "value, '{}')",
                url, key, value));
        }
    }
    return out;
}

Status checkStaysOnHost(const std::string& url) {
    auto parsed = parseLcmUrl(url);
    if (!parsed.isOk()) return parsed.status();
    if (parsed->provider == "memq") return Status::ok();
    if (parsed->provider != "udpm") {
        return failedPrecondition(fmt::format(
            "LCM URL '{}': provider '{}' is not known to keep traffic on this host (only memq "
            "and udpm with ttl=0 are)",
            url, parsed->provider));
    }
    PLUMB_RETURN_IF_ERROR(checkMulticastGroup(url, parsed->network));
    const auto ttl = parsed->options.find("ttl");
    if (ttl == parsed->options.end()) {
        return failedPrecondition(fmt::format("LCM URL '{}' has no ttl=0 option", url));
    }
    if (ttl->second != "0") {
        return failedPrecondition(
            fmt::format("LCM URL '{}': ttl={} lets packets leave this host (only ttl=0 does not)",
                        url, ttl->second));
    }
    return Status::ok();
}

bool keepsTrafficOnHost(const std::string& url) { return checkStaysOnHost(url).isOk(); }

}  // namespace plumb::messages
