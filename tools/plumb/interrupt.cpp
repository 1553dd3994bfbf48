// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/interrupt.hpp"

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <string>

#include "common/core/check.hpp"

namespace plumb::tools {
namespace {

std::atomic<bool> g_requested{false};
std::atomic<bool> g_active{false};
char g_message[256] = {};
struct sigaction g_old_int, g_old_term;

void onSignal(int) {
    if (g_requested.exchange(true)) {
        constexpr char kAbort[] = "\ninterrupted again: stopping at once\n";
        [[maybe_unused]] const ssize_t n = write(STDERR_FILENO, kAbort, sizeof(kAbort) - 1);
        _exit(130);
    }
    [[maybe_unused]] const ssize_t n = write(STDERR_FILENO, g_message, std::strlen(g_message));
}

}  // namespace

InterruptScope::InterruptScope(const char* what) {
    PLUMB_CHECK(!g_active.exchange(true)) << "one InterruptScope at a time";
    const std::string text = std::string("\n") + what +
                             ": interrupted; stopping at the next frame or stage, keeping the work "
                             "done (Ctrl-C again to abort at once)\n";
    std::strncpy(g_message, text.c_str(), sizeof(g_message) - 1);
    g_requested = false;
    struct sigaction sa {};
    sa.sa_handler = onSignal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART;
    sigaction(SIGINT, &sa, &g_old_int);
    sigaction(SIGTERM, &sa, &g_old_term);
}

InterruptScope::~InterruptScope() {
    sigaction(SIGINT, &g_old_int, nullptr);
    sigaction(SIGTERM, &g_old_term, nullptr);
    g_active = false;
}

bool InterruptScope::requested() { return g_requested.load(); }

}  // namespace plumb::tools
