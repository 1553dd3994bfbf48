// SPDX-License-Identifier: Apache-2.0
#include "common/core/status.hpp"

namespace plumb {

const char* toString(StatusCode code) {
    switch (code) {
        case StatusCode::kOk:
            return "ok";
        case StatusCode::kInvalidArgument:
            return "invalid argument";
        case StatusCode::kNotFound:
            return "not found";
        case StatusCode::kCorrupt:
            return "corrupt";
        case StatusCode::kUnsupported:
            return "unsupported";
        case StatusCode::kIoError:
            return "I/O error";
        case StatusCode::kOutOfRange:
            return "out of range";
        case StatusCode::kFailedPrecondition:
            return "failed precondition";
        case StatusCode::kInternal:
            return "internal error";
        case StatusCode::kUnavailable:
            return "unavailable";
        case StatusCode::kCancelled:
            return "cancelled";
    }
    return "unknown";
}

std::string Status::toString() const {
    if (isOk()) return "ok";
    return std::string(plumb::toString(code_)) + ": " + message_;
}

}  // namespace plumb
