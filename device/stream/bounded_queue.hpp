// SPDX-License-Identifier: Apache-2.0
#pragma once

// A bounded multi-producer multi-consumer queue for the device's pipeline threads. tryPush never
// blocks (capture from a live sensor: a full queue means the frame is dropped, and the caller
// counts it); push waits for room (recorded sources, fragments). close() wakes everyone: pushes
// fail from then on, pops drain what is left and then report the end. Thread-safe.

#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>

namespace plumb::device {

template <typename T>
class BoundedQueue {
  public:
    explicit BoundedQueue(size_t capacity) : capacity_(capacity < 1 ? 1 : capacity) {}

    /// Adds `v` when there is room; false (v untouched) when full or closed.
    bool tryPush(T& v) {
        std::lock_guard<std::mutex> lock(mutex_);
        if (closed_ || items_.size() >= capacity_) return false;
        items_.push_back(std::move(v));
        not_empty_.notify_one();
        return true;
    }

    /// Waits for room; false when the queue was closed first.
    bool push(T v) {
        std::unique_lock<std::mutex> lock(mutex_);
        not_full_.wait(lock, [&] { return closed_ || items_.size() < capacity_; });
        if (closed_) return false;
        items_.push_back(std::move(v));
        not_empty_.notify_one();
        return true;
    }

    /// Waits up to `timeout` for an item; nullopt on timeout or when closed and drained.
    std::optional<T> pop(std::chrono::milliseconds timeout) {
        std::unique_lock<std::mutex> lock(mutex_);
        not_empty_.wait_for(lock, timeout, [&] { return closed_ || !items_.empty(); });
        if (items_.empty()) return std::nullopt;
        T v = std::move(items_.front());
        items_.pop_front();
        not_full_.notify_one();
        return v;
    }

    /// Removes an item without waiting.
    std::optional<T> tryPop() { return pop(std::chrono::milliseconds(0)); }

    void close() {
        std::lock_guard<std::mutex> lock(mutex_);
        closed_ = true;
        not_empty_.notify_all();
        not_full_.notify_all();
    }
    bool closed() const {
        std::lock_guard<std::mutex> lock(mutex_);
        return closed_;
    }
    /// True when closed and nothing is left.
    bool drained() const {
        std::lock_guard<std::mutex> lock(mutex_);
        return closed_ && items_.empty();
    }
    size_t size() const {
        std::lock_guard<std::mutex> lock(mutex_);
        return items_.size();
    }

  private:
    const size_t capacity_;
    mutable std::mutex mutex_;
    std::condition_variable not_empty_, not_full_;
    std::deque<T> items_;
    bool closed_ = false;
};

}  // namespace plumb::device
