// SPDX-License-Identifier: Apache-2.0
#pragma once

// The channel for expected failures: a Status (ok or an error code with a message) and Result<T>
// (a value or a Status). Callers log the message with their own context; nothing here throws.
//
// Thread-safety: Status and Result are value types with no shared state.

#include <optional>
#include <string>
#include <utility>
#include <variant>

#include "common/core/check.hpp"

namespace plumb {

enum class StatusCode {
    kOk = 0,
    kInvalidArgument,  ///< the caller passed something unusable (bad flag, bad config value)
    kNotFound,         ///< a file, frame or device that should exist does not
    kCorrupt,          ///< data exists but cannot be decoded (truncated PNG, bad CRC, NaN pose)
    kUnsupported,      ///< a valid but unsupported variant (unknown dataset layout, PLY property)
    kIoError,          ///< the OS refused (permissions, full disk, device unplugged)
    kOutOfRange,       ///< end of a stream, index beyond the data
    kFailedPrecondition,  ///< the operation cannot run in the current state
    kInternal,            ///< a failure we could not classify
    kUnavailable,         ///< a device is gone for now (unplugged, stalled); retrying may succeed
    kCancelled,           ///< the work was stopped on request (Ctrl-C) before it finished
};

const char* toString(StatusCode code);

class [[nodiscard]] Status {
  public:
    Status() = default;
    Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

    static Status ok() { return {}; }
    bool isOk() const { return code_ == StatusCode::kOk; }
    explicit operator bool() const { return isOk(); }
    StatusCode code() const { return code_; }
    const std::string& message() const { return message_; }
    /// "corrupt: depth/12.png: truncated PNG" style text for logs and error output.
    std::string toString() const;

  private:
    StatusCode code_ = StatusCode::kOk;
    std::string message_;
};

inline Status invalidArgument(std::string m) {
    return {StatusCode::kInvalidArgument, std::move(m)};
}
inline Status notFound(std::string m) { return {StatusCode::kNotFound, std::move(m)}; }
inline Status corrupt(std::string m) { return {StatusCode::kCorrupt, std::move(m)}; }
inline Status unsupported(std::string m) { return {StatusCode::kUnsupported, std::move(m)}; }
inline Status ioError(std::string m) { return {StatusCode::kIoError, std::move(m)}; }
inline Status outOfRange(std::string m) { return {StatusCode::kOutOfRange, std::move(m)}; }
inline Status failedPrecondition(std::string m) {
    return {StatusCode::kFailedPrecondition, std::move(m)};
}
inline Status unavailable(std::string m) { return {StatusCode::kUnavailable, std::move(m)}; }
inline Status cancelled(std::string m) { return {StatusCode::kCancelled, std::move(m)}; }

/// The same error with "<context>: " before its message (the stage or input it concerns).
inline Status prefixed(const Status& status, const std::string& context) {
    return {status.code(), context + ": " + status.message()};
}

/// A value or the Status that explains why there is none.
template <typename T>
class [[nodiscard]] Result {
  public:
    Result(T value) : data_(std::move(value)) {}        // NOLINT(google-explicit-constructor)
    Result(Status status) : data_(std::move(status)) {  // NOLINT(google-explicit-constructor)
        PLUMB_CHECK(!std::get<Status>(data_).isOk()) << "a Result needs a value or an error";
    }

    bool isOk() const { return std::holds_alternative<T>(data_); }
    explicit operator bool() const { return isOk(); }

    const Status& status() const {
        static const Status kOkStatus;
        return isOk() ? kOkStatus : std::get<Status>(data_);
    }
    T& value() & {
        PLUMB_CHECK(isOk()) << "value() of a failed Result: " << status().toString();
        return std::get<T>(data_);
    }
    const T& value() const& {
        PLUMB_CHECK(isOk()) << "value() of a failed Result: " << status().toString();
        return std::get<T>(data_);
    }
    T&& value() && {
        PLUMB_CHECK(isOk()) << "value() of a failed Result: " << status().toString();
        return std::get<T>(std::move(data_));
    }
    T* operator->() { return &value(); }
    const T* operator->() const { return &value(); }
    T& operator*() & { return value(); }
    const T& operator*() const& { return value(); }

  private:
    std::variant<T, Status> data_;
};

}  // namespace plumb

/// Returns the Status of `expr` from the enclosing function if it is an error.
#define PLUMB_RETURN_IF_ERROR(expr)                      \
    do {                                                 \
        ::plumb::Status plumb_status_ = (expr);          \
        if (!plumb_status_.isOk()) return plumb_status_; \
    } while (false)
