// SPDX-License-Identifier: Apache-2.0
#include "drivers/v4l2/v4l2_io.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>

namespace plumb::v4l2 {
namespace {

class SystemIo final : public V4l2Io {
  public:
    int open(const std::string& path, int flags) override {
        const int fd = ::open(path.c_str(), flags);
        return fd < 0 ? -errno : fd;
    }
    int close(int fd) override { return ::close(fd) < 0 ? -errno : 0; }
    int ioctl(int fd, unsigned long request, void* arg) override {
        int r = 0;
        do {
            r = ::ioctl(fd, request, arg);
        } while (r < 0 && errno == EINTR);
        return r < 0 ? -errno : r;
    }
    void* mmap(size_t length, int fd, off_t offset) override {
        void* p = ::mmap(nullptr, length, PROT_READ | PROT_WRITE, MAP_SHARED, fd, offset);
        return p == MAP_FAILED ? nullptr : p;
    }
    int munmap(void* address, size_t length) override {
        return ::munmap(address, length) < 0 ? -errno : 0;
    }
    int poll(int fd, int timeout_ms) override {
        pollfd p{fd, POLLIN, 0};
        int r = 0;
        do {
            r = ::poll(&p, 1, timeout_ms);
        } while (r < 0 && errno == EINTR);
        if (r < 0) return -errno;
        if (r == 0) return 0;
        if ((p.revents & (POLLERR | POLLHUP | POLLNVAL)) != 0) return -ENODEV;
        return 1;
    }
};

}  // namespace

std::shared_ptr<V4l2Io> systemIo() { return std::make_shared<SystemIo>(); }

}  // namespace plumb::v4l2
