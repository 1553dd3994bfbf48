// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/pose_lookup.hpp"

#include <utility>

namespace plumb::tools {

Result<PosedDepth> readPosedDepth(FrameSource& source, const PoseLookup& poses,
                                  int64_t frame_step) {
    PosedDepth out;
    for (int64_t posed = 0;;) {
        Result<Frame> frame = source.next();
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            return frame.status();
        }
        const std::optional<Eigen::Isometry3d> pose = poses.find(*frame);
        if (!pose) {
            ++out.without_pose;
            continue;
        }
        if (posed++ % frame_step != 0) continue;
        out.depth.push_back(std::move(frame->depth));
        out.T_W_C.push_back(*pose);
    }
    return out;
}

}  // namespace plumb::tools
