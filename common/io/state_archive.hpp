// SPDX-License-Identifier: Apache-2.0
#pragma once

// A byte archive of in-memory state, for checkpoints that a later process restores exactly (an
// interrupted run continued with --resume). Values are written as their bytes in memory, so an
// archive is read back only on a machine of the same byte order and type sizes (the one that
// wrote it); it is not an interchange format. The reader never reads past its input: a short or
// damaged archive makes it fail (ok() false) and every read after that returns false.
//
// Not thread-safe: a StateWriter or StateReader is used by one thread at a time.

#include <Eigen/Geometry>
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <span>
#include <type_traits>
#include <vector>

#include "common/image/image.hpp"

namespace plumb::io {

/// Types written as their bytes: standard-layout values holding no pointers (scalars, Eigen
/// fixed-size matrices, plain structs of them). The compiler cannot check the "no pointers" part.
template <typename T>
inline constexpr bool kRawBytes = std::is_standard_layout_v<T> && !std::is_pointer_v<T>;

class StateWriter {
  public:
    template <typename T>
    void value(const T& v) {
        static_assert(kRawBytes<T>, "raw bytes only for types whose bytes are their value");
        raw(&v, sizeof(T));
    }
    /// Size, then the elements' bytes.
    template <typename T>
    void array(const std::vector<T>& v) {
        static_assert(kRawBytes<T>, "raw bytes only for types whose bytes are their value");
        value<uint64_t>(v.size());
        raw(v.data(), v.size() * sizeof(T));
    }
    template <typename T>
    void image(const Image<T>& im) {
        value<int32_t>(im.width());
        value<int32_t>(im.height());
        array(im.pixels());
    }
    void pose(const Eigen::Isometry3d& T) { raw(T.matrix().data(), 16 * sizeof(double)); }
    template <typename Derived>
    void matrix(const Eigen::MatrixBase<Derived>& m) {
        const typename Derived::PlainObject plain = m;
        raw(plain.data(), static_cast<size_t>(plain.size()) * sizeof(typename Derived::Scalar));
    }

    const std::vector<uint8_t>& bytes() const { return bytes_; }

  private:
    void raw(const void* data, size_t n) {
        const size_t at = bytes_.size();
        bytes_.resize(at + n);
        if (n > 0) std::memcpy(bytes_.data() + at, data, n);
    }
    std::vector<uint8_t> bytes_;
};

class StateReader {
  public:
    explicit StateReader(std::span<const uint8_t> bytes) : bytes_(bytes) {}

    template <typename T>
    bool value(T* v) {
        static_assert(kRawBytes<T>, "raw bytes only for types whose bytes are their value");
        return raw(v, sizeof(T));
    }
    /// At most `max_size` elements (a damaged size fails instead of allocating).
    template <typename T>
    bool array(std::vector<T>* v, uint64_t max_size = uint64_t{1} << 32) {
        static_assert(kRawBytes<T>, "raw bytes only for types whose bytes are their value");
        uint64_t n = 0;
        if (!value(&n)) return false;
        if (n > max_size || n > (bytes_.size() - offset_) / std::max<size_t>(sizeof(T), 1)) {
            return fail();
        }
        v->resize(n);
        return raw(v->data(), n * sizeof(T));
    }
    template <typename T>
    bool image(Image<T>* im) {
        int32_t w = 0, h = 0;
        if (!value(&w) || !value(&h) || w < 0 || h < 0) return fail();
        T zero;  // a defined fill (Eigen's default leaves its values uninitialised)
        std::memset(static_cast<void*>(&zero), 0, sizeof(T));
        Image<T> out(w, h, zero);
        std::vector<T> pixels;
        if (!array(&pixels) || pixels.size() != out.size()) return fail();
        out.pixels() = std::move(pixels);
        *im = std::move(out);
        return true;
    }
    bool pose(Eigen::Isometry3d* T) {
        Eigen::Matrix4d m;
        if (!raw(m.data(), 16 * sizeof(double))) return false;
        T->matrix() = m;
        return true;
    }
    template <typename Derived>
    bool matrix(Eigen::MatrixBase<Derived>* m) {
        typename Derived::PlainObject plain = *m;
        if (!raw(plain.data(),
                 static_cast<size_t>(plain.size()) * sizeof(typename Derived::Scalar))) {
            return false;
        }
        *m = plain;
        return true;
    }

    /// False once a read failed.
    bool ok() const { return ok_; }
    /// True when every byte was read.
    bool atEnd() const { return offset_ == bytes_.size(); }

  private:
    bool fail() {
        ok_ = false;
        return false;
    }
    bool raw(void* out, size_t n) {
        if (!ok_ || n > bytes_.size() - offset_) return fail();
        if (n > 0) std::memcpy(out, bytes_.data() + offset_, n);
        offset_ += n;
        return true;
    }
    std::span<const uint8_t> bytes_;
    size_t offset_ = 0;
    bool ok_ = true;
};

}  // namespace plumb::io
