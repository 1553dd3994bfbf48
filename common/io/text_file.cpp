// SPDX-License-Identifier: Apache-2.0
#include "common/io/text_file.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <system_error>

namespace plumb::io {

Status writeText(const std::filesystem::path& path, const std::string& text) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) {
        return ioError(
            fmt::format("{}: cannot open for writing: {}", path.string(), std::strerror(errno)));
    }
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    out.close();
    if (!out) return ioError(fmt::format("{}: write failed (disk full?)", path.string()));
    return Status::ok();
}

Status writeTextReplacing(const std::filesystem::path& path, const std::string& text) {
    const std::filesystem::path tmp = path.string() + ".tmp";
    PLUMB_RETURN_IF_ERROR(writeText(tmp, text));
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec) return ioError(fmt::format("{}: {}", path.string(), ec.message()));
    return Status::ok();
}

}  // namespace plumb::io
