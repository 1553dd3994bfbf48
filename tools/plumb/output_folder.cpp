// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/output_folder.hpp"

#include <fmt/format.h>

#include <fstream>

namespace plumb::tools {
namespace fs = std::filesystem;
namespace {

bool looksLikePlumbOutput(const fs::path& dir) {
    std::error_code ec;
    for (const char* name :
         {"metrics.json", "config.toml", "fragments.json", "fragments", "resume"}) {
        if (fs::exists(dir / name, ec)) return true;
    }
    return false;
}

Status clearFolder(const fs::path& out) {
    std::error_code ec;
    for (const fs::directory_entry& e : fs::directory_iterator(out, ec)) {
        fs::remove_all(e.path(), ec);
        if (ec) {
            return ioError(fmt::format("--out {}: cannot remove {}: {}", out.string(),
                                       e.path().filename().string(), ec.message()));
        }
    }
    if (ec) return ioError(fmt::format("--out {}: cannot list: {}", out.string(), ec.message()));
    return Status::ok();
}

}  // namespace

Status prepareOutputFolder(const fs::path& out, bool force) {
    std::error_code ec;
    if (fs::exists(out, ec) && !fs::is_directory(out, ec)) {
        return invalidArgument(fmt::format("--out {}: exists and is not a folder", out.string()));
    }
    if (fs::is_directory(out, ec) && !fs::is_empty(out, ec)) {
        if (!force) {
            return invalidArgument(fmt::format(
                "--out {}: the folder is not empty (an earlier run's files would mix with this "
                "one's); choose another, add --force to clear it, or continue an interrupted run "
                "with --resume {}",
                out.string(), out.string()));
        }
        if (!looksLikePlumbOutput(out)) {
            return invalidArgument(fmt::format(
                "--out {}: --force clears only an earlier plumb run's output folder, and this "
                "one holds other files; clear it yourself or choose another",
                out.string()));
        }
        PLUMB_RETURN_IF_ERROR(clearFolder(out));
    }
    fs::create_directories(out, ec);
    if (ec) return ioError(fmt::format("--out {}: cannot create: {}", out.string(), ec.message()));
    const fs::path probe = out / ".plumb-write-test";
    {
        std::ofstream f(probe);
        if (!(f << "plumb\n")) {
            return ioError(fmt::format("--out {}: cannot write into it", out.string()));
        }
    }
    fs::remove(probe, ec);
    return Status::ok();
}

}  // namespace plumb::tools
