// SPDX-License-Identifier: Apache-2.0
#pragma once

// LCM URLs read exactly as LCM 1.3.1 reads them, so that the on-host check of plumb-device,
// plumb-backend and `plumb monitor` judges the URL LCM will actually use.
//
// LCM 1.3.1 (lcm.c, lcm_parse_url): "provider://network?k1=v1&k2=v2". The provider is what comes
// before the first "://", the network what follows up to the first "?", the options what follows
// that, split at every "&"; an option is split at its first "="; empty options are skipped,
// options with an empty key or value are ignored (with a warning on stderr), and an option given
// twice keeps its LAST value (a hash table insert). udpm (lcm_udpm.c) reads the network as an
// IPv4 address with inet_aton and an optional ":port", and `ttl` with strtol(value, 0), stored in
// an unsigned char. An empty URL makes LCM read $LCM_DEFAULT_URL.
//
// plumb is stricter than LCM wherever LCM's reading could surprise: a repeated option, an option
// without key or value, or an empty URL are refused outright (InvalidArgument).
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <map>
#include <string>

#include "common/core/status.hpp"

namespace plumb::messages {

struct LcmUrl {
    std::string provider;                        ///< before the first "://" (e.g. "udpm")
    std::string network;                         ///< up to the first "?" (may be empty)
    std::map<std::string, std::string> options;  ///< key -> value, each key once
};

/// Splits `url` as LCM 1.3.1 does. InvalidArgument (naming the problem) for an empty URL, no
/// "://", an option without key or value, or an option given more than once.
Result<LcmUrl> parseLcmUrl(const std::string& url);

/// Ok when LCM at `url` cannot send packets off this machine: memq://, or udpm:// to an IPv4
/// multicast group named explicitly (224.0.0.0/4, dotted decimal) whose `ttl` option is exactly
/// "0". FailedPrecondition (saying why) for any other URL parseLcmUrl accepts;
/// its InvalidArgument for one it refuses.
Status checkStaysOnHost(const std::string& url);

/// checkStaysOnHost(url).isOk().
bool keepsTrafficOnHost(const std::string& url);

}  // namespace plumb::messages
