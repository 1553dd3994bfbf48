// SPDX-License-Identifier: Apache-2.0
#include "common/fragment/fragment.hpp"

namespace plumb {

const char* toString(FragmentEnd end) {
    switch (end) {
        case FragmentEnd::kFrameCount:
            return "frame_count";
        case FragmentEnd::kTrackingLost:
            return "tracking_lost";
        case FragmentEnd::kBlockBudget:
            return "block_budget";
        case FragmentEnd::kEndOfStream:
            return "end_of_stream";
    }
    return "unknown";
}

}  // namespace plumb
