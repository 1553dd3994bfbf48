// SPDX-License-Identifier: Apache-2.0
#pragma once

// The tracking and fusion of `plumb reconstruct`, as plumb-device does it, into a fragment store
// in DIR/fragments: each fragment is encoded (messages/fragment_codec.hpp, as the device sends
// it), written, fsynced and renamed into place as it closes, and the backend reads the stored
// fragments, so a run and its continuation see the same bytes. Fragments without surface points
// (a tracking loss on a fragment's first frame) are dropped and the rest numbered 0..n-1.
//
// A stop request ends the pass at a frame boundary. checkpoint() then writes the whole state of
// the pass (the tracker and fusion state, the frames read, the poses read with them) into
// DIR/resume/fusion_state.bin, from which resume() continues exactly: the same fragments, byte
// for byte, as an uninterrupted pass. A checkpoint of a finished pass only marks it finished.

#include <filesystem>
#include <functional>
#include <memory>
#include <vector>

#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"
#include "common/io/trajectory.hpp"
#include "device/fusion/fragment_builder.hpp"
#include "messages/fragment_store.hpp"

namespace plumb::tools {

struct FusionCounts {
    uint64_t read = 0;   ///< source frames read (or skipped by --frame-step)
    uint64_t fused = 0;  ///< of those, frames tracked and fused
    uint64_t lost = 0;   ///< of those, frames on which tracking failed
};

class FusionPass {
  public:
    /// A new pass into `out`/fragments (which must hold no fragment yet).
    static Result<std::unique_ptr<FusionPass>> start(const std::filesystem::path& out,
                                                     const PinholeCamera& camera,
                                                     const device::FusionConfig& config,
                                                     double frame_step);
    /// The pass checkpointed in `out`/resume, with `source` (opened as for the first run) moved
    /// past the frames it had read. kNotFound without a checkpoint, kCorrupt for a damaged one
    /// or one of another camera or configuration.
    static Result<std::unique_ptr<FusionPass>> resume(const std::filesystem::path& out,
                                                      FrameSource& source,
                                                      const PinholeCamera& camera,
                                                      const device::FusionConfig& config,
                                                      double frame_step);

    /// Tracks and fuses frames until the source ends (true: the pass is finished) or `stop`
    /// returns true at a frame boundary (false). Fails for unusable input, a failed store, or
    /// a finished pass without any fragment.
    Result<bool> run(FrameSource& source, const std::function<bool()>& stop, bool quiet);

    /// Writes the checkpoint (atomically).
    Status checkpoint() const;

    /// The stored fragments, decoded, ids 0..n-1.
    Result<std::vector<Fragment>> fragments() const;

    bool finished() const { return finished_; }
    const FusionCounts& counts() const { return counts_; }
    uint32_t fragmentsStored() const { return stored_; }
    /// The poses the source read with its frames (ground truth of some datasets).
    const io::Trajectory& posesRead() const { return poses_read_; }
    /// The odometry of every frame tracked so far.
    const io::Trajectory& tracked() const { return tracked_; }

  private:
    FusionPass(std::filesystem::path out, const PinholeCamera& camera,
               const device::FusionConfig& config, double frame_step);
    Status store(Fragment fragment);

    std::filesystem::path out_;
    device::FragmentBuilder builder_;
    double frame_step_ = 1.0;
    std::unique_ptr<messages::FragmentStore> store_;
    FusionCounts counts_;
    uint32_t stored_ = 0;
    bool finished_ = false;
    io::Trajectory poses_read_;
    io::Trajectory tracked_;
};

/// The session id of the fragments `plumb reconstruct` stores (the store's file names carry it).
inline constexpr int64_t kReconstructSession = 1;

}  // namespace plumb::tools
