// The chunk codec's bit streams (internal to net/chunk_encoder.cpp and
// net/chunk_decoder.cpp): Exp-Golomb codes written and read LSB first. A header
// of their own because the encoder writes and the decoder reads the same codes.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace fovea::net::codec_detail {

// ---- bit coding (docs/protocol-chunks.md) ----
// Bits are written LSB first into zeroed bytes. Values are Exp-Golomb codes of
// order k: w = (v >> k) + 1 with n = bit_width(w) - 1; n zero bits, a one bit,
// the n low bits of w, the k low bits of v: 2n + 1 + k bits.
inline std::size_t egBits(uint64_t v, int k) {
  return 2 * static_cast<std::size_t>(std::bit_width((v >> k) + 1) - 1) + 1 + static_cast<std::size_t>(k);
}

class BitWriter {
 public:
  // out needs 8 bytes of slack past the last byte written.
  explicit BitWriter(uint8_t* out) : out_(out) {}
  std::size_t bits() const { return 8 * bytes_ + static_cast<std::size_t>(n_); }
  // Up to 56 bits (v has no bits above len). Branch-free, as zstd's bit stream:
  // add to a register, store all 8 bytes of it, advance by the whole bytes, keep
  // the 0..7 bits left. Writing each code into memory and re-reading it instead
  // stalls on store forwarding; flushing only when 32 bits are full mispredicts.
  [[gnu::always_inline]] void put(uint64_t v, int len) {
    acc_ |= v << n_;
    n_ += len;
    std::memcpy(out_ + bytes_, &acc_, 8);
    bytes_ += static_cast<std::size_t>(n_ >> 3);
    acc_ = (acc_ >> (n_ & ~7)) & 0xff;  // n_ <= 63, so the shift is < 64
    n_ &= 7;
    acc_ &= (uint64_t{1} << n_) - 1;
  }
  // A short Exp-Golomb code (v >> k below 2^27, k <= 28: at most 56 bits) as
  // the bits put() takes; its length in len.
  [[gnu::always_inline]] static uint64_t egCode(uint64_t v, int k, int& len) {
    const uint64_t w = (v >> k) + 1;
    const int n = std::bit_width(w) - 1;
    len = 2 * n + 1 + k;
    const uint64_t low = w ^ (uint64_t{1} << n);
    return (((low << 1) | 1) << n) | ((v & ((uint64_t{1} << k) - 1)) << (2 * n + 1));
  }
  [[gnu::always_inline]] void putEg(uint64_t v, int k) {
    const uint64_t w = (v >> k) + 1;
    const int n = std::bit_width(w) - 1;
    const uint64_t low = w ^ (uint64_t{1} << n);
    if (2 * n + 1 + k <= 56) {  // one write: n zeros, 1, the n low bits of w, the k low bits of v
      const uint64_t r = v & ((uint64_t{1} << k) - 1);
      put((((low << 1) | 1) << n) | (r << (2 * n + 1)), 2 * n + 1 + k);
      return;
    }
    // Long codes (only for huge position jumps): in pieces of at most 32 bits.
    put(0, std::min(n, 32));
    if (n > 32) put(0, n - 32);
    put(1, 1);
    put(low & 0xffffffffu, std::min(n, 32));
    if (n > 32) put(low >> 32, n - 32);
    const uint64_t r = v & ((uint64_t{1} << k) - 1);
    put(r & 0xffffffffu, std::min(k, 32));
    if (k > 32) put(r >> 32, k - 32);
  }
  // Everything written so far, to go back to.
  struct Mark {
    std::size_t bytes;
    uint64_t acc;
    int n;
  };
  Mark mark() const { return {bytes_, acc_, n_}; }
  void rewind(const Mark& m) { bytes_ = m.bytes, acc_ = m.acc, n_ = m.n; }
  // Writes the last partial byte (padded with zeros).
  void finish() { std::memcpy(out_ + bytes_, &acc_, 8); }

 private:
  uint8_t* out_;
  std::size_t bytes_ = 0;
  uint64_t acc_ = 0;  // the n_ (< 8) bits not yet in whole bytes
  int n_ = 0;
};

class BitReader {
 public:
  BitReader(const uint8_t* data, std::size_t bytes) : data_(data), bytes_(bytes), total_(8 * bytes) {}
  std::size_t bits() const { return pos_; }
  // Up to 57 bits; false past the end.
  [[gnu::always_inline]] bool get(int len, uint64_t& v) {
    if (len == 0) {
      v = 0;
      return true;
    }
    if (total_ - pos_ < static_cast<std::size_t>(len)) return false;
    v = peek() & ((uint64_t{1} << len) - 1);
    pos_ += static_cast<std::size_t>(len);
    return true;
  }
  [[gnu::always_inline]] bool getEg(int k, uint64_t& v) {
    {  // the common short code in one read
      const uint64_t p = peek();
      if (p != 0) {
        const int n = std::countr_zero(p);
        const int len = 2 * n + 1 + k;
        if (len <= 56 && static_cast<std::size_t>(len) <= total_ - pos_) {
          const uint64_t low = (p >> (n + 1)) & ((uint64_t{1} << n) - 1);
          v = (((uint64_t{1} << n) | low) - 1) << k | ((p >> (2 * n + 1)) & ((uint64_t{1} << k) - 1));
          pos_ += static_cast<std::size_t>(len);
          return true;
        }
      }
    }
    int n = 0;
    for (;;) {  // the zero run, then its one bit
      if (pos_ == total_) return false;
      const std::size_t avail = std::min<std::size_t>(32, total_ - pos_);
      const uint64_t p = peek() & ((uint64_t{1} << avail) - 1);
      if (p == 0) {
        n += static_cast<int>(avail);
        pos_ += avail;
        if (n > 63) return false;
        continue;
      }
      const int tz = std::countr_zero(p);
      n += tz;
      pos_ += static_cast<std::size_t>(tz) + 1;
      break;
    }
    if (n > 63) return false;
    uint64_t low = 0, hi = 0;
    if (n <= 32) {
      if (!get(n, low)) return false;
    } else {
      if (!get(32, low) || !get(n - 32, hi)) return false;
      low |= hi << 32;
    }
    const uint64_t q = (n == 63 ? (uint64_t{1} << 63) : (uint64_t{1} << n)) - 1 + low;  // w - 1
    if (std::bit_width(q) + k > 63) return false;  // the value would pass 63 bits
    uint64_t r = 0;
    if (!get(k, r)) return false;
    v = (q << k) | r;
    return true;
  }

 private:
  [[gnu::always_inline]] uint64_t peek() const {
    const std::size_t byte = pos_ / 8;
    uint64_t word = 0;
    if (byte + 8 <= bytes_) {
      std::memcpy(&word, data_ + byte, 8);
    } else {
      for (std::size_t i = byte; i < bytes_; ++i) word |= uint64_t{data_[i]} << (8 * (i - byte));
    }
    return word >> (pos_ % 8);
  }
  const uint8_t* data_;
  std::size_t bytes_, total_;
  std::size_t pos_ = 0;
};

}  // namespace fovea::net::codec_detail
