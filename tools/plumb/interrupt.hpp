// SPDX-License-Identifier: Apache-2.0
#pragma once

// Ctrl-C for long commands. While an InterruptScope lives, the first SIGINT or SIGTERM only
// asks the work to stop (requested() turns true) and prints one line saying so on stderr; the
// work checks requested() at its boundaries (a frame, a stage), keeps what it has and returns
// kExitInterrupted. A second signal ends the process at once with status 130. The previous
// handlers are restored when the scope ends. One scope at a time.

namespace plumb::tools {

class InterruptScope {
  public:
    /// `what`: the work, for the message ("plumb reconstruct").
    explicit InterruptScope(const char* what);
    ~InterruptScope();
    InterruptScope(const InterruptScope&) = delete;
    InterruptScope& operator=(const InterruptScope&) = delete;

    /// True once a signal asked the work to stop.
    static bool requested();
};

}  // namespace plumb::tools
