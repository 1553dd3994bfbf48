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
#include "messages/conversions.hpp"
#include "messages/files.hpp"
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
    auto note = [&scan](const std::string& text) {
        scan.note += (scan.note.empty() ? "" : "; ") + text;
    };
    if (coverage.stride > 1) {
        note(fmt::format(
            "the device streamed one frame in {} (stream.raw_frame_every = {}): they are tracked "
            "again at 1/{} of the camera's rate, with {} times the motion between frames, and "
            "tracking may fail; a scan meant to be reconstructed again streams every frame",
            coverage.stride, coverage.stride, coverage.stride, coverage.stride));
    } else if (coverage.matched < coverage.tracked_frames) {
        note(fmt::format(
            "{} of the {} frames session {} tracked have a raw frame (frames were lost on the "
            "network or not kept)",
            coverage.matched, coverage.tracked_frames, *session));
    }
    if (options.colour) {
        // Whether the frames carry colour: the first one says (a device streams them all alike).
        auto first = messages::readFile(frames.front().path, int64_t{64} << 20);
        auto decoded = first.isOk() ? messages::decodeRawFrame(*first)
                                    : Result<messages::RawRgbdFrame>(first.status());
        if (decoded.isOk() && decoded->colour.empty()) {
            note(
                "the raw frames carry no colour (stream.raw_frame_colour = false): they are "
                "tracked again by depth alone, which drifts where the walls are plain (25 cm of "
                "ATE against 0.45 cm with colour on a 900-frame recording, BENCHMARKS.md); a "
                "scan meant to be reconstructed again streams its colour");
        }
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
