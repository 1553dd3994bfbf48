// SPDX-License-Identifier: Apache-2.0
#pragma once

// Open-addressing hash map from integer block coordinates to block indices (reference §2.5):
// linear probing over a power-of-two table, hash of Teschner et al. 2003 / Niessner et al. 2013,
// `(x * 73856093) ^ (y * 19349669) ^ (z * 83492791)`, whose low bits are poorly mixed for small
// coordinates, so the slot is taken from the high bits of a Fibonacci multiplication of it.
// No deletion (volumes are cleared whole).
// Thread-safety: concurrent find() is safe; insert() and clear() need exclusive access.

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace plumb::tsdf {

using BlockKey = Eigen::Vector3i;

/// Teschner spatial hash of a block key.
inline uint32_t hashBlockKey(int x, int y, int z) {
    return (static_cast<uint32_t>(x) * 73856093u) ^ (static_cast<uint32_t>(y) * 19349669u) ^
           (static_cast<uint32_t>(z) * 83492791u);
}

class BlockHashMap {
  public:
    static constexpr int32_t kNotFound = -1;

    BlockHashMap() { reset(1024); }

    /// The value stored for (x, y, z), or kNotFound.
    int32_t find(int x, int y, int z) const {
        size_t slot = slotOf(x, y, z);
        while (true) {
            const Entry& e = entries_[slot];
            if (e.value == kNotFound) return kNotFound;
            if (e.x == x && e.y == y && e.z == z) return e.value;
            slot = (slot + 1) & mask_;
        }
    }
    int32_t find(const BlockKey& k) const { return find(k.x(), k.y(), k.z()); }

    /// Inserts key -> value; the key must not be present yet (value >= 0).
    void insert(const BlockKey& k, int32_t value) {
        if ((size_ + 1) * 2 > entries_.size()) grow();
        place(k.x(), k.y(), k.z(), value);
        ++size_;
    }

    size_t size() const { return size_; }
    void clear() { reset(1024); }

  private:
    struct Entry {
        int32_t x = 0;
        int32_t y = 0;
        int32_t z = 0;
        int32_t value = kNotFound;
    };

    void reset(size_t capacity) {
        entries_.assign(capacity, Entry{});
        mask_ = capacity - 1;
        shift_ = 64;
        while ((size_t{1} << (64 - shift_)) < capacity) --shift_;
        size_ = 0;
    }
    size_t slotOf(int x, int y, int z) const {
        return static_cast<size_t>((uint64_t{hashBlockKey(x, y, z)} * 11400714819323198485ull) >>
                                   shift_) &
               mask_;
    }
    void place(int x, int y, int z, int32_t value) {
        size_t slot = slotOf(x, y, z);
        while (entries_[slot].value != kNotFound) slot = (slot + 1) & mask_;
        entries_[slot] = Entry{x, y, z, value};
    }
    void grow() {
        std::vector<Entry> old;
        old.swap(entries_);
        const size_t n = size_;
        reset(old.size() * 2);
        for (const Entry& e : old) {
            if (e.value != kNotFound) place(e.x, e.y, e.z, e.value);
        }
        size_ = n;
    }

    std::vector<Entry> entries_;
    size_t mask_ = 0;
    int shift_ = 64;  ///< 64 - log2(capacity)
    size_t size_ = 0;
};

}  // namespace plumb::tsdf
