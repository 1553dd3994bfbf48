// SPDX-License-Identifier: Apache-2.0
#pragma once

// How long algorithms report progress without doing any I/O: they take a ProgressCallback and
// call it with the number of items they have just finished; programs connect it to a terminal
// Progress (common/core/progress.hpp, advanceOf) or leave it empty.
//
// Thread-safety: an algorithm may call its callback from its worker threads when its own
// contract says so; advanceOf's callback may be called from any thread.

#include <cstdint>
#include <functional>

namespace plumb {

/// `n` more items are done. Empty: nobody is listening.
using ProgressCallback = std::function<void(uint64_t n)>;

/// Calls `progress` with `n` when it is set.
inline void report(const ProgressCallback& progress, uint64_t n = 1) {
    if (progress) progress(n);
}

}  // namespace plumb
