// SPDX-License-Identifier: Apache-2.0
#include "device/fusion/fuse_frames.hpp"

#include <optional>
#include <utility>

namespace plumb::device {

Result<bool> fuseFrames(FrameSource& source, FragmentBuilder& builder, const FuseHooks& hooks,
                        uint64_t max_frames) {
    for (uint64_t read = 0; read < max_frames;) {
        if (hooks.stop && hooks.stop()) return false;
        Result<Frame> frame = source.next();
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            if (hooks.skip_error && hooks.skip_error(frame.status())) continue;
            return frame.status();
        }
        ++read;
        if (hooks.keep && !hooks.keep(*frame)) continue;
        Result<FrameReport> report = builder.process(*frame);
        if (!report.isOk()) return report.status();
        if (hooks.on_frame) PLUMB_RETURN_IF_ERROR(hooks.on_frame(*frame, *report));
        for (Fragment& f : report->closed) {
            if (hooks.on_fragment) PLUMB_RETURN_IF_ERROR(hooks.on_fragment(std::move(f)));
        }
    }
    if (std::optional<Fragment> last = builder.finish(); last && hooks.on_fragment) {
        PLUMB_RETURN_IF_ERROR(hooks.on_fragment(std::move(*last)));
    }
    return true;
}

}  // namespace plumb::device
