// SPDX-License-Identifier: Apache-2.0
#pragma once

// Running a built program from a test as a user would, with its output captured.

#include <sys/types.h>

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace plumb::testing {

struct ProcessRun {
    int exit_code = -1;  ///< -1 when the program did not exit normally
    std::string out;     ///< what it wrote to stdout
    std::string err;     ///< what it wrote to stderr
};

/// The whole content of a file ("" when it cannot be read).
std::string slurp(const std::filesystem::path& path);

/// Runs `command` (a program path, optionally followed by a subcommand, e.g. "/x/plumb sim")
/// with `args`, each single-quoted, capturing stdout and stderr through files in `log_dir`.
ProcessRun runProgram(const std::string& command, const std::filesystem::path& log_dir,
                      const std::vector<std::string>& args);

/// A program started in the background, for tests that signal it: stdout and stderr go to
/// files in `log_dir`. The destructor kills (SIGKILL) and reaps it if it is still running.
class BackgroundProcess {
  public:
    BackgroundProcess(const std::string& program, const std::vector<std::string>& args,
                      const std::filesystem::path& log_dir);
    ~BackgroundProcess();
    BackgroundProcess(const BackgroundProcess&) = delete;
    BackgroundProcess& operator=(const BackgroundProcess&) = delete;

    /// False when it could not be started.
    bool started() const { return pid_ > 0; }
    pid_t pid() const { return pid_; }
    void signal(int signal_number) const;
    /// Waits up to `timeout_s` for it to exit: its exit status (128 + the signal that ended
    /// it), or nullopt when it is still running.
    std::optional<int> wait(double timeout_s);
    /// Polls `condition` every 10 ms for up to `timeout_s` while the program runs; false when
    /// it did not become true (or the program exited first).
    bool waitUntil(const std::function<bool()>& condition, double timeout_s);
    std::string out() const { return slurp(log_dir_ / "stdout.txt"); }
    std::string err() const { return slurp(log_dir_ / "stderr.txt"); }

  private:
    std::filesystem::path log_dir_;
    pid_t pid_ = -1;
    std::optional<int> exit_;
};

/// Pids of the running processes whose command line contains `text`.
std::vector<pid_t> processesMentioning(const std::string& text);

}  // namespace plumb::testing
