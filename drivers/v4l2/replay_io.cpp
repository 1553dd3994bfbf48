// SPDX-License-Identifier: Apache-2.0
#include "drivers/v4l2/replay_io.hpp"

#include <linux/videodev2.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>

namespace plumb::v4l2 {
namespace {

constexpr char kMagic[8] = {'P', 'L', 'V', '4', 'L', '2', 'R', '1'};
constexpr uint32_t kPage = 4096;

template <typename T>
void put(std::ostream& out, const T& v) {
    out.write(reinterpret_cast<const char*>(&v), sizeof(T));
}
template <typename T>
bool get(std::istream& in, T* v) {
    return static_cast<bool>(in.read(reinterpret_cast<char*>(v), sizeof(T)));
}
void putString(std::ostream& out, const std::string& s) {
    put(out, static_cast<uint32_t>(s.size()));
    out.write(s.data(), static_cast<std::streamsize>(s.size()));
}
bool getString(std::istream& in, std::string* s, uint32_t max) {
    uint32_t n = 0;
    if (!get(in, &n) || n > max) return false;
    s->resize(n);
    return static_cast<bool>(in.read(s->data(), n));
}

}  // namespace

Status saveRecording(const V4l2Recording& r, const std::filesystem::path& file) {
    std::ofstream out(file, std::ios::binary | std::ios::trunc);
    if (!out) return ioError("cannot write V4L2 recording '" + file.string() + "'");
    out.write(kMagic, sizeof(kMagic));
    putString(out, r.path);
    putString(out, r.card);
    put(out, static_cast<uint32_t>(r.formats.size()));
    for (uint32_t f : r.formats) put(out, f);
    put(out, r.pixelformat);
    put(out, r.width);
    put(out, r.height);
    put(out, r.bytesperline);
    put(out, r.sizeimage);
    put(out, static_cast<uint32_t>(r.buffers.size()));
    for (const auto& b : r.buffers) {
        put(out, b.bytesused);
        put(out, b.sequence);
        put(out, b.timestamp_us);
        put(out, b.flags);
        put(out, static_cast<uint32_t>(b.bytes.size()));
        out.write(reinterpret_cast<const char*>(b.bytes.data()),
                  static_cast<std::streamsize>(b.bytes.size()));
    }
    if (!out) return ioError("writing V4L2 recording '" + file.string() + "' failed");
    return Status::ok();
}

Result<V4l2Recording> loadRecording(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    if (!in) return notFound("V4L2 recording '" + file.string() + "' cannot be opened");
    const auto bad = [&](const std::string& what) {
        return corrupt("V4L2 recording '" + file.string() + "': " + what);
    };
    char magic[8] = {};
    if (!in.read(magic, sizeof(magic)) || std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) {
        return bad("not a plumb V4L2 recording (bad magic)");
    }
    V4l2Recording r;
    uint32_t n = 0;
    if (!getString(in, &r.path, 4096) || !getString(in, &r.card, 4096) || !get(in, &n) || n > 256) {
        return bad("truncated header");
    }
    r.formats.resize(n);
    for (auto& f : r.formats) {
        if (!get(in, &f)) return bad("truncated format list");
    }
    if (!get(in, &r.pixelformat) || !get(in, &r.width) || !get(in, &r.height) ||
        !get(in, &r.bytesperline) || !get(in, &r.sizeimage) || !get(in, &n)) {
        return bad("truncated format");
    }
    if (r.width > 16384 || r.height > 16384 || r.sizeimage > (1u << 28)) {
        return bad("implausible format " + std::to_string(r.width) + "x" +
                   std::to_string(r.height));
    }
    r.buffers.resize(n);
    for (uint32_t i = 0; i < n; ++i) {
        RecordedBuffer& b = r.buffers[i];
        uint32_t size = 0;
        if (!get(in, &b.bytesused) || !get(in, &b.sequence) || !get(in, &b.timestamp_us) ||
            !get(in, &b.flags) || !get(in, &size) || size > (1u << 28)) {
            return bad("truncated buffer " + std::to_string(i));
        }
        b.bytes.resize(size);
        if (!in.read(reinterpret_cast<char*>(b.bytes.data()), size)) {
            return bad("truncated data of buffer " + std::to_string(i));
        }
    }
    return r;
}

// ---- ReplayIo ----------------------------------------------------------------------------------

bool ReplayIo::stale(int fd) const {
    auto it = fds_.find(fd);
    return it == fds_.end() || it->second != generation_ || unplugged_;
}

int ReplayIo::open(const std::string& path, int /*flags*/) {
    std::lock_guard lock(mutex_);
    if (path != rec_.path) return -ENOENT;
    if (unplugged_) {
        if (++failed_opens_ < replug_after_opens_) return -ENOENT;
        unplugged_ = false;  // the camera is back (same node, as udev usually gives it)
        failed_opens_ = 0;
        return -ENOENT;  // this attempt still raced the re-enumeration
    }
    const int fd = next_fd_++;
    fds_[fd] = generation_;
    return fd;
}

int ReplayIo::close(int fd) {
    std::lock_guard lock(mutex_);
    if (fds_.erase(fd) == 0) return -EBADF;
    if (fds_.empty()) {
        streaming_ = false;
    }
    return 0;
}

int ReplayIo::ioctl(int fd, unsigned long request, void* arg) {
    std::lock_guard lock(mutex_);
    if (fds_.count(fd) == 0) return -EBADF;
    if (stale(fd)) return -ENODEV;
    switch (request) {
        case VIDIOC_QUERYCAP: {
            auto* cap = static_cast<v4l2_capability*>(arg);
            *cap = {};
            std::snprintf(reinterpret_cast<char*>(cap->driver), sizeof(cap->driver), "uvcvideo");
            std::snprintf(reinterpret_cast<char*>(cap->card), sizeof(cap->card), "%s",
                          rec_.card.c_str());
            cap->device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING;
            cap->capabilities = cap->device_caps | V4L2_CAP_DEVICE_CAPS;
            return 0;
        }
        case VIDIOC_ENUM_FMT: {
            auto* d = static_cast<v4l2_fmtdesc*>(arg);
            if (d->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || d->index >= rec_.formats.size()) {
                return -EINVAL;
            }
            d->pixelformat = rec_.formats[d->index];
            return 0;
        }
        case VIDIOC_G_FMT:
        case VIDIOC_S_FMT:
        case VIDIOC_TRY_FMT: {
            // Like a driver with one mode: whatever is asked, the recorded format is granted.
            auto* f = static_cast<v4l2_format*>(arg);
            if (f->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return -EINVAL;
            if (request == VIDIOC_S_FMT && streaming_) return -EBUSY;
            f->fmt.pix.pixelformat = rec_.pixelformat;
            f->fmt.pix.width = rec_.width;
            f->fmt.pix.height = rec_.height;
            f->fmt.pix.bytesperline = rec_.bytesperline;
            f->fmt.pix.sizeimage = rec_.sizeimage;
            f->fmt.pix.field = V4L2_FIELD_NONE;
            return 0;
        }
        case VIDIOC_S_PARM:
        case VIDIOC_G_PARM:
            return 0;
        case VIDIOC_REQBUFS: {
            auto* req = static_cast<v4l2_requestbuffers*>(arg);
            if (req->memory != V4L2_MEMORY_MMAP) return -EINVAL;
            if (streaming_) return -EBUSY;
            if (req->count > 0 && mapped_ > 0) return -EBUSY;
            req->count = std::min<uint32_t>(req->count, 8);
            const uint32_t length = (std::max(rec_.sizeimage, 1u) + kPage - 1) / kPage * kPage;
            pool_.assign(req->count, std::vector<uint8_t>(length, 0));
            queued_.assign(req->count, false);
            return 0;
        }
        case VIDIOC_QUERYBUF: {
            auto* b = static_cast<v4l2_buffer*>(arg);
            if (b->index >= pool_.size()) return -EINVAL;
            b->length = static_cast<uint32_t>(pool_[b->index].size());
            b->m.offset = b->index * static_cast<uint32_t>(pool_[0].size());
            return 0;
        }
        case VIDIOC_QBUF: {
            auto* b = static_cast<v4l2_buffer*>(arg);
            if (b->index >= pool_.size() || queued_[b->index]) return -EINVAL;
            queued_[b->index] = true;
            return 0;
        }
        case VIDIOC_STREAMON:
            if (pool_.empty()) return -EINVAL;
            streaming_ = true;
            return 0;
        case VIDIOC_STREAMOFF:
            streaming_ = false;
            std::fill(queued_.begin(), queued_.end(), false);
            return 0;
        case VIDIOC_DQBUF: {
            if (!streaming_) return -EINVAL;
            if (next_buffer_ >= rec_.buffers.size()) return -EAGAIN;
            size_t slot = pool_.size();
            for (size_t i = 0; i < pool_.size(); ++i) {
                if (queued_[i]) {
                    slot = i;
                    break;
                }
            }
            if (slot == pool_.size()) return -EAGAIN;
            const RecordedBuffer& r = rec_.buffers[next_buffer_++];
            queued_[slot] = false;
            std::vector<uint8_t>& dst = pool_[slot];
            std::fill(dst.begin(), dst.end(), 0);
            std::memcpy(dst.data(), r.bytes.data(), std::min(dst.size(), r.bytes.size()));
            auto* b = static_cast<v4l2_buffer*>(arg);
            b->index = static_cast<uint32_t>(slot);
            b->bytesused = std::min<uint32_t>(r.bytesused, static_cast<uint32_t>(dst.size()));
            b->sequence = r.sequence;
            b->flags = r.flags | V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
            b->timestamp.tv_sec = static_cast<time_t>(r.timestamp_us / 1000000);
            b->timestamp.tv_usec = static_cast<suseconds_t>(r.timestamp_us % 1000000);
            if (unplug_after_ >= 0 && static_cast<int64_t>(next_buffer_) >= unplug_after_ &&
                !unplugged_ && generation_ == 0) {
                // The camera is pulled right after this buffer: the next call sees ENODEV.
                unplugged_ = true;
                ++generation_;
                streaming_ = false;  // a re-enumerated node starts fresh
            }
            return 0;
        }
        default:
            return -ENOTTY;
    }
}

void* ReplayIo::mmap(size_t length, int fd, off_t offset) {
    std::lock_guard lock(mutex_);
    if (stale(fd) || pool_.empty()) return nullptr;
    const size_t index = static_cast<size_t>(offset) / pool_[0].size();
    if (index >= pool_.size() || length > pool_[index].size()) return nullptr;
    ++mapped_;
    return pool_[index].data();
}

int ReplayIo::munmap(void* /*address*/, size_t /*length*/) {
    std::lock_guard lock(mutex_);
    if (mapped_ == 0) return -EINVAL;
    --mapped_;
    return 0;
}

int ReplayIo::poll(int fd, int /*timeout_ms*/) {
    std::lock_guard lock(mutex_);
    if (fds_.count(fd) == 0) return -EBADF;
    if (stale(fd)) return -ENODEV;
    if (next_buffer_ >= rec_.buffers.size()) return 0;  // the camera has nothing more: timeout
    return 1;
}

int ReplayIo::openDescriptors() const {
    std::lock_guard lock(mutex_);
    return static_cast<int>(fds_.size());
}

int ReplayIo::mappings() const {
    std::lock_guard lock(mutex_);
    return mapped_;
}

// ---- RecordingIo -------------------------------------------------------------------------------

int RecordingIo::open(const std::string& path, int flags) {
    const int fd = inner_->open(path, flags);
    if (fd >= 0) rec_.path = path;
    return fd;
}

void* RecordingIo::mmap(size_t length, int fd, off_t offset) {
    void* p = inner_->mmap(length, fd, offset);
    if (p != nullptr) address_of_offset_[static_cast<uint32_t>(offset)] = static_cast<uint8_t*>(p);
    return p;
}

int RecordingIo::ioctl(int fd, unsigned long request, void* arg) {
    const int r = inner_->ioctl(fd, request, arg);
    if (r < 0) return r;
    switch (request) {
        case VIDIOC_QUERYCAP: {
            const auto* cap = static_cast<const v4l2_capability*>(arg);
            rec_.card = std::string(reinterpret_cast<const char*>(cap->card),
                                    strnlen(reinterpret_cast<const char*>(cap->card), 32));
            break;
        }
        case VIDIOC_ENUM_FMT: {
            const auto* d = static_cast<const v4l2_fmtdesc*>(arg);
            if (d->index == 0) rec_.formats.clear();
            rec_.formats.push_back(d->pixelformat);
            break;
        }
        case VIDIOC_S_FMT: {
            const auto& pix = static_cast<const v4l2_format*>(arg)->fmt.pix;
            rec_.pixelformat = pix.pixelformat;
            rec_.width = pix.width;
            rec_.height = pix.height;
            rec_.bytesperline = pix.bytesperline;
            rec_.sizeimage = pix.sizeimage;
            break;
        }
        case VIDIOC_QUERYBUF: {
            const auto* b = static_cast<const v4l2_buffer*>(arg);
            offset_of_index_[b->index] = b->m.offset;
            break;
        }
        case VIDIOC_DQBUF: {
            const auto* b = static_cast<const v4l2_buffer*>(arg);
            RecordedBuffer rb;
            rb.bytesused = b->bytesused;
            rb.sequence = b->sequence;
            rb.flags = b->flags & ~V4L2_BUF_FLAG_TIMESTAMP_MASK;
            rb.timestamp_us = static_cast<uint64_t>(b->timestamp.tv_sec) * 1000000ULL +
                              static_cast<uint64_t>(b->timestamp.tv_usec);
            auto off = offset_of_index_.find(b->index);
            if (off != offset_of_index_.end()) {
                auto addr = address_of_offset_.find(off->second);
                if (addr != address_of_offset_.end()) {
                    rb.bytes.assign(addr->second, addr->second + b->bytesused);
                }
            }
            rec_.buffers.push_back(std::move(rb));
            break;
        }
        default:
            break;
    }
    return r;
}

}  // namespace plumb::v4l2
