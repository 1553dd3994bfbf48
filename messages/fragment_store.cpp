// SPDX-License-Identifier: Apache-2.0
#include "messages/fragment_store.hpp"

#include <fmt/format.h>

#include <cstring>
#include <system_error>

#include "messages/crc32.hpp"
#include "messages/files.hpp"

namespace plumb::messages {
namespace {

constexpr int64_t kMaxFileBytes = int64_t{1} << 32;

}  // namespace

bool hasValidCrcTrailer(std::span<const uint8_t> bytes) {
    if (bytes.size() < 4) return false;
    uint32_t stored = 0;
    std::memcpy(&stored, bytes.data() + bytes.size() - 4, 4);  // little-endian like the codec
    return crc32(bytes.first(bytes.size() - 4)) == stored;
}

Result<std::unique_ptr<FragmentStore>> FragmentStore::open(const std::filesystem::path& dir) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) {
        return ioError(
            fmt::format("fragment store: cannot create {}: {}", dir.string(), ec.message()));
    }
    std::unique_ptr<FragmentStore> store(new FragmentStore(dir, false));
    PLUMB_RETURN_IF_ERROR(store->indexFiles());
    return store;
}

Result<std::unique_ptr<FragmentStore>> FragmentStore::openReadOnly(
    const std::filesystem::path& dir) {
    std::error_code ec;
    if (!std::filesystem::is_directory(dir, ec)) {
        return notFound(fmt::format("fragment store: no store at {}", dir.string()));
    }
    std::unique_ptr<FragmentStore> store(new FragmentStore(dir, true));
    PLUMB_RETURN_IF_ERROR(store->indexFiles());
    return store;
}

Status FragmentStore::indexFiles() {
    std::error_code ec;
    std::vector<std::filesystem::path> files;
    for (const auto& item : std::filesystem::directory_iterator(dir_, ec)) {
        files.push_back(item.path());
    }
    if (ec) {
        return ioError(
            fmt::format("fragment store: cannot list {}: {}", dir_.string(), ec.message()));
    }
    for (const auto& path : files) {
        const std::string name = path.filename().string();
        if (name.ends_with(kTempSuffix)) {
            // An interrupted write, never acknowledged; or, read-only, one in progress.
            if (!read_only_) PLUMB_RETURN_IF_ERROR(removeFile(path));
            continue;
        }
        StoredFragment f;
        if (!parseFragmentFileName(name, f.session_id, f.fragment_id)) continue;
        auto bytes = readFile(path, kMaxFileBytes);
        if (!bytes.isOk()) return bytes.status();
        if (!hasValidCrcTrailer(*bytes)) {
            if (read_only_) {
                quarantined_.push_back(path);
                continue;
            }
            std::filesystem::path aside = path;
            aside += ".corrupt";
            std::filesystem::rename(path, aside, ec);
            if (ec) {
                return ioError(fmt::format("fragment store: cannot move damaged {} aside: {}",
                                           path.string(), ec.message()));
            }
            quarantined_.push_back(aside);
            continue;
        }
        f.crc32 = crc32(*bytes);
        f.size_bytes = static_cast<int64_t>(bytes->size());
        f.path = path;
        index_.emplace(FragmentKey{f.session_id, f.fragment_id}, f);
    }
    return Status::ok();
}

Result<bool> FragmentStore::put(int64_t session_id, uint32_t fragment_id,
                                std::span<const uint8_t> bytes) {
    if (read_only_) {
        return failedPrecondition(
            fmt::format("fragment store: {} was opened read-only", dir_.string()));
    }
    const uint32_t crc = crc32(bytes);
    const FragmentKey key{session_id, fragment_id};
    if (auto it = index_.find(key); it != index_.end()) {
        if (it->second.crc32 == crc &&
            it->second.size_bytes == static_cast<int64_t>(bytes.size())) {
            return false;
        }
        return failedPrecondition(fmt::format(
            "fragment store: fragment {} of session {} is already stored with other content",
            fragment_id, session_id));
    }
    if (!hasValidCrcTrailer(bytes)) {
        return corrupt(
            fmt::format("fragment store: fragment {} fails its CRC trailer", fragment_id));
    }
    StoredFragment f;
    f.session_id = session_id;
    f.fragment_id = fragment_id;
    f.crc32 = crc;
    f.size_bytes = static_cast<int64_t>(bytes.size());
    f.path = dir_ / fragmentFileName(session_id, fragment_id);
    PLUMB_RETURN_IF_ERROR(writeFileAtomic(f.path, bytes));
    index_.emplace(key, std::move(f));
    return true;
}

Result<std::vector<uint8_t>> FragmentStore::get(int64_t session_id, uint32_t fragment_id) const {
    auto it = index_.find(FragmentKey{session_id, fragment_id});
    if (it == index_.end()) {
        return notFound(
            fmt::format("fragment store: no fragment {} of session {}", fragment_id, session_id));
    }
    auto bytes = readFile(it->second.path, it->second.size_bytes);
    if (!bytes.isOk()) return bytes.status();
    if (crc32(*bytes) != it->second.crc32) {
        return corrupt(fmt::format("fragment store: {} changed on disk", it->second.path.string()));
    }
    return bytes;
}

bool FragmentStore::contains(int64_t session_id, uint32_t fragment_id) const {
    return index_.count(FragmentKey{session_id, fragment_id}) > 0;
}

std::vector<StoredFragment> FragmentStore::fragments() const {
    std::vector<StoredFragment> out;
    out.reserve(index_.size());
    for (const auto& [k, f] : index_) out.push_back(f);
    return out;
}

}  // namespace plumb::messages
