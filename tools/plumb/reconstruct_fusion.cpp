// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/reconstruct_fusion.hpp"

#include <fmt/format.h>

#include <cmath>
#include <utility>

#include "common/core/logging.hpp"
#include "common/core/progress.hpp"
#include "common/io/state_archive.hpp"
#include "device/fusion/fuse_frames.hpp"
#include "messages/files.hpp"
#include "messages/fragment_codec.hpp"

namespace plumb::tools {
namespace fs = std::filesystem;
namespace {

constexpr uint32_t kCheckpointMagic = 0x43465250u;  // "PRFC"
constexpr uint32_t kCheckpointVersion = 1;
constexpr int64_t kMaxCheckpointBytes = int64_t{1} << 34;

fs::path checkpointPath(const fs::path& out) { return out / "resume" / "fusion_state.bin"; }

void saveTrajectory(io::StateWriter& w, const io::Trajectory& t) {
    w.value<uint64_t>(t.size());
    for (const io::StampedPose& p : t) {
        w.value(p.timestamp_s);
        w.pose(p.T_W_C);
    }
}

bool loadTrajectory(io::StateReader& r, io::Trajectory* t) {
    uint64_t n = 0;
    if (!r.value(&n) || n > (uint64_t{1} << 32)) return false;
    t->resize(n);
    for (io::StampedPose& p : *t) {
        if (!r.value(&p.timestamp_s) || !r.pose(&p.T_W_C)) return false;
    }
    return true;
}

}  // namespace

FusionPass::FusionPass(fs::path out, const PinholeCamera& camera,
                       const device::FusionConfig& config, double frame_step)
    : out_(std::move(out)), builder_(camera, config), frame_step_(frame_step) {}

Result<std::unique_ptr<FusionPass>> FusionPass::start(const fs::path& out,
                                                      const PinholeCamera& camera,
                                                      const device::FusionConfig& config,
                                                      double frame_step) {
    std::unique_ptr<FusionPass> pass(new FusionPass(out, camera, config, frame_step));
    Result<std::unique_ptr<messages::FragmentStore>> store =
        messages::FragmentStore::open(out / "fragments");
    if (!store.isOk()) return store.status();
    if (!(*store)->fragments().empty()) {
        return failedPrecondition(
            fmt::format("{} already holds fragments", (out / "fragments").string()));
    }
    pass->store_ = std::move(*store);
    return pass;
}

Result<std::unique_ptr<FusionPass>> FusionPass::resume(const fs::path& out, FrameSource& source,
                                                       const PinholeCamera& camera,
                                                       const device::FusionConfig& config,
                                                       double frame_step) {
    Result<std::vector<uint8_t>> bytes =
        messages::readFile(checkpointPath(out), kMaxCheckpointBytes);
    if (!bytes.isOk()) return bytes.status();
    std::unique_ptr<FusionPass> pass(new FusionPass(out, camera, config, frame_step));
    io::StateReader r(*bytes);
    uint32_t magic = 0, version = 0;
    uint8_t finished = 0;
    double step = 0.0;
    std::vector<uint8_t> builder;
    const bool ok = r.value(&magic) && magic == kCheckpointMagic && r.value(&version) &&
                    version == kCheckpointVersion && r.value(&step) && r.value(&finished) &&
                    r.value(&pass->counts_) && r.value(&pass->stored_) &&
                    loadTrajectory(r, &pass->poses_read_) && loadTrajectory(r, &pass->tracked_) &&
                    r.array(&builder) && r.atEnd();
    const std::string what = checkpointPath(out).string();
    if (!ok) return corrupt(what + ": not a plumb fusion checkpoint, or damaged");
    if (step != frame_step) return corrupt(what + ": saved with another --frame-step");
    pass->finished_ = finished != 0;
    if (!pass->finished_) {
        if (Status s = pass->builder_.restoreState(builder); !s.isOk()) {
            return prefixed(s, what);
        }
    }
    Result<std::unique_ptr<messages::FragmentStore>> store =
        messages::FragmentStore::open(out / "fragments");
    if (!store.isOk()) return store.status();
    pass->store_ = std::move(*store);
    for (uint32_t id = 0; id < pass->stored_; ++id) {
        if (!pass->store_->contains(kReconstructSession, id)) {
            return corrupt(fmt::format("{}: fragment {} of the checkpoint is missing",
                                       (out / "fragments").string(), id));
        }
    }
    if (pass->store_->fragments().size() != pass->stored_) {
        return corrupt(fmt::format("{} holds {} fragments, the checkpoint {}",
                                   (out / "fragments").string(), pass->store_->fragments().size(),
                                   pass->stored_));
    }
    if (!pass->finished_) {
        for (uint64_t i = 0; i < pass->counts_.read; ++i) {
            if (Status s = source.skip(); !s.isOk()) {
                return prefixed(s, fmt::format("moving the source to frame {} of the "
                                               "interrupted run",
                                               pass->counts_.read));
            }
        }
    }
    return pass;
}

Status FusionPass::store(Fragment f) {
    if (f.points_F.points.empty()) {
        log::warn("fragment {} has no surface points; dropped", f.id);
        return Status::ok();
    }
    f.id = stored_;
    Result<std::vector<uint8_t>> bytes = messages::encodeFragment(f);
    if (!bytes.isOk()) return prefixed(bytes.status(), fmt::format("encoding fragment {}", f.id));
    Result<bool> put = store_->put(kReconstructSession, f.id, *bytes);
    if (!put.isOk()) return prefixed(put.status(), fmt::format("storing fragment {}", f.id));
    ++stored_;
    return Status::ok();
}

Result<bool> FusionPass::run(FrameSource& source, const std::function<bool()>& stop, bool quiet) {
    if (finished_) return true;
    ProgressOptions po;
    if (quiet) po.mode = ProgressOptions::Mode::kQuiet;
    po.unit = "frames";
    Progress progress("tracking and fusing", source.size().value_or(0), po);
    progress.advance(counts_.read);
    device::FuseHooks hooks;
    hooks.stop = [&stop] { return stop && stop(); };
    hooks.keep = [this, &progress](const Frame& frame) {
        if (frame.T_W_C_gt) poses_read_.push_back({frame.timestamp_s, *frame.T_W_C_gt});
        const uint64_t position = counts_.read++;
        const auto due =
            static_cast<uint64_t>(std::floor(static_cast<double>(counts_.fused) * frame_step_));
        progress.advance();
        if (position != due) return false;  // dropped, as a device keeping up with 1 / frame_step
        ++counts_.fused;
        return true;
    };
    hooks.on_frame = [this](const Frame& frame, const device::FrameReport& report) {
        if (report.tracked) {
            tracked_.push_back({frame.timestamp_s, report.T_W_C});
        } else {
            ++counts_.lost;
        }
        return Status::ok();
    };
    hooks.on_fragment = [this](Fragment f) { return store(std::move(f)); };
    Result<bool> ran = device::fuseFrames(source, builder_, hooks);
    if (!ran.isOk() || !*ran) return ran;
    progress.finish();
    finished_ = true;
    if (counts_.lost > 0) {
        log::warn("tracking failed on {} frames (their fragments were closed early)", counts_.lost);
    }
    if (stored_ == 0) return failedPrecondition("the scan produced no fragment with a surface");
    return true;
}

Status FusionPass::checkpoint() const {
    io::StateWriter w;
    w.value(kCheckpointMagic);
    w.value(kCheckpointVersion);
    w.value(frame_step_);
    w.value<uint8_t>(finished_ ? 1 : 0);
    w.value(counts_);
    w.value(stored_);
    saveTrajectory(w, poses_read_);
    saveTrajectory(w, tracked_);
    w.array(finished_ ? std::vector<uint8_t>{} : builder_.saveState());
    std::error_code ec;
    fs::create_directories(out_ / "resume", ec);
    if (ec)
        return ioError(
            fmt::format("{}: cannot create: {}", (out_ / "resume").string(), ec.message()));
    return messages::writeFileAtomic(checkpointPath(out_), w.bytes());
}

Result<std::vector<Fragment>> FusionPass::fragments() const {
    std::vector<Fragment> out;
    out.reserve(stored_);
    for (uint32_t id = 0; id < stored_; ++id) {
        Result<std::vector<uint8_t>> bytes = store_->get(kReconstructSession, id);
        if (!bytes.isOk()) return bytes.status();
        Result<Fragment> f = messages::decodeFragment(*bytes);
        if (!f.isOk()) return prefixed(f.status(), fmt::format("stored fragment {}", id));
        out.push_back(std::move(*f));
    }
    return out;
}

}  // namespace plumb::tools
