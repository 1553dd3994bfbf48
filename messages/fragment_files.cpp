// SPDX-License-Identifier: Apache-2.0
#include "messages/fragment_files.hpp"

#include <fmt/format.h>

namespace plumb::messages {

std::string fragmentFileName(int64_t session_id, uint32_t fragment_id) {
    return fmt::format("s{:016x}_f{:010d}.plf", static_cast<uint64_t>(session_id), fragment_id);
}

bool parseFragmentFileName(const std::string& name, int64_t& session_id, uint32_t& fragment_id) {
    if (name.size() != 1 + 16 + 2 + 10 + 4 || name[0] != 's' || name.compare(17, 2, "_f") != 0 ||
        name.compare(29, 4, ".plf") != 0) {
        return false;
    }
    uint64_t s = 0, f = 0;
    for (size_t i = 1; i < 17; ++i) {
        const char c = name[i];
        const int d = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
        if (d < 0) return false;
        s = s * 16 + static_cast<uint64_t>(d);
    }
    for (size_t i = 19; i < 29; ++i) {
        if (name[i] < '0' || name[i] > '9') return false;
        f = f * 10 + static_cast<uint64_t>(name[i] - '0');
    }
    if (f > UINT32_MAX) return false;
    session_id = static_cast<int64_t>(s);
    fragment_id = static_cast<uint32_t>(f);
    return true;
}

}  // namespace plumb::messages
