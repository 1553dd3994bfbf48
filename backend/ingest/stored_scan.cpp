// SPDX-License-Identifier: Apache-2.0
#include "backend/ingest/stored_scan.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <set>
#include <utility>
#include <vector>

#include "backend/ingest/ingestor.hpp"
#include "backend/ingest/raw_frame_store.hpp"
#include "messages/fragment_sender.hpp"  // toUtime
#include "messages/fragment_store.hpp"

namespace plumb::backend {

namespace fs = std::filesystem;

Result<StoredScan> openStoredScan(const fs::path& fragments_dir, const StoredScanOptions& options) {
    std::error_code ec;
    if (!fs::is_directory(fragments_dir, ec)) {
        return Status(StatusCode::kNotFound,
                      fmt::format("no fragment store at {}", fragments_dir.string()));
    }
    // Read-only: a live backend may be writing the store (its temporary files stay).
    auto store = messages::FragmentStore::openReadOnly(fragments_dir);
    if (!store.isOk()) return store.status();
    StoredScan scan;
    std::set<int64_t> wanted;
    if (options.session) wanted.insert(*options.session);
    auto session = chooseSession(**store, wanted, &scan.note);
    if (!session.isOk()) return session.status();
    scan.session = *session;
    auto fragments = loadStoredFragments(**store, *session);
    if (!fragments.isOk()) return fragments.status();
    // The session's capture-time span, a second either side.
    double first_s = std::numeric_limits<double>::infinity(), last_s = -first_s;
    for (const Fragment& fragment : *fragments) {
        for (const FragmentFrame& frame : fragment.frames) {
            first_s = std::min(first_s, frame.timestamp_s);
            last_s = std::max(last_s, frame.timestamp_s);
        }
    }
    auto stored = listRawFrames(rawFramesDir(fragments_dir));
    if (!stored.isOk()) return stored.status();
    std::vector<StoredRawFrame> frames;
    if (first_s <= last_s) {  // the session has frames
        const int64_t from = messages::toUtime(first_s - 1.0), to = messages::toUtime(last_s + 1.0);
        for (const StoredRawFrame& f : *stored) {
            if (f.session_id && *f.session_id != *session) continue;  // another session's
            if (f.utime >= from && f.utime <= to) frames.push_back(f);
        }
    }
    if (frames.empty()) {
        return Status(
            StatusCode::kNotFound,
            fmt::format("{} holds no raw frame of session {} (plumb-device --set "
                        "stream.raw_frame_every=1 streams every frame to the backend, "
                        "which keeps them in {})",
                        fragments_dir.string(), *session, rawFramesDir(fragments_dir).string()));
    }
    const RawFrameCoverage coverage = rawFrameCoverage(frames, *fragments, *session);
    scan.fragment_frames = coverage.tracked_frames;
    scan.fragment_frames_with_raw = coverage.matched;
    if (coverage.matched < coverage.tracked_frames) {
        if (!scan.note.empty()) scan.note += "; ";
        scan.note += fmt::format(
            "{} of the {} frames session {} tracked have a raw frame (the device streamed every "
            "k-th frame, or frames were lost on the network)",
            coverage.matched, coverage.tracked_frames, *session);
    }
    if (options.max_frames > 0 && frames.size() > options.max_frames)
        frames.resize(options.max_frames);
    scan.frames = frames.size();
    PinholeCamera camera;
    if (options.camera) {
        camera = *options.camera;
    } else {
        auto read = readCameraInfo(
            {fragments_dir.parent_path() / "camera_info.json", fragments_dir / "camera_info.json"});
        if (!read.isOk()) return read.status();
        camera = *read;
    }
    RawFrameView view;
    view.renumber = true;
    view.colour = options.colour;
    view.description = fmt::format(
        "raw frames of session {} in the fragment store {} ({} frames, {}x{} fx={:.1f})", *session,
        fragments_dir.string(), frames.size(), camera.width, camera.height, camera.fx);
    scan.source = openRawFrameSource(std::move(frames), camera, nullptr, std::move(view));
    return scan;
}

}  // namespace plumb::backend
