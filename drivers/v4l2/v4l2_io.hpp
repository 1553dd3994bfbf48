// SPDX-License-Identifier: Apache-2.0
#pragma once

// The system calls of a V4L2 capture device behind one injectable interface, so the V4L2 source
// runs unchanged against a real /dev/videoN (systemIo) or a replayed recording (ReplayIo). Every
// call returns >= 0 or -errno, as libcamera's V4L2Device does; mmap returns nullptr on failure.
// UniqueFd and MappedBuffer release what they hold through the same interface (RAII).
//
// Thread-safety: systemIo's calls are the system calls and are thread-safe; other V4l2Io
// implementations say otherwise. UniqueFd and MappedBuffer are owned by one thread at a time.

#include <sys/types.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace plumb::v4l2 {

class V4l2Io {
  public:
    virtual ~V4l2Io() = default;
    virtual int open(const std::string& path, int flags) = 0;
    virtual int close(int fd) = 0;
    virtual int ioctl(int fd, unsigned long request, void* arg) = 0;
    virtual void* mmap(size_t length, int fd, off_t offset) = 0;  ///< shared, read-write
    virtual int munmap(void* address, size_t length) = 0;
    /// Waits for a buffer: 1 ready, 0 timeout, -ENODEV when the device is gone (POLLERR/POLLHUP).
    virtual int poll(int fd, int timeout_ms) = 0;
};

/// The real system calls (ioctl retried on EINTR).
std::shared_ptr<V4l2Io> systemIo();

/// An open descriptor, closed through its V4l2Io on destruction. Move-only.
class UniqueFd {
  public:
    UniqueFd() = default;
    UniqueFd(std::shared_ptr<V4l2Io> io, int fd) : io_(std::move(io)), fd_(fd) {}
    ~UniqueFd() { reset(); }
    UniqueFd(UniqueFd&& o) noexcept : io_(std::move(o.io_)), fd_(o.fd_) { o.fd_ = -1; }
    UniqueFd& operator=(UniqueFd&& o) noexcept {
        if (this != &o) {
            reset();
            io_ = std::move(o.io_);
            fd_ = o.fd_;
            o.fd_ = -1;
        }
        return *this;
    }
    UniqueFd(const UniqueFd&) = delete;
    UniqueFd& operator=(const UniqueFd&) = delete;

    int get() const { return fd_; }
    bool valid() const { return fd_ >= 0; }
    void reset() {
        if (fd_ >= 0 && io_) io_->close(fd_);
        fd_ = -1;
    }

  private:
    std::shared_ptr<V4l2Io> io_;
    int fd_ = -1;
};

/// One mmap'ed capture buffer, unmapped on destruction. Move-only.
class MappedBuffer {
  public:
    MappedBuffer() = default;
    MappedBuffer(std::shared_ptr<V4l2Io> io, void* address, size_t length)
        : io_(std::move(io)), address_(address), length_(length) {}
    ~MappedBuffer() { reset(); }
    MappedBuffer(MappedBuffer&& o) noexcept
        : io_(std::move(o.io_)), address_(o.address_), length_(o.length_) {
        o.address_ = nullptr;
    }
    MappedBuffer& operator=(MappedBuffer&& o) noexcept {
        if (this != &o) {
            reset();
            io_ = std::move(o.io_);
            address_ = o.address_;
            length_ = o.length_;
            o.address_ = nullptr;
        }
        return *this;
    }
    MappedBuffer(const MappedBuffer&) = delete;
    MappedBuffer& operator=(const MappedBuffer&) = delete;

    const uint8_t* data() const { return static_cast<const uint8_t*>(address_); }
    size_t length() const { return length_; }
    void reset() {
        if (address_ != nullptr && io_) io_->munmap(address_, length_);
        address_ = nullptr;
    }

  private:
    std::shared_ptr<V4l2Io> io_;
    void* address_ = nullptr;
    size_t length_ = 0;
};

}  // namespace plumb::v4l2
