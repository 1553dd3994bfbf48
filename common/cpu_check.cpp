// SPDX-License-Identifier: Apache-2.0
// Compiled into every program that links plumb::common (an interface source of that library):
// a build for x86-64-v2 (PLUMB_X86_64_V2) refuses, with a message, to start on a CPU without
// SSE4.2 and POPCNT, instead of dying on the first such instruction with "Illegal instruction".
// The check itself is compiled for the x86-64 baseline and runs before any other constructor of
// the program.

#if defined(__x86_64__) && defined(__SSE4_2__)
#include <unistd.h>

namespace {

__attribute__((constructor(101), target("arch=x86-64"))) void plumbRequireX8664V2() {
    __builtin_cpu_init();
    if (__builtin_cpu_supports("sse4.2") && __builtin_cpu_supports("popcnt")) return;
    static const char kMessage[] =
        "plumb: this build needs an x86-64-v2 CPU (SSE4.2 and POPCNT), which this one is not; "
        "build plumb for it with cmake -DPLUMB_X86_64_V2=OFF\n";
    [[maybe_unused]] const ssize_t n = write(STDERR_FILENO, kMessage, sizeof kMessage - 1);
    _exit(1);
}

}  // namespace
#endif
