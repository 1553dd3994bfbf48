// SPDX-License-Identifier: Apache-2.0
// Wall-clock time per pipeline stage, for the report's "time per stage" table.
#pragma once

#include <chrono>
#include <string>
#include <vector>

namespace plumb::backend {

/// One measured stage: its name and the seconds it took (summed over repeated entries).
struct StageTime {
    std::string name;
    double seconds = 0.0;
    int calls = 0;
};

/// Accumulates stage times in first-seen order. Not thread-safe: the pipeline driver owns it.
class StageTimer {
  public:
    /// RAII scope: adds the elapsed time to `name` when it ends.
    class Scope {
      public:
        Scope(StageTimer& timer, std::string name);
        ~Scope();
        Scope(const Scope&) = delete;
        Scope& operator=(const Scope&) = delete;

      private:
        StageTimer& timer_;
        std::string name_;
        std::chrono::steady_clock::time_point start_;
    };

    Scope scope(std::string name) { return Scope(*this, std::move(name)); }
    void add(const std::string& name, double seconds);
    const std::vector<StageTime>& stages() const { return stages_; }
    double totalSeconds() const;

  private:
    std::vector<StageTime> stages_;
};

}  // namespace plumb::backend
