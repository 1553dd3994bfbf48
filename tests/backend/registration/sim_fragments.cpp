// SPDX-License-Identifier: Apache-2.0
#include "tests/backend/registration/sim_fragments.hpp"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "device/fusion/fragment_builder.hpp"
#include "device/fusion/fuse_frames.hpp"
#include "drivers/sim/sim_source.hpp"
#include "messages/files.hpp"
#include "messages/fragment_codec.hpp"

namespace plumb::testing {

namespace {

std::filesystem::path cacheDir(const SimScanOptions& o) {
    std::ostringstream key;
    key << "v5-" << o.camera << "-" << o.voxel_size_m << "-" << o.truncation_m << "-" << o.scene
        << "-" << o.num_frames << "-" << o.rate_hz << "-" << o.frames_per_fragment << "-"
        << (o.loop ? "loop" : "open") << "-" << o.seed;
    return std::filesystem::temp_directory_path() / "plumb-registration-cache" / key.str();
}

Result<SimScan> generate(const SimScanOptions& o, std::vector<std::vector<uint8_t>>* encoded) {
    sim::SimConfig sc;
    sc.scene = o.scene;
    Result<PinholeCamera> camera = cameraPreset(o.camera);
    if (!camera.isOk()) return camera.status();
    sc.camera = camera.value();
    sc.trajectory.loop = o.loop;
    sc.trajectory.num_frames = o.num_frames;
    sc.trajectory.rate_hz = o.rate_hz;
    sc.seed = o.seed;
    PLUMB_RETURN_IF_ERROR(sim::parseNoiseMode("undistorted", &sc.noise));
    auto source = sim::SimSource::create(sc);
    if (!source.isOk()) return source.status();
    device::FusionConfig fc;
    fc.frames_per_fragment = o.frames_per_fragment;
    fc.tsdf.voxel_size_m = o.voxel_size_m;
    fc.tsdf.truncation_m = o.truncation_m;
    device::FragmentBuilder builder((*source)->camera(), fc);
    SimScan scan;
    std::vector<Fragment> raw;
    device::FuseHooks hooks;
    hooks.on_frame = [&](const Frame& frame, const device::FrameReport&) {
        io::StampedPose gt;
        gt.timestamp_s = frame.timestamp_s;
        gt.T_W_C = frame.T_W_C_gt.value_or(Eigen::Isometry3d::Identity());
        scan.gt_frames.push_back(gt);
        return Status::ok();
    };
    hooks.on_fragment = [&](Fragment f) {
        raw.push_back(std::move(f));
        return Status::ok();
    };
    Result<bool> fused = device::fuseFrames(**source, builder, hooks, o.num_frames);
    if (!fused.isOk()) return fused.status();
    for (const Fragment& f : raw) {
        // Round trip through the codec so fresh and cached runs are identical.
        auto bytes = messages::encodeFragment(f);
        if (!bytes.isOk()) return bytes.status();
        auto back = messages::decodeFragment(*bytes);
        if (!back.isOk()) return back.status();
        encoded->push_back(bytes.value());
        scan.fragments.push_back(std::move(back.value()));
    }
    return scan;
}

void fillGtFragmentPoses(SimScan* scan) {
    scan->gt_T_W_F.clear();
    for (const Fragment& f : scan->fragments) {
        const size_t k = static_cast<size_t>(f.frames.front().frame_index);
        scan->gt_T_W_F.push_back(scan->gt_frames.at(k).T_W_C);
    }
}

}  // namespace

Result<SimScan> simLoopScan(const SimScanOptions& options) {
    const std::filesystem::path dir = cacheDir(options);
    const std::filesystem::path done = dir / "complete";
    if (std::filesystem::exists(done)) {
        SimScan scan;
        auto gt = io::readTumTrajectory(dir / "gt.txt");
        if (gt.isOk()) {
            scan.gt_frames = std::move(gt.value());
            bool ok = true;
            for (size_t i = 0;; ++i) {
                const auto path = dir / ("fragment_" + std::to_string(i) + ".bin");
                if (!std::filesystem::exists(path)) break;
                auto bytes = messages::readFile(path, int64_t{1} << 30);
                if (!bytes.isOk()) {
                    ok = false;
                    break;
                }
                auto f = messages::decodeFragment(*bytes);
                if (!f.isOk()) {
                    ok = false;
                    break;
                }
                scan.fragments.push_back(std::move(f.value()));
            }
            if (ok && !scan.fragments.empty()) {
                fillGtFragmentPoses(&scan);
                return scan;
            }
        }
    }
    std::vector<std::vector<uint8_t>> encoded;
    Result<SimScan> scan = generate(options, &encoded);
    if (!scan.isOk()) return scan.status();
    fillGtFragmentPoses(&scan.value());
    // Best-effort cache (a failure to write only costs time). Written to a private directory
    // first and renamed, so concurrent test processes never read a partial cache.
    std::error_code ec;
    const std::filesystem::path tmp =
        dir.string() + ".tmp" + std::to_string(static_cast<long>(::getpid()));
    std::filesystem::create_directories(tmp, ec);
    if (!ec) {
        bool ok = io::writeTumTrajectory(tmp / "gt.txt", scan->gt_frames).isOk();
        for (size_t i = 0; ok && i < encoded.size(); ++i) {
            ok = messages::writeFileAtomic(tmp / ("fragment_" + std::to_string(i) + ".bin"),
                                           encoded[i])
                     .isOk();
        }
        if (ok) ok = messages::writeFileAtomic(tmp / "complete", std::vector<uint8_t>{'1'}).isOk();
        if (ok) {
            std::filesystem::create_directories(dir.parent_path(), ec);
            std::filesystem::rename(tmp, dir, ec);
        }
        std::filesystem::remove_all(tmp, ec);
    }
    return scan;
}

}  // namespace plumb::testing
