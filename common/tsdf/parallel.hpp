// SPDX-License-Identifier: Apache-2.0
#pragma once

// Index-parallel loops for the TSDF kernels. Work items write disjoint outputs, so results are
// identical for every thread count.

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace plumb::tsdf {

/// Calls fn(i) for i in [0, n) on `num_threads` workers (0 = TBB default).
template <typename Fn>
void parallelFor(int num_threads, int n, const Fn& fn) {
    if (n <= 0) return;
    auto body = [&] {
        tbb::parallel_for(tbb::blocked_range<int>(0, n), [&](const tbb::blocked_range<int>& r) {
            for (int i = r.begin(); i != r.end(); ++i) fn(i);
        });
    };
    if (num_threads == 1) {
        for (int i = 0; i < n; ++i) fn(i);
    } else if (num_threads > 1) {
        tbb::task_arena arena(num_threads);
        arena.execute(body);
    } else {
        body();
    }
}

}  // namespace plumb::tsdf
