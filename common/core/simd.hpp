// SPDX-License-Identifier: Apache-2.0
#pragma once

// Runtime choice of the instruction set of a few hot kernels. The build targets x86-64-v2 (SSE4.2;
// PLUMB_X86_64_V2, else the x86-64 baseline) or the baseline ARM ISA, which keep the alignment
// Debian's PCL/Open3D were built with; kernels with an AVX2 variant compile it for that target
// alone (no AVX in any Eigen code) and pick it at run time when the CPU has it.
// Every variant computes the same operations in the same order per pixel or voxel, so results are
// identical bit for bit whichever runs.

namespace plumb::simd {

enum class Level {
    kPortable,  ///< the build's ISA only
    kAvx2,      ///< x86-64 with AVX2 (no FMA: the same rounding as the portable code)
};

/// The best level this CPU runs; kPortable where the environment variable PLUMB_SIMD is
/// "portable" (to compare both on one machine).
Level best();

/// For tests: while it lives, best() returns at most `level` (every thread). Not for concurrent
/// use with kernels running.
class ScopedLevel {
  public:
    explicit ScopedLevel(Level level);
    ~ScopedLevel();
    ScopedLevel(const ScopedLevel&) = delete;
    ScopedLevel& operator=(const ScopedLevel&) = delete;

  private:
    int previous_;
};

}  // namespace plumb::simd
