// SPDX-License-Identifier: Apache-2.0
#include "backend/ingest/raw_frame_store.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <deque>
#include <future>
#include <map>
#include <system_error>
#include <tuple>
#include <utility>

#include "common/core/logging.hpp"
#include "messages/conversions.hpp"
#include "messages/files.hpp"
#include "messages/fragment_sender.hpp"  // toUtime

namespace plumb::backend {
namespace {

namespace fs = std::filesystem;

constexpr const char* kSuffix = ".raw";
/// A raw frame message is at most a few megabytes (VGA depth and colour, losslessly coded).
constexpr int64_t kMaxFileBytes = int64_t{64} << 20;
/// Capture times of a fragment's frame and of its raw frame agree to the microsecond; this
/// allows for a codec that keeps them at millisecond precision.
constexpr int64_t kTimeToleranceUs = 1000;
/// Frames read and decoded ahead, each on its own thread: a frame's lossless colour decodes
/// serially (about 10 ms at VGA), so one reader alone would keep the integration waiting.
constexpr size_t kReadAhead = 3;

std::string fileName(int64_t utime, int64_t frame_index, std::optional<int64_t> session_id) {
    if (!session_id) return fmt::format("{:017d}_{:09d}{}", utime, frame_index, kSuffix);
    return fmt::format("{:017d}_{:09d}_s{}{}", utime, frame_index, *session_id, kSuffix);
}

/// The capture time, index and session (when named) of a file named by fileName.
bool parseFileName(const std::string& name, StoredRawFrame* f) {
    if (!name.ends_with(kSuffix)) return false;
    long long t = 0, i = 0, s = 0;
    int consumed = 0;
    if (std::sscanf(name.c_str(), "%lld_%lld%n", &t, &i, &consumed) != 2) return false;
    std::string rest = name.substr(static_cast<size_t>(consumed));
    std::optional<int64_t> session;
    if (rest != kSuffix) {
        int more = 0;
        if (std::sscanf(rest.c_str(), "_s%lld%n", &s, &more) != 1) return false;
        if (rest.substr(static_cast<size_t>(more)) != kSuffix) return false;
        session = s;
    }
    if (t < 0 || i < 0) return false;
    f->utime = t;
    f->frame_index = i;
    f->session_id = session;
    return true;
}

/// Capture time, then index, then session (frames of one instant from two sessions stay apart
/// in a fixed order).
bool inCaptureOrder(const StoredRawFrame& a, const StoredRawFrame& b) {
    return std::tuple(a.utime, a.frame_index, a.session_id) <
           std::tuple(b.utime, b.frame_index, b.session_id);
}

class RawFrameSource final : public FrameSource {
  public:
    RawFrameSource(std::vector<StoredRawFrame> frames, const PinholeCamera& camera,
                   std::function<bool()> stop_requested, RawFrameView view = {})
        : frames_(std::move(frames)),
          camera_(camera),
          stop_(std::move(stop_requested)),
          view_(std::move(view)) {}

    const PinholeCamera& camera() const override { return camera_; }
    std::optional<size_t> size() const override { return frames_.size(); }
    std::string description() const override {
        if (!view_.description.empty()) return view_.description;
        return fmt::format("{} stored raw frames ({}x{})", frames_.size(), camera_.width,
                           camera_.height);
    }

    Result<Frame> next() override {
        while (true) {
            if (stop_ && stop_()) return cancelled("stopped while reading the raw frames");
            while (ahead_.size() < kReadAhead && next_ < frames_.size()) {
                const StoredRawFrame* stored = &frames_[next_];
                const auto position = static_cast<int64_t>(next_++);
                ahead_.push_back(std::async(std::launch::async, [this, stored, position] {
                    return read(*stored, position);
                }));
            }
            if (ahead_.empty())
                return Status(StatusCode::kOutOfRange, "end of the stored raw frames");
            Result<Frame> frame = ahead_.front().get();
            ahead_.pop_front();
            if (frame.isOk()) return frame;
            log::warn("final model: raw frame left out: {}", frame.status().message());
        }
    }

    Status skip() override {
        if (!ahead_.empty()) {
            ahead_.front().wait();
            ahead_.pop_front();
            return Status::ok();
        }
        if (next_ >= frames_.size())
            return Status(StatusCode::kOutOfRange, "end of the stored raw frames");
        ++next_;
        return Status::ok();
    }

  private:
    /// Thread-safe: reads only `stored` and the camera.
    Result<Frame> read(const StoredRawFrame& stored, int64_t position) const {
        const std::string name = stored.path.filename().string();
        auto bytes = messages::readFile(stored.path, kMaxFileBytes);
        if (!bytes.isOk()) return bytes.status();
        auto raw = messages::decodeRawFrame(*bytes);
        if (!raw.isOk()) return Status(raw.status().code(), name + ": " + raw.status().message());
        if (raw->depth.width() != camera_.width || raw->depth.height() != camera_.height) {
            return Status(
                StatusCode::kInvalidArgument,
                fmt::format("{}: {}x{} depth, the camera is {}x{}", name, raw->depth.width(),
                            raw->depth.height(), camera_.width, camera_.height));
        }
        Frame frame;
        frame.index = view_.renumber ? position : raw->frame_index;
        frame.timestamp_s = static_cast<double>(raw->utime) * 1e-6;
        frame.depth = toMetres(raw->depth, raw->depth_scale);
        if (view_.colour) frame.colour = std::move(raw->colour);
        frame.name = view_.renumber ? fmt::format("capture frame {}", raw->frame_index) : name;
        return frame;
    }

    std::vector<StoredRawFrame> frames_;
    PinholeCamera camera_;
    std::function<bool()> stop_;
    RawFrameView view_;
    size_t next_ = 0;                               ///< the next frame to start reading
    std::deque<std::future<Result<Frame>>> ahead_;  ///< frames being read, in order
};

}  // namespace

fs::path rawFramesDir(const fs::path& fragments_dir) { return fragments_dir / "raw_frames"; }

Result<std::unique_ptr<RawFrameStore>> RawFrameStore::open(const fs::path& dir) {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) {
        return Status(StatusCode::kIoError,
                      fmt::format("raw frames: cannot create {}: {}", dir.string(), ec.message()));
    }
    std::vector<fs::path> leftovers;
    for (const auto& item : fs::directory_iterator(dir, ec)) {
        if (item.path().filename().string().ends_with(messages::kTempSuffix))
            leftovers.push_back(item.path());
    }
    if (ec) {
        return Status(StatusCode::kIoError,
                      fmt::format("raw frames: cannot list {}: {}", dir.string(), ec.message()));
    }
    for (const fs::path& p : leftovers) fs::remove(p, ec);  // an interrupted write
    return std::unique_ptr<RawFrameStore>(new RawFrameStore(dir));
}

Status RawFrameStore::put(int64_t utime, int64_t frame_index,
                          std::span<const uint8_t> message_bytes,
                          std::optional<int64_t> session_id) {
    if (utime < 0 || frame_index < 0) {
        return Status(
            StatusCode::kInvalidArgument,
            fmt::format("raw frames: negative capture time {} or index {}", utime, frame_index));
    }
    const fs::path path = dir_ / fileName(utime, frame_index, session_id);
    const fs::path tmp = fs::path(path.string() + messages::kTempSuffix);
    std::FILE* f = std::fopen(tmp.c_str(), "wb");
    if (f == nullptr) {
        return Status(StatusCode::kIoError, fmt::format("raw frames: cannot create {}: {}",
                                                        tmp.string(), std::strerror(errno)));
    }
    const size_t written = std::fwrite(message_bytes.data(), 1, message_bytes.size(), f);
    const int write_errno = errno;
    const bool closed = std::fclose(f) == 0;
    if (written != message_bytes.size() || !closed) {
        std::error_code ec;
        fs::remove(tmp, ec);
        return Status(
            StatusCode::kIoError,
            fmt::format("raw frames: cannot write {}: {}", tmp.string(),
                        std::strerror(written != message_bytes.size() ? write_errno : errno)));
    }
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) {
        fs::remove(tmp, ec);
        return Status(StatusCode::kIoError,
                      fmt::format("raw frames: cannot rename {}: {}", tmp.string(), ec.message()));
    }
    return Status::ok();
}

Result<std::vector<StoredRawFrame>> listRawFrames(const fs::path& dir) {
    std::vector<StoredRawFrame> out;
    std::error_code ec;
    if (!fs::exists(dir, ec)) return out;
    for (const auto& item : fs::directory_iterator(dir, ec)) {
        StoredRawFrame f;
        if (!parseFileName(item.path().filename().string(), &f)) continue;
        f.path = item.path();
        out.push_back(std::move(f));
    }
    if (ec) {
        return Status(StatusCode::kIoError,
                      fmt::format("raw frames: cannot list {}: {}", dir.string(), ec.message()));
    }
    std::sort(out.begin(), out.end(), inCaptureOrder);
    return out;
}

RawFrameCoverage rawFrameCoverage(const std::vector<StoredRawFrame>& stored,
                                  const std::vector<Fragment>& fragments,
                                  std::optional<int64_t> session_id) {
    std::multimap<int64_t, const StoredRawFrame*> by_index;
    for (const StoredRawFrame& f : stored) {
        if (session_id && f.session_id && *f.session_id != *session_id) continue;
        by_index.emplace(f.frame_index, &f);
    }
    RawFrameCoverage c;
    c.min_fragment_share = fragments.empty() ? 0.0 : 1.0;
    for (const Fragment& fragment : fragments) {
        size_t tracked = 0, matched = 0;
        for (const FragmentFrame& frame : fragment.frames) {
            if (!frame.tracking_ok) continue;
            ++tracked;
            const int64_t utime = messages::toUtime(frame.timestamp_s);
            // The frame that names the session rather than one that names none (an older
            // device's at the same instant).
            const StoredRawFrame* best = nullptr;
            auto [begin, end] = by_index.equal_range(frame.frame_index);
            for (auto it = begin; it != end; ++it) {
                if (std::abs(it->second->utime - utime) > kTimeToleranceUs) continue;
                if (best == nullptr || (!best->session_id && it->second->session_id))
                    best = it->second;
            }
            if (best != nullptr) {
                c.frames.push_back(*best);
                ++matched;
            }
        }
        c.tracked_frames += tracked;
        c.matched += matched;
        const double share =
            tracked == 0 ? 1.0 : static_cast<double>(matched) / static_cast<double>(tracked);
        if (share < c.min_fragment_share) {
            c.min_fragment_share = share;
            c.min_fragment_id = fragment.id;
        }
    }
    std::sort(c.frames.begin(), c.frames.end(), inCaptureOrder);
    std::map<int64_t, size_t> steps;  // ordered: the smaller step wins a tie
    for (size_t k = 1; k < c.frames.size(); ++k) {
        const int64_t step = c.frames[k].frame_index - c.frames[k - 1].frame_index;
        if (step > 0) ++steps[step];
    }
    size_t most = 0;
    for (const auto& [step, count] : steps) {
        if (count > most) {
            most = count;
            c.stride = step;
        }
    }
    return c;
}

std::unique_ptr<FrameSource> openRawFrameSource(std::vector<StoredRawFrame> frames,
                                                const PinholeCamera& camera,
                                                std::function<bool()> stop_requested,
                                                RawFrameView view) {
    return std::make_unique<RawFrameSource>(std::move(frames), camera, std::move(stop_requested),
                                            std::move(view));
}

}  // namespace plumb::backend
