// SPDX-License-Identifier: Apache-2.0
#include "messages/colour_codec.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <bit>
#include <utility>

namespace plumb::messages {
namespace {

constexpr int kChannels = 3;
constexpr int kMaxRiceParameter = 7;

/// LOCO-I median edge detector (header comment) for sample u of a row, given the row so far
/// (`row`, samples before u known) and the row above (`above`, nullptr for the first row).
inline uint8_t predict(const uint8_t* row, const uint8_t* above, int u) {
    if (above == nullptr) return u == 0 ? 0 : row[u - 1];
    if (u == 0) return above[0];
    const int a = row[u - 1];
    const int b = above[u];
    const int c = above[u - 1];
    if (c >= std::max(a, b)) return static_cast<uint8_t>(std::min(a, b));
    if (c <= std::min(a, b)) return static_cast<uint8_t>(std::max(a, b));
    return static_cast<uint8_t>(a + b - c);
}

/// Channel `channel` (0 R, 1 G, 2 B) of row v of `image` into `out` (width samples).
void extractRow(const ColourImage& image, int v, int channel, uint8_t* out) {
    const auto* p = reinterpret_cast<const uint8_t*>(&image(0, v)) + channel;
    for (int u = 0; u < image.width(); ++u) out[u] = p[3 * u];
}

/// Writes `row` into channel `channel` of row v of `image`.
void storeRow(const uint8_t* row, int v, int channel, ColourImage* image) {
    auto* p = reinterpret_cast<uint8_t*>(&(*image)(0, v)) + channel;
    for (int u = 0; u < image->width(); ++u) p[3 * u] = row[u];
}

/// (x - pred) mod 256 as a signed byte, zig-zag mapped to [0, 255].
uint8_t zigzag(uint8_t x, uint8_t pred) {
    const auto e = static_cast<int8_t>(static_cast<uint8_t>(x - pred));
    return static_cast<uint8_t>((static_cast<uint8_t>(e) << 1) ^ static_cast<uint8_t>(e >> 7));
}

uint8_t unzigzag(uint8_t z, uint8_t pred) {
    const uint8_t e = static_cast<uint8_t>((z >> 1) ^ static_cast<uint8_t>(-(z & 1)));
    return static_cast<uint8_t>(pred + e);
}

/// The Rice parameter with the fewest bits for these residuals: sum over z of (z >> k) + 1 + k,
/// evaluated on their histogram.
int bestRiceParameter(const std::vector<uint8_t>& z) {
    std::array<uint32_t, 256> histogram{};
    for (const uint8_t value : z) ++histogram[value];
    int best_k = 0;
    uint64_t best_bits = UINT64_MAX;
    for (int k = 0; k <= kMaxRiceParameter; ++k) {
        uint64_t bits = 0;
        for (int value = 0; value < 256; ++value) {
            bits += uint64_t{histogram[value]} * static_cast<uint64_t>((value >> k) + 1 + k);
        }
        if (bits < best_bits) {
            best_bits = bits;
            best_k = k;
        }
    }
    return best_k;
}

/// Packs bits most significant first.
class BitWriter {
  public:
    explicit BitWriter(std::vector<uint8_t>* out) : out_(out) {}
    /// Appends the low `n` (<= 32) bits of `bits`.
    void put(uint32_t bits, int n) {
        acc_ = (acc_ << n) | bits;
        used_ += n;
        while (used_ >= 8) {
            used_ -= 8;
            out_->push_back(static_cast<uint8_t>(acc_ >> used_));
        }
    }
    /// Pads the last byte with zero bits.
    void align() {
        if (used_ > 0) put(0, 8 - used_);
    }

  private:
    std::vector<uint8_t>* out_;
    uint64_t acc_ = 0;  ///< the low used_ bits are pending
    int used_ = 0;
};

/// Reads bits most significant first through a 64-bit window; every read is bounds-checked.
class BitReader {
  public:
    explicit BitReader(std::span<const uint8_t> bytes) : bytes_(bytes) {}

    /// Reads `n` (<= 32) bits into `value`; false at the end of the stream.
    bool get(int n, uint32_t* value) {
        refill();
        if (avail_ < n) return false;
        *value = n == 0 ? 0 : static_cast<uint32_t>(window_ >> (64 - n));
        consume(n);
        return true;
    }
    /// Reads a run of one-bits and its terminating zero-bit; the run length in `ones`. False at
    /// the end of the stream or when the run exceeds `max_ones` (an overlong code, `*overlong`).
    bool getUnary(int max_ones, int* ones, bool* overlong) {
        *ones = 0;
        *overlong = false;
        while (true) {
            refill();
            if (avail_ == 0) return false;
            const int run = std::min(std::countl_one(window_), avail_);
            *ones += run;
            if (*ones > max_ones) {
                *overlong = true;
                return false;
            }
            if (run < avail_) {  // the zero-bit is in the window
                consume(run + 1);
                return true;
            }
            consume(run);
        }
    }
    /// Skips to the next whole byte.
    void align() { consume(avail_ % 8); }
    /// Whole bytes not read yet.
    size_t remainingBytes() const { return (bytes_.size() - pos_) + avail_ / 8; }

  private:
    void refill() {
        while (avail_ <= 56 && pos_ < bytes_.size()) {
            window_ |= static_cast<uint64_t>(bytes_[pos_++]) << (56 - avail_);
            avail_ += 8;
        }
    }
    void consume(int n) {
        window_ = n >= 64 ? 0 : window_ << n;
        avail_ -= n;
    }

    std::span<const uint8_t> bytes_;
    size_t pos_ = 0;
    uint64_t window_ = 0;  ///< the next avail_ bits, left-aligned
    int avail_ = 0;
};

}  // namespace

std::vector<uint8_t> encodeColourRice(const ColourImage& colour) {
    PLUMB_CHECK(!colour.empty()) << "encoding an empty colour image";
    const int w = colour.width();
    std::vector<uint8_t> out;
    out.reserve(colour.size() * 2);
    std::vector<uint8_t> z(static_cast<size_t>(w));
    // rows[c] holds channel c of the current row, rows[3 + c] of the row above.
    std::vector<std::vector<uint8_t>> rows(2 * kChannels, std::vector<uint8_t>(w));
    BitWriter bits(&out);
    for (int v = 0; v < colour.height(); ++v) {
        for (int c = 0; c < kChannels; ++c) {
            std::swap(rows[c], rows[kChannels + c]);
            extractRow(colour, v, c, rows[c].data());
            const uint8_t* row = rows[c].data();
            const uint8_t* above = v == 0 ? nullptr : rows[kChannels + c].data();
            for (int u = 0; u < w; ++u) z[u] = zigzag(row[u], predict(row, above, u));
            const int k = bestRiceParameter(z);
            bits.put(static_cast<uint32_t>(k), 8);
            for (const uint8_t value : z) {
                int q = value >> k;
                for (; q >= 32; q -= 32) bits.put(0xFFFFFFFFu, 32);
                bits.put((1u << q) - 1u, q);                // q one-bits
                bits.put(value & ((1u << k) - 1u), k + 1);  // a zero, k bits
            }
            bits.align();
        }
    }
    return out;
}

Result<ColourImage> decodeColourRice(std::span<const uint8_t> bytes, int width, int height) {
    if (width <= 0 || height <= 0) {
        return corrupt(fmt::format("colour stream: image size {}x{}", width, height));
    }
    ColourImage out(width, height);
    std::vector<std::vector<uint8_t>> rows(2 * kChannels, std::vector<uint8_t>(width));
    BitReader bits(bytes);
    for (int v = 0; v < height; ++v) {
        for (int c = 0; c < kChannels; ++c) {
            std::swap(rows[c], rows[kChannels + c]);
            uint8_t* row = rows[c].data();
            const uint8_t* above = v == 0 ? nullptr : rows[kChannels + c].data();
            uint32_t k = 0;
            if (!bits.get(8, &k)) {
                return corrupt(fmt::format("colour stream: truncated at row {} channel {}", v, c));
            }
            if (k > kMaxRiceParameter) {
                return corrupt(
                    fmt::format("colour stream: Rice parameter {} at row {} channel {}", k, v, c));
            }
            const int shift = static_cast<int>(k);
            for (int u = 0; u < width; ++u) {
                int q = 0;
                bool overlong = false;
                uint32_t low = 0;
                if (!bits.getUnary(255 >> shift, &q, &overlong) || !bits.get(shift, &low)) {
                    return corrupt(fmt::format("colour stream: {} at pixel ({}, {}) channel {}",
                                               overlong ? "overlong code" : "truncated", u, v, c));
                }
                const auto z = static_cast<uint8_t>((q << shift) | static_cast<int>(low));
                row[u] = unzigzag(z, predict(row, above, u));
            }
            storeRow(row, v, c, &out);
            bits.align();
        }
    }
    if (bits.remainingBytes() != 0) {
        return corrupt(fmt::format("colour stream: {} trailing bytes", bits.remainingBytes()));
    }
    return out;
}

}  // namespace plumb::messages
