// SPDX-License-Identifier: Apache-2.0
#pragma once

// An in-memory multicast "network" for protocol tests: every subscriber of a channel receives
// every message published on it, after the hub drops, duplicates and reorders them (seeded).
// Delivery happens only in deliver(), so a test controls time completely.

#include <algorithm>
#include <deque>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "messages/transport.hpp"

namespace plumb::messages::testing {

struct LossyConfig {
    double loss = 0.0;       ///< probability that a published message vanishes
    double duplicate = 0.0;  ///< probability that a delivered message arrives twice
    bool reorder = false;    ///< shuffle each delivery round
    uint32_t seed = 1;
};

class LossyHub final : public Transport {
  public:
    explicit LossyHub(LossyConfig config = {}) : config_(config), rng_(config.seed) {}

    Status publish(const std::string& channel, std::span<const uint8_t> bytes) override {
        ++published_;
        if (tap_) tap_(channel, bytes);
        if (uniform_(rng_) < config_.loss) {
            ++dropped_;
            return Status::ok();
        }
        queue_.push_back({channel, std::vector<uint8_t>(bytes.begin(), bytes.end())});
        if (uniform_(rng_) < config_.duplicate) {
            ++duplicated_;
            queue_.push_back(queue_.back());
        }
        return Status::ok();
    }

    Status subscribe(const std::string& channel, Handler handler) override {
        handlers_[channel].push_back(std::move(handler));
        return Status::ok();
    }

    /// Delivers everything queued so far (messages published by handlers wait for the next round).
    /// Returns the number of messages delivered.
    size_t deliver() {
        std::vector<std::pair<std::string, std::vector<uint8_t>>> round(queue_.begin(),
                                                                        queue_.end());
        queue_.clear();
        if (config_.reorder) std::shuffle(round.begin(), round.end(), rng_);
        for (const auto& [channel, bytes] : round) {
            auto it = handlers_.find(channel);
            if (it == handlers_.end()) continue;
            for (auto& h : it->second) h(channel, bytes);
        }
        return round.size();
    }

    /// Sees every published message before loss (to capture messages for replay attacks).
    void setTap(Handler tap) { tap_ = std::move(tap); }
    bool idle() const { return queue_.empty(); }
    size_t published() const { return published_; }
    size_t dropped() const { return dropped_; }
    size_t duplicated() const { return duplicated_; }

  private:
    LossyConfig config_;
    std::mt19937 rng_;
    std::uniform_real_distribution<double> uniform_{0.0, 1.0};
    std::deque<std::pair<std::string, std::vector<uint8_t>>> queue_;
    std::map<std::string, std::vector<Handler>> handlers_;
    Handler tap_;
    size_t published_ = 0, dropped_ = 0, duplicated_ = 0;
};

}  // namespace plumb::messages::testing
