// SPDX-License-Identifier: Apache-2.0
#pragma once

// Recorded V4L2 sessions and a V4l2Io that replays them, so the V4L2 source runs in CI against
// what a camera delivered: the formats it offered, its negotiated format and every dequeued
// buffer (bytes, bytesused, sequence, timestamp, flags), plus an unplug. RecordingIo wraps a real
// V4l2Io and captures such a session from a live camera; saveRecording/loadRecording store it
// (".v4l2rec": a small binary header, then the buffers).
//
// ReplayIo models a UVC node: QUERYCAP, ENUM_FMT, S_FMT (grants only the recorded format and
// size, like a driver, and reports the recorded stride/size), S_PARM, REQBUFS/QUERYBUF/mmap,
// QBUF/DQBUF (each DQBUF copies the next recorded buffer into a queued mmap buffer), STREAMON/OFF
// and poll. After `unplug_after` buffers every call on an open descriptor fails with ENODEV and
// open() fails with ENOENT, until `replug_after_opens` failed opens have passed; then the node
// reappears and the remaining buffers follow. It counts open descriptors and mappings so tests
// can check that the source released everything.
//
// Not thread-safe: a ReplayIo or RecordingIo serves one V4L2 source (one thread at a time), as
// the V4L2 source uses its V4l2Io. saveRecording and loadRecording keep no state.

#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <vector>

#include "common/core/status.hpp"
#include "drivers/v4l2/v4l2_io.hpp"

namespace plumb::v4l2 {

struct RecordedBuffer {
    std::vector<uint8_t> bytes;  ///< the buffer's first bytesused bytes (or fewer, when damaged)
    uint32_t bytesused = 0;
    uint32_t sequence = 0;
    uint64_t timestamp_us = 0;
    uint32_t flags = 0;
};

struct V4l2Recording {
    std::string path = "/dev/video0";  ///< node the session came from
    std::string card = "Recorded depth camera";
    std::vector<uint32_t> formats;  ///< what ENUM_FMT listed, in order
    uint32_t pixelformat = 0;       ///< negotiated format
    uint32_t width = 0;
    uint32_t height = 0;
    uint32_t bytesperline = 0;
    uint32_t sizeimage = 0;
    std::vector<RecordedBuffer> buffers;
};

Status saveRecording(const V4l2Recording& recording, const std::filesystem::path& file);
Result<V4l2Recording> loadRecording(const std::filesystem::path& file);

class ReplayIo final : public V4l2Io {
  public:
    explicit ReplayIo(V4l2Recording recording) : rec_(std::move(recording)) {}

    /// The node vanishes after this many buffers were dequeued (-1 = never)...
    void setUnplugAfter(int64_t buffers) { unplug_after_ = buffers; }
    /// ... and comes back after this many failed open() attempts.
    void setReplugAfterOpens(int opens) { replug_after_opens_ = opens; }

    int open(const std::string& path, int flags) override;
    int close(int fd) override;
    int ioctl(int fd, unsigned long request, void* arg) override;
    void* mmap(size_t length, int fd, off_t offset) override;
    int munmap(void* address, size_t length) override;
    int poll(int fd, int timeout_ms) override;

    int openDescriptors() const;
    int mappings() const;
    size_t delivered() const { return next_buffer_; }
    bool unplugged() const { return unplugged_; }

  private:
    bool stale(int fd) const;
    mutable std::mutex mutex_;
    V4l2Recording rec_;
    int64_t unplug_after_ = -1;
    int replug_after_opens_ = 1;
    bool unplugged_ = false;
    int failed_opens_ = 0;
    int generation_ = 0;  ///< bumps on unplug: older descriptors stay dead
    int next_fd_ = 100;
    std::map<int, int> fds_;  ///< fd -> generation
    std::vector<std::vector<uint8_t>> pool_;
    std::vector<bool> queued_;
    int mapped_ = 0;
    bool streaming_ = false;
    size_t next_buffer_ = 0;
};

/// Passes every call to `inner` and records the session (formats, format, dequeued buffers).
class RecordingIo final : public V4l2Io {
  public:
    explicit RecordingIo(std::shared_ptr<V4l2Io> inner) : inner_(std::move(inner)) {}
    const V4l2Recording& recording() const { return rec_; }

    int open(const std::string& path, int flags) override;
    int close(int fd) override { return inner_->close(fd); }
    int ioctl(int fd, unsigned long request, void* arg) override;
    void* mmap(size_t length, int fd, off_t offset) override;
    int munmap(void* address, size_t length) override { return inner_->munmap(address, length); }
    int poll(int fd, int timeout_ms) override { return inner_->poll(fd, timeout_ms); }

  private:
    std::shared_ptr<V4l2Io> inner_;
    V4l2Recording rec_;
    std::map<uint32_t, uint32_t> offset_of_index_;
    std::map<uint32_t, const uint8_t*> address_of_offset_;
};

}  // namespace plumb::v4l2
