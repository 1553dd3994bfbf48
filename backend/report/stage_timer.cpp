// SPDX-License-Identifier: Apache-2.0
#include "backend/report/stage_timer.hpp"

#include <algorithm>

namespace plumb::backend {

StageTimer::Scope::Scope(StageTimer& timer, std::string name)
    : timer_(timer), name_(std::move(name)), start_(std::chrono::steady_clock::now()) {}

StageTimer::Scope::~Scope() {
    const std::chrono::duration<double> elapsed = std::chrono::steady_clock::now() - start_;
    timer_.add(name_, elapsed.count());
}

void StageTimer::add(const std::string& name, double seconds) {
    auto it = std::find_if(stages_.begin(), stages_.end(),
                           [&](const StageTime& s) { return s.name == name; });
    if (it == stages_.end()) {
        stages_.push_back({name, 0.0, 0});
        it = std::prev(stages_.end());
    }
    it->seconds += seconds;
    ++it->calls;
}

double StageTimer::totalSeconds() const {
    double total = 0.0;
    for (const StageTime& s : stages_) total += s.seconds;
    return total;
}

}  // namespace plumb::backend
