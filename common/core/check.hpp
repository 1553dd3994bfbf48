// SPDX-License-Identifier: Apache-2.0
#pragma once

// Always-on invariant checks. A broken invariant is a bug: PLUMB_CHECK prints the condition, file,
// line and an optional streamed message to stderr, then aborts. Expected failures (bad files, lost
// packets, unplugged sensors) never use this: they return a Status or Result
// (common/core/status.hpp).
//
//   PLUMB_CHECK(depth.width() == camera.width) << "depth is " << depth.width() << " wide";
//
// Thread-safety: PLUMB_CHECK may be used on any thread; a failure aborts the whole process.

#include <sstream>

namespace plumb::detail {

/// Collects the message of a failed check; its destructor reports and aborts.
class CheckFailure {
  public:
    CheckFailure(const char* condition, const char* file, int line);
    [[noreturn]] ~CheckFailure();
    CheckFailure(const CheckFailure&) = delete;
    CheckFailure& operator=(const CheckFailure&) = delete;

    template <typename T>
    CheckFailure& operator<<(const T& value) {
        stream_ << value;
        return *this;
    }

  private:
    std::ostringstream stream_;
};

/// Lets `PLUMB_CHECK(c) << x` parse as one expression of type void.
struct CheckVoidify {
    void operator&(const CheckFailure&) {}
};

}  // namespace plumb::detail

#define PLUMB_CHECK(condition)                      \
    (condition) ? (void)0                           \
                : ::plumb::detail::CheckVoidify() & \
                      ::plumb::detail::CheckFailure(#condition, __FILE__, __LINE__)
