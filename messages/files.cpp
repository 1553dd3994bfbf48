// SPDX-License-Identifier: Apache-2.0
#include "messages/files.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace plumb::messages {
namespace {

Status osError(const std::string& what, const std::filesystem::path& path) {
    return ioError(fmt::format("{} {}: {}", what, path.string(), std::strerror(errno)));
}

/// Closes a descriptor on scope exit.
class Fd {
  public:
    explicit Fd(int fd) : fd_(fd) {}
    ~Fd() {
        if (fd_ >= 0) ::close(fd_);
    }
    Fd(const Fd&) = delete;
    Fd& operator=(const Fd&) = delete;
    int get() const { return fd_; }
    int release() { return std::exchange(fd_, -1); }

  private:
    int fd_;
};

Status syncDirectory(const std::filesystem::path& dir) {
    Fd fd(::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
    if (fd.get() < 0) return osError("cannot open directory", dir);
    if (::fsync(fd.get()) != 0) return osError("cannot fsync directory", dir);
    return Status::ok();
}

}  // namespace

Status writeFileAtomic(const std::filesystem::path& path, std::span<const uint8_t> bytes) {
    std::filesystem::path tmp = path;
    tmp += kTempSuffix;
    {
        Fd fd(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644));
        if (fd.get() < 0) return osError("cannot create", tmp);
        size_t done = 0;
        while (done < bytes.size()) {
            const ssize_t n = ::write(fd.get(), bytes.data() + done, bytes.size() - done);
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) {
                Status s = osError("cannot write", tmp);
                ::unlink(tmp.c_str());
                return s;
            }
            done += static_cast<size_t>(n);
        }
        if (::fsync(fd.get()) != 0) {
            Status s = osError("cannot fsync", tmp);
            ::unlink(tmp.c_str());
            return s;
        }
        if (::close(fd.release()) != 0) {
            Status s = osError("cannot close", tmp);
            ::unlink(tmp.c_str());
            return s;
        }
    }
    if (::rename(tmp.c_str(), path.c_str()) != 0) {
        Status s = osError("cannot rename onto", path);
        ::unlink(tmp.c_str());
        return s;
    }
    return syncDirectory(path.parent_path());
}

Result<std::vector<uint8_t>> readFile(const std::filesystem::path& path, int64_t max_bytes) {
    Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    if (fd.get() < 0) {
        if (errno == ENOENT) return notFound(fmt::format("{}: no such file", path.string()));
        return osError("cannot open", path);
    }
    struct stat st {};
    if (::fstat(fd.get(), &st) != 0) return osError("cannot stat", path);
    if (st.st_size > max_bytes) {
        return outOfRange(fmt::format("{}: {} bytes exceed the limit of {}", path.string(),
                                      st.st_size, max_bytes));
    }
    std::vector<uint8_t> out(static_cast<size_t>(st.st_size));
    size_t done = 0;
    while (done < out.size()) {
        const ssize_t n = ::read(fd.get(), out.data() + done, out.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) return osError("cannot read", path);
        if (n == 0) return ioError(fmt::format("{}: shrank while reading", path.string()));
        done += static_cast<size_t>(n);
    }
    return out;
}

Status removeFile(const std::filesystem::path& path) {
    if (::unlink(path.c_str()) != 0) {
        if (errno == ENOENT) return Status::ok();
        return osError("cannot remove", path);
    }
    return syncDirectory(path.parent_path());
}

Status moveFile(const std::filesystem::path& from, const std::filesystem::path& to) {
    if (::rename(from.c_str(), to.c_str()) != 0) {
        return ioError(fmt::format("cannot move {} to {}: {}", from.string(), to.string(),
                                   std::strerror(errno)));
    }
    PLUMB_RETURN_IF_ERROR(syncDirectory(to.parent_path()));
    return syncDirectory(from.parent_path());
}

}  // namespace plumb::messages
