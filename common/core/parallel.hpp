// SPDX-License-Identifier: Apache-2.0
#pragma once

// The index-parallel loop of every algorithm that takes `num_threads`. Work items must write
// disjoint outputs (or per-item / per-chunk accumulators reduced afterwards in index order), so
// results are identical for every thread count.

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <type_traits>

namespace plumb {

/// Calls fn(i) for i in [0, n) on up to `num_threads` workers (0 = TBB default, 1 = inline on
/// the calling thread). `Index` is any integer type; n <= 0 does nothing. Thread-safe as far as
/// `fn` is: it is called concurrently for different i.
template <typename Index, typename Fn>
void parallelFor(int num_threads, Index n, const Fn& fn) {
    static_assert(std::is_integral_v<Index>, "parallelFor: the index must be an integer");
    if (n <= 0) return;
    if (num_threads == 1 || n == 1) {
        for (Index i = 0; i < n; ++i) fn(i);
        return;
    }
    auto body = [&] {
        tbb::parallel_for(tbb::blocked_range<Index>(0, n), [&](const tbb::blocked_range<Index>& r) {
            for (Index i = r.begin(); i != r.end(); ++i) fn(i);
        });
    };
    if (num_threads > 1) {
        tbb::task_arena arena(num_threads);
        arena.execute(body);
    } else {
        body();
    }
}

}  // namespace plumb
