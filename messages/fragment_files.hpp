// SPDX-License-Identifier: Apache-2.0
#pragma once

// How an encoded fragment is named where it is kept on disk: by the device's spool
// (device/stream/spool.hpp) and by the backend's fragment store (messages/fragment_store.hpp),
// both keyed by (session, fragment id). Pure functions: thread-safe.

#include <cstdint>
#include <string>

namespace plumb::messages {

/// A fragment of a device session: the key of the spool and of the fragment store.
struct FragmentKey {
    int64_t session_id = 0;
    uint32_t fragment_id = 0;
    auto operator<=>(const FragmentKey&) const = default;
};

/// File name used by the spool and the fragment store: "s<session, 16 hex>_f<id, 10 digits>.plf".
std::string fragmentFileName(int64_t session_id, uint32_t fragment_id);
/// Inverse of fragmentFileName; false for any other name.
bool parseFragmentFileName(const std::string& name, int64_t& session_id, uint32_t& fragment_id);

}  // namespace plumb::messages
