// The point-chunk codec (net/codec.h, docs/protocol-chunks.md).
#include "net/codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>

#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_initStaticCCtx/DCtx: contexts that never allocate
#include <zstd.h>

#include "net/schema/chunk_generated.h"

namespace fovea::net {
namespace {

constexpr std::size_t kMinPayload = kMinMtu - kDatagramOverhead;
constexpr std::size_t kMaxPayload = kMaxMtu - kDatagramOverhead;
constexpr std::size_t alignUp(std::size_t n, std::size_t alignment) { return (n + alignment - 1) / alignment * alignment; }
constexpr int kRadixBits = 11;
constexpr uint16_t kChunkCountPlaceholder = 0xffff;
// Lattice coordinates up to 2^50 steps: w + 0.5 stays exact enough in double
// that rounding by truncation keeps |w - q| <= 1/2.
constexpr double kMaxLatticeCoord = 1125899906842624.0;

// ---- Morton codes (21 bits per axis, x in the lowest bit) ----
inline uint64_t spread3(uint64_t v) {
  v &= 0x1fffff;
  v = (v | (v << 32)) & 0x1f00000000ffffULL;
  v = (v | (v << 16)) & 0x1f0000ff0000ffULL;
  v = (v | (v << 8)) & 0x100f00f00f00f00fULL;
  v = (v | (v << 4)) & 0x10c30c30c30c30c3ULL;
  v = (v | (v << 2)) & 0x1249249249249249ULL;
  return v;
}
inline uint32_t compact3(uint64_t v) {
  v &= 0x1249249249249249ULL;
  v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ULL;
  v = (v ^ (v >> 4)) & 0x100f00f00f00f00fULL;
  v = (v ^ (v >> 8)) & 0x1f0000ff0000ffULL;
  v = (v ^ (v >> 16)) & 0x1f00000000ffffULL;
  v = (v ^ (v >> 32)) & 0x1fffff;
  return static_cast<uint32_t>(v);
}
inline uint64_t morton(uint64_t x, uint64_t y, uint64_t z) { return spread3(x) | (spread3(y) << 1) | (spread3(z) << 2); }

// ---- bit coding (docs/protocol-chunks.md) ----
// Bits are written LSB first into zeroed bytes. Values are Exp-Golomb codes of
// order k: w = (v >> k) + 1 with n = bit_width(w) - 1; n zero bits, a one bit,
// the n low bits of w, the k low bits of v: 2n + 1 + k bits.
inline std::size_t egBits(uint64_t v, int k) {
  return 2 * static_cast<std::size_t>(std::bit_width((v >> k) + 1) - 1) + 1 + static_cast<std::size_t>(k);
}
inline uint32_t zigzag8(uint8_t delta) {  // a byte difference (mod 256) as a small unsigned
  const int d = static_cast<int8_t>(delta);
  return static_cast<uint32_t>((d * 2) ^ (d >> 31));  // branch-free: 0, -1, 1, -2 -> 0, 1, 2, 3
}
// A difference of two values in [-255, 255], taken mod 512 as a signed 9-bit
// number, zigzagged to 0..511 (lossless YCoCg-R chroma).
inline uint32_t zigzag9(int delta) {
  const int d = static_cast<int>(static_cast<uint32_t>(delta) << 23) >> 23;  // sign-extend the low 9 bits
  return static_cast<uint32_t>((d * 2) ^ (d >> 31));
}
inline int unzigzag9(uint32_t z) { return static_cast<int>((z >> 1) ^ (0u - (z & 1))); }
// Lossless YCoCg-R (Malvar and Sullivan): Y in 0..255, Co and Cg in -255..255.
struct Ycocg {
  int y, co, cg;
};
inline Ycocg toYcocg(uint32_t c) {
  const int r = pipeline::rgbRed(c), g = pipeline::rgbGreen(c), b = pipeline::rgbBlue(c);
  const int co = r - b, t = b + (co >> 1), cg = g - t;
  return {t + (cg >> 1), co, cg};
}
inline uint8_t unzigzag8(uint32_t z) { return static_cast<uint8_t>((z >> 1) ^ (0u - (z & 1))); }

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

// The order k in [lo, hi] that codes `values` in the fewest bits, among the four
// below the bit width of their mean (on the mock frames the best order was always
// 1 to 4 below it; a fifth candidate saves 0.1 %). Exact counts: an estimate from
// a histogram of bit widths (one bit off when v >> k is all ones) cost 0.7 % more
// bytes. The four candidates are counted in one pass.
inline int bestOrder(const uint64_t* values, std::size_t n, int lo, int hi) {
  if (n == 0) return lo;
  uint64_t sum = 0;
  for (std::size_t i = 0; i < n; ++i) sum += std::min<uint64_t>(values[i], uint64_t{1} << 56);
  const int guess = std::bit_width(sum / n);
  const int k0 = std::max(lo, guess - 4), k1 = std::min(hi, guess - 1);
  if (k1 <= k0) return k0;
  // 2n + 1 + k with n = bit_width(v + 2^k) - k - 1: summing bit_width(v + 2^k) is enough.
  std::array<std::size_t, 4> bits{};
  for (std::size_t i = 0; i < n; ++i) {
    const uint64_t v = std::min<uint64_t>(values[i], uint64_t{1} << 62);
    for (int c = 0; c < 4; ++c) bits[static_cast<std::size_t>(c)] += static_cast<std::size_t>(std::bit_width(v + (uint64_t{1} << std::min(k0 + c, 62))));
  }
  int best = k0;
  std::size_t best_bits = SIZE_MAX;
  for (int k = k0; k <= k1; ++k) {
    const std::size_t total = 2 * bits[static_cast<std::size_t>(k - k0)] - n * static_cast<std::size_t>(k + 1);
    if (total < best_bits) best_bits = total, best = k;
  }
  return best;
}

// ---- colour ----
inline int luma(uint32_t c) {
  return (pipeline::rgbRed(c) + 2 * pipeline::rgbGreen(c) + pipeline::rgbBlue(c) + 2) >> 2;
}
inline uint8_t clampByte(int v) { return static_cast<uint8_t>(std::clamp(v, 0, 255)); }
// Co = (R - B) / 2 and Cg = (2G - R - B) / 4 of a pair, offset by 128.
inline uint8_t pairCo(uint32_t c0, uint32_t c1) {
  const int sum = (pipeline::rgbRed(c0) - pipeline::rgbBlue(c0)) + (pipeline::rgbRed(c1) - pipeline::rgbBlue(c1));
  return static_cast<uint8_t>(std::clamp((sum + 2) >> 2, -128, 127) + 128);
}
inline uint8_t pairCg(uint32_t c0, uint32_t c1) {
  const int sum = (2 * pipeline::rgbGreen(c0) - pipeline::rgbRed(c0) - pipeline::rgbBlue(c0)) +
                  (2 * pipeline::rgbGreen(c1) - pipeline::rgbRed(c1) - pipeline::rgbBlue(c1));
  return static_cast<uint8_t>(std::clamp((sum + 4) >> 3, -128, 127) + 128);
}
// Bytes of a chunk's data before the bitstream: the four Exp-Golomb orders.
constexpr std::size_t kDataHeader = 4;
// Bits of the first Morton code: a 6-bit length, then that many bits.
inline std::size_t firstCodeBits(uint64_t code) { return 6 + static_cast<std::size_t>(std::bit_width(code)); }

// ---- the chunk header (docs/protocol-chunks.md, "Chunk header") ----
// Little-endian, byte-aligned, no padding:
//   0  u32  frame_id            4  u64  capture_time_ns
//   12 u16  chunk_index         14 u16  chunk_count (patched in once the frame is cut)
//   16 u16  point_count         18 u8   region (bits 0-2) and flags (bits 3-5)
//   19 f64  step_m              27      origin: 3 zigzag LEB128 varints, the region's
//                                       smallest lattice point (origin_m = q * step_m)
//   then, with kChunkFlagBrick: i32 x, y, z, u32 version, u8 level (17 bytes);
//   then the data (4 order bytes and the bit stream, or their zstd frame).
constexpr std::size_t kFixedHeader = 27;
constexpr std::size_t kChunkCountOffset = 14;
constexpr std::size_t kBrickTagBytes = 17;
constexpr std::size_t kMaxVarint = 8;  // a zigzagged lattice coordinate below 2^51: 8 groups of 7 bits
constexpr std::size_t kMaxHeader = kFixedHeader + 3 * kMaxVarint + kBrickTagBytes;
// Flags in the header byte (region in its low 3 bits).
constexpr uint8_t kHeaderFlagZstd = 1u << 3;
constexpr uint8_t kHeaderFlagHalf = 1u << 4;
constexpr uint8_t kHeaderFlagBrick = 1u << 5;
constexpr uint8_t kHeaderKnownBits = 0x3f;

template <typename T>
inline void putLe(uint8_t* p, T v) {
  static_assert(std::is_unsigned_v<T>);
  for (std::size_t i = 0; i < sizeof(T); ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
template <typename T>
inline T getLe(const uint8_t* p) {
  static_assert(std::is_unsigned_v<T>);
  T v = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) v = static_cast<T>(v | (T{p[i]} << (8 * i)));
  return v;
}
inline uint64_t zigzag64(int64_t v) { return (static_cast<uint64_t>(v) << 1) ^ static_cast<uint64_t>(v >> 63); }
inline int64_t unzigzag64(uint64_t z) { return static_cast<int64_t>(z >> 1) ^ -static_cast<int64_t>(z & 1); }
inline std::size_t varintBytes(uint64_t v) { return std::max<std::size_t>(1, (static_cast<std::size_t>(std::bit_width(v)) + 6) / 7); }
inline std::size_t putVarint(uint8_t* p, uint64_t v) {
  std::size_t n = 0;
  while (v >= 0x80) {
    p[n++] = static_cast<uint8_t>(v | 0x80);
    v >>= 7;
  }
  p[n++] = static_cast<uint8_t>(v);
  return n;
}

// What a chunk's header says.
struct HeaderFields {
  uint32_t frame_id = 0;
  uint64_t capture_time_ns = 0;
  uint16_t chunk_index = 0, chunk_count = 0, points = 0;
  uint8_t region = 0;
  uint8_t flags = 0;  // kChunkFlagZstd, kChunkFlagHalfChroma (codec.h)
  double step_m = 0.0;
  std::array<int64_t, 3> origin_q{};  // lattice units
  bool has_brick = false;
  BrickTag brick;
};

inline std::size_t headerBytes(const std::array<int64_t, 3>& origin_q, bool brick) {
  std::size_t n = kFixedHeader + (brick ? kBrickTagBytes : 0);
  for (int64_t q : origin_q) n += varintBytes(zigzag64(q));
  return n;
}

// Writes the header; its size.
inline std::size_t writeHeader(uint8_t* p, const HeaderFields& h) {
  putLe<uint32_t>(p, h.frame_id);
  putLe<uint64_t>(p + 4, h.capture_time_ns);
  putLe<uint16_t>(p + 12, h.chunk_index);
  putLe<uint16_t>(p + 14, h.chunk_count);
  putLe<uint16_t>(p + 16, h.points);
  p[18] = static_cast<uint8_t>(h.region | ((h.flags & kChunkFlagZstd) ? kHeaderFlagZstd : 0) |
                               ((h.flags & kChunkFlagHalfChroma) ? kHeaderFlagHalf : 0) |
                               (h.has_brick ? kHeaderFlagBrick : 0));
  putLe<uint64_t>(p + 19, std::bit_cast<uint64_t>(h.step_m));
  std::size_t n = kFixedHeader;
  for (int64_t q : h.origin_q) n += putVarint(p + n, zigzag64(q));
  if (h.has_brick) {
    putLe<uint32_t>(p + n, static_cast<uint32_t>(h.brick.x));
    putLe<uint32_t>(p + n + 4, static_cast<uint32_t>(h.brick.y));
    putLe<uint32_t>(p + n + 8, static_cast<uint32_t>(h.brick.z));
    putLe<uint32_t>(p + n + 12, h.brick.version);
    p[n + 16] = h.brick.level;
    n += kBrickTagBytes;
  }
  return n;
}

// Reads and checks a header (structure only: sizes, varints, flag bits, the
// region, the brick level); its size in `size`, or an error text.
inline const char* readHeader(std::span<const uint8_t> payload, HeaderFields& h, std::size_t& size) {
  const uint8_t* p = payload.data();
  if (payload.size() < kFixedHeader + 3) return "shorter than its header";
  h.frame_id = getLe<uint32_t>(p);
  h.capture_time_ns = getLe<uint64_t>(p + 4);
  h.chunk_index = getLe<uint16_t>(p + 12);
  h.chunk_count = getLe<uint16_t>(p + 14);
  h.points = getLe<uint16_t>(p + 16);
  const uint8_t rf = p[18];
  if ((rf & ~kHeaderKnownBits) != 0) return "unknown flags";
  h.region = rf & 7u;
  h.flags = static_cast<uint8_t>(((rf & kHeaderFlagZstd) ? kChunkFlagZstd : 0) |
                                 ((rf & kHeaderFlagHalf) ? kChunkFlagHalfChroma : 0));
  h.has_brick = (rf & kHeaderFlagBrick) != 0;
  h.step_m = std::bit_cast<double>(getLe<uint64_t>(p + 19));
  std::size_t n = kFixedHeader;
  for (int64_t& q : h.origin_q) {
    uint64_t v = 0;
    for (std::size_t i = 0;; ++i) {
      if (i == kMaxVarint || n == payload.size()) return "origin varint too long or truncated";
      const uint8_t b = p[n++];
      v |= uint64_t{b & 0x7fu} << (7 * i);
      if ((b & 0x80) == 0) break;
    }
    if (v >= (uint64_t{1} << 51)) return "origin beyond 2^50 steps";
    q = unzigzag64(v);
  }
  if (h.has_brick) {
    if (payload.size() - n < kBrickTagBytes) return "brick tag truncated";
    h.brick.x = static_cast<int32_t>(getLe<uint32_t>(p + n));
    h.brick.y = static_cast<int32_t>(getLe<uint32_t>(p + n + 4));
    h.brick.z = static_cast<int32_t>(getLe<uint32_t>(p + n + 8));
    h.brick.version = getLe<uint32_t>(p + n + 12);
    h.brick.level = p[n + 16];
    if (h.brick.level >= pipeline::kMaxRegions) return "brick level out of range";
    n += kBrickTagBytes;
  }
  size = n;
  return nullptr;
}

// ---- encoder steps ----
// The frame being encoded: what each of its chunks carries, and its points per region.
struct FrameInProgress {
  uint32_t frame_id = 0;
  uint64_t capture_time_ns = 0;
  const BrickTag* brick = nullptr;  // every chunk's tag, in a brick encode
  std::size_t arena_used = 0;                                   // bytes of the arena holding chunks
  std::array<uint32_t, pipeline::kMaxRegions + 1> start{};      // region r: order[start[r], start[r + 1])
  std::array<std::array<int64_t, 3>, pipeline::kMaxRegions> qmin{}, qmax{};  // lattice bounds per region
};

// One region's points in Morton order, to be cut into chunks.
struct RegionCut {
  int region;
  const uint64_t* keys;   // Morton keys, sorted
  const uint32_t* order;  // the input index of each key (rgb is gathered in this order)
  std::size_t points;
  bool half;              // chroma shared by pairs of points
  std::array<int64_t, 3> origin_q;  // the region's lattice origin (qmin), steps
  const uint32_t* rgb;    // colour of each key's point
};

// A chunk's Exp-Golomb orders: of the position deltas, and of the three colour codes.
struct Orders {
  int position;
  std::array<int, 3> colour;
};

// The colour coder's previous values (a point's are committed once it fits).
struct ColourPrev {
  uint8_t y = 0;           // previous Y
  int fco = 0, fcg = 0;    // full colour: previous Co, Cg (-255..255)
  uint8_t co = 0, cg = 0;  // halved chroma: the previous pair's Co, Cg
};

// A chunk's first Morton code: a 6-bit length, then that many bits.
[[gnu::always_inline]] inline void putFirstCode(BitWriter& bw, uint64_t code) {
  const std::size_t len = firstCodeBits(code) - 6;
  bw.put(len, 6);
  if (len > 32) {
    bw.put(code & 0xffffffffu, 32);
    bw.put(code >> 32, static_cast<int>(len - 32));
  } else {
    bw.put(code, static_cast<int>(len));
  }
}

// Lossless YCoCg-R deltas of point j as three Exp-Golomb codes (values below 512
// and orders <= 8: at most 27 bits each); `next` gets the point's YCoCg-R.
struct ColourCodes {
  uint64_t code[3];
  int len[3];
  int bits() const { return len[0] + len[1] + len[2]; }
  // The three codes packed from the lowest bit (bits() <= 64 when used whole).
  uint64_t packed() const { return code[0] | (code[1] << len[0]) | (code[2] << (len[0] + len[1])); }
};

[[gnu::always_inline]] inline ColourCodes fullColourCodes(uint32_t c, const Orders& orders, const ColourPrev& prev,
                                                          ColourPrev& next) {
  const Ycocg v = toYcocg(c);
  next.y = static_cast<uint8_t>(v.y);
  next.fco = v.co, next.fcg = v.cg;
  ColourCodes codes;
  codes.code[0] = BitWriter::egCode(zigzag8(static_cast<uint8_t>(next.y - prev.y)), orders.colour[0], codes.len[0]);
  codes.code[1] = BitWriter::egCode(zigzag9(next.fco - prev.fco), orders.colour[1], codes.len[1]);
  codes.code[2] = BitWriter::egCode(zigzag9(next.fcg - prev.fcg), orders.colour[2], codes.len[2]);
  return codes;
}

// The three codes, in one put() when they fit 56 bits (two otherwise).
[[gnu::always_inline]] inline void putColourCodes(BitWriter& bw, const ColourCodes& codes) {
  if (codes.bits() <= 56) {
    bw.put(codes.packed(), codes.bits());
  } else {
    bw.put(codes.code[0] | (codes.code[1] << codes.len[0]), codes.len[0] + codes.len[1]);
    bw.put(codes.code[2], codes.len[2]);
  }
}

// Lossless YCoCg-R deltas of point j.
[[gnu::always_inline]] inline void putFullColour(BitWriter& bw, uint32_t c, const Orders& orders, const ColourPrev& prev,
                                                 ColourPrev& next) {
  putColourCodes(bw, fullColourCodes(c, orders, prev, next));
}

// A point after the first, full colour: its position delta and colour codes, in
// one put() when they fit 56 bits together (nearly always).
[[gnu::always_inline]] inline void putPointFull(BitWriter& bw, uint64_t delta, uint32_t c, const Orders& orders,
                                                const ColourPrev& prev, ColourPrev& next) {
  const int kp = orders.position;
  const int lp = 2 * (std::bit_width((delta >> kp) + 1) - 1) + 1 + kp;
  const ColourCodes codes = fullColourCodes(c, orders, prev, next);
  if (lp + codes.bits() <= 56) {
    int len;
    const uint64_t pc = BitWriter::egCode(delta, kp, len);
    bw.put(pc | (codes.packed() << lp), lp + codes.bits());
    return;
  }
  bw.putEg(delta, kp);
  putColourCodes(bw, codes);
}

// Point j's luma, and after the second point of a pair the pair's chroma. The
// bits a first point's own chroma would take if it stays alone: they must fit too.
[[gnu::always_inline]] inline std::size_t putHalfColour(BitWriter& bw, const RegionCut& cut, std::size_t j,
                                                        std::size_t count, const Orders& orders, const ColourPrev& prev,
                                                        ColourPrev& next) {
  const uint32_t c = cut.rgb[j];
  next.y = static_cast<uint8_t>(luma(c));
  bw.putEg(zigzag8(static_cast<uint8_t>(next.y - prev.y)), orders.colour[0]);
  if (count % 2 == 1) {  // the pair's chroma, after its second point
    const uint32_t c0 = cut.rgb[j - 1];
    next.co = pairCo(c0, c), next.cg = pairCg(c0, c);
    bw.putEg(zigzag8(static_cast<uint8_t>(next.co - prev.co)), orders.colour[1]);
    bw.putEg(zigzag8(static_cast<uint8_t>(next.cg - prev.cg)), orders.colour[2]);
    return 0;
  }
  return egBits(zigzag8(static_cast<uint8_t>(pairCo(c, c) - prev.co)), orders.colour[1]) +
         egBits(zigzag8(static_cast<uint8_t>(pairCg(c, c) - prev.cg)), orders.colour[2]);
}

}  // namespace

// ---- configuration ----

Status validate(const CodecConfig& c) {
  if (c.max_payload < kMinPayload || c.max_payload > kMaxPayload) {
    return {ErrorCode::kInvalidArgument, "codec.max_payload: " + std::to_string(c.max_payload) + " is outside [" +
                                             std::to_string(kMinPayload) + ", " + std::to_string(kMaxPayload) +
                                             "] (MTU minus " + std::to_string(kDatagramOverhead) + " bytes)"};
  }
  if (!std::isfinite(c.fovea_step_m) || c.fovea_step_m < 1e-6 || c.fovea_step_m > 1.0) {
    return {ErrorCode::kInvalidArgument,
            "codec.fovea_step_m: " + std::to_string(c.fovea_step_m) + " is outside [1e-6, 1] m"};
  }
  if (!std::isfinite(c.periphery_step_ratio) || c.periphery_step_ratio < 1.0 / 1024 || c.periphery_step_ratio > 1.0) {
    return {ErrorCode::kInvalidArgument, "codec.periphery_step_ratio: " + std::to_string(c.periphery_step_ratio) +
                                             " is outside [1/1024, 1] (a fraction of the voxel size)"};
  }
  if (c.zstd_level < -7 || c.zstd_level > 9) {
    return {ErrorCode::kInvalidArgument, "codec.zstd_level: " + std::to_string(c.zstd_level) + " is outside [-7, 9]"};
  }
  return Status::ok();
}

// ---- encoder ----

struct ChunkEncoder::State {
  CodecConfig config;
  std::size_t max_points = 0;
  std::size_t budget = 0;  // bytes of data in a chunk of the region in progress (max_payload - its header)
  std::size_t max_chunks = 0;

  // Per point of the frame, grouped by region.
  std::vector<int64_t> qx, qy, qz;  // lattice coordinates, in `order`'s slots (grouped by region)
  std::vector<uint64_t> keys, keys_tmp;
  std::vector<uint32_t> order, order_tmp;
  std::vector<uint32_t> colours;  // the points' colours in Morton order (a separate gather: more loads in flight)
  std::vector<uint32_t> histogram;  // 1 << kRadixBits per radix pass

  // One chunk in the making: 4 order bytes, then the bitstream (+ slack for rollback).
  std::vector<uint8_t> raw;
  std::vector<uint8_t> packed;  // zstd output
  std::vector<uint8_t> zstd_workspace;
  ZSTD_CCtx* cctx = nullptr;
  std::array<uint64_t, 4 * 64> sample{};  // values that choose a chunk's orders

  flatbuffers::FlatBufferBuilder summary_fbb;

  std::vector<uint8_t> arena;  // max_chunks * max_payload
  struct ChunkRef {
    uint32_t offset, size, points;
    uint8_t region;
  };
  std::vector<ChunkRef> chunks;
  std::size_t chunk_count = 0;
  std::array<double, pipeline::kMaxRegions> step{};

  State() : summary_fbb(1) {}
  ~State() = default;

  // Writes one chunk (header, then data) at arena[offset]; its size. The chunk
  // count is a placeholder until patchChunkCount().
  std::size_t buildChunk(std::size_t offset, uint32_t frame_id, uint16_t index, uint8_t region, uint64_t capture_ns,
                         const std::array<int64_t, 3>& origin_q, double step_m, uint32_t points, uint8_t flags,
                         const uint8_t* data, std::size_t data_size, const BrickTag* brick) {
    HeaderFields h;
    h.frame_id = frame_id;
    h.capture_time_ns = capture_ns;
    h.chunk_index = index;
    h.chunk_count = kChunkCountPlaceholder;
    h.points = static_cast<uint16_t>(points);
    h.region = region;
    h.flags = flags;
    h.step_m = step_m;
    h.origin_q = origin_q;
    h.has_brick = brick != nullptr;
    if (brick != nullptr) h.brick = *brick;
    uint8_t* out = arena.data() + offset;
    const std::size_t n = writeHeader(out, h);
    std::memcpy(out + n, data, data_size);
    return n + data_size;
  }

  // encode()'s steps, in order.
  Status countRegions(const pipeline::FoveatedCloud& cloud, std::span<const double> region_voxel_size_m,
                      FrameInProgress& frame);
  Status quantize(const pipeline::FoveatedCloud& cloud, FrameInProgress& frame);
  Status encodeRegion(const pipeline::FoveatedCloud& cloud, int r, FrameInProgress& frame);
  std::pair<const uint64_t*, const uint32_t*> sortByMorton(std::size_t begin, std::size_t end,
                                                           const std::array<int64_t, 3>& qmin, int64_t span);
  Orders chooseOrders(const RegionCut& cut, std::size_t k);
  std::size_t packChunk(const RegionCut& cut, std::size_t k, const Orders& orders, std::size_t& raw_size);
  Status storeChunk(const RegionCut& cut, std::size_t points, std::size_t raw_size, FrameInProgress& frame);
  Status patchChunkCount();

  // zstd of raw[0, size) into packed; 0 when it does not pay or fails.
  std::size_t compress(std::size_t size) {
    const std::size_t c = ZSTD_compressCCtx(cctx, packed.data(), packed.size(), raw.data(), size, config.zstd_level);
    if (ZSTD_isError(c) || c >= size) return 0;
    return c;
  }
};

ChunkEncoder::ChunkEncoder(std::unique_ptr<State> state) : s_(std::move(state)) {}
ChunkEncoder::ChunkEncoder(ChunkEncoder&&) noexcept = default;
ChunkEncoder& ChunkEncoder::operator=(ChunkEncoder&&) noexcept = default;
ChunkEncoder::~ChunkEncoder() = default;

Result<ChunkEncoder> ChunkEncoder::create(const CodecConfig& config, std::size_t max_points) {
  if (Status st = validate(config); !st) return st;
  if (max_points == 0 || max_points > (std::size_t{1} << 26)) {
    return Result<ChunkEncoder>(ErrorCode::kInvalidArgument,
                                "codec: max_points " + std::to_string(max_points) + " is outside [1, 2^26]");
  }
  auto s = std::make_unique<State>();
  s->config = config;
  s->max_points = max_points;

  // The largest header (a brick tag, origin varints of 8 bytes) leaves room for points.
  static_assert(kMinPayload >= kMaxHeader + 64);
  s->budget = config.max_payload - kMaxHeader;

  // Every chunk but a region's last holds more than budget - 23 bytes of at
  // most 23 bytes per point (a 127-bit position code, a 17-bit luma code and two
  // chroma codes of at most 19 bits), budget being at least max_payload - kMaxHeader.
  const std::size_t per_chunk = config.max_payload - kMaxHeader - 23;
  s->max_chunks = (23 * max_points + per_chunk - 1) / per_chunk + pipeline::kMaxRegions + 1;
  // Each chunk starts at a kPayloadAlignment boundary (net/wire.h): the patch
  // below and every decoder read it in place.
  s->arena.resize(s->max_chunks * alignUp(config.max_payload, kPayloadAlignment));
  s->chunks.resize(s->max_chunks);

  s->qx.resize(max_points);
  s->qy.resize(max_points);
  s->qz.resize(max_points);
  s->keys.resize(max_points);
  s->keys_tmp.resize(max_points);
  s->order.resize(max_points);
  s->order_tmp.resize(max_points);
  s->colours.resize(max_points);
  s->histogram.resize(((63 + kRadixBits - 1) / kRadixBits) * (std::size_t{1} << kRadixBits));  // one per pass
  s->raw.resize(config.max_payload + 64);
  s->packed.resize(ZSTD_compressBound(config.max_payload));
  if (config.entropy_coding) {
    s->zstd_workspace.resize(ZSTD_estimateCCtxSize(config.zstd_level));
    s->cctx = ZSTD_initStaticCCtx(s->zstd_workspace.data(), s->zstd_workspace.size());
    if (s->cctx == nullptr) return Result<ChunkEncoder>(ErrorCode::kInvalidArgument, "codec: zstd context failed");
  }
  s->summary_fbb = flatbuffers::FlatBufferBuilder(1024);
  // Warm up the summary builder (its first use allocates).
  const std::array<uint16_t, pipeline::kMaxRegions> zeros{};
  ChunkEncoder enc(std::move(s));
  (void)enc.encodeSummary(0, zeros, zeros);
  return enc;
}

const CodecConfig& ChunkEncoder::config() const { return s_->config; }
std::size_t ChunkEncoder::chunkCount() const { return s_->chunk_count; }
std::span<const uint8_t> ChunkEncoder::chunk(std::size_t i) const {
  const State::ChunkRef& c = s_->chunks[i];
  return {s_->arena.data() + c.offset, c.size};
}
uint8_t ChunkEncoder::chunkRegion(std::size_t i) const { return s_->chunks[i].region; }
uint32_t ChunkEncoder::chunkPoints(std::size_t i) const { return s_->chunks[i].points; }
double ChunkEncoder::regionStep(int region) const { return s_->step[static_cast<std::size_t>(region)]; }

Status ChunkEncoder::encode(const pipeline::FoveatedCloud& cloud, std::span<const double> region_voxel_size_m,
                            uint32_t frame_id, uint64_t capture_time_ns, const BrickTag* brick) {
  State& s = *s_;
  s.chunk_count = 0;
  if (brick != nullptr && brick->level >= pipeline::kMaxRegions) {
    return {ErrorCode::kInvalidArgument, "codec: brick level " + std::to_string(brick->level) + " is not below " +
                                             std::to_string(pipeline::kMaxRegions)};
  }
  const std::size_t n = cloud.size();
  if (n > s.max_points) {
    return {ErrorCode::kCapacityExceeded, "codec: frame has " + std::to_string(n) + " points, max_points is " +
                                              std::to_string(s.max_points)};
  }
  FrameInProgress frame;
  frame.frame_id = frame_id;
  frame.capture_time_ns = capture_time_ns;
  frame.brick = brick;
  if (Status st = s.countRegions(cloud, region_voxel_size_m, frame); !st) return st;
  if (Status st = s.quantize(cloud, frame); !st) return st;
  for (int r = 0; r < pipeline::kMaxRegions; ++r) {
    if (Status st = s.encodeRegion(cloud, r, frame); !st) return st;
  }
  if (brick != nullptr && s.chunk_count == 0) {
    // A brick version with no points (its surfels all went): one chunk of none,
    // so that the operator replaces what it draws of the brick with nothing.
    std::memset(s.raw.data(), 0, kDataHeader);
    const std::size_t size = s.buildChunk(0, frame_id, 0, brick->level, capture_time_ns, {0, 0, 0},
                                          s.step[brick->level], 0, 0, s.raw.data(), kDataHeader, frame.brick);
    s.chunks[0] = {0, static_cast<uint32_t>(size), 0, brick->level};
    s.chunk_count = 1;
  }
  return s.patchChunkCount();
}

// Points per region (frame.start, as offsets), and the step of each region.
Status ChunkEncoder::State::countRegions(const pipeline::FoveatedCloud& cloud,
                                         std::span<const double> region_voxel_size_m, FrameInProgress& frame) {
  std::array<uint32_t, pipeline::kMaxRegions + 1>& start = frame.start;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const uint8_t r = cloud.region[i];
    if (r >= pipeline::kMaxRegions || r >= region_voxel_size_m.size()) {
      return {ErrorCode::kInvalidInput, "codec: point " + std::to_string(i) + " has region " + std::to_string(r) +
                                            " without a voxel size"};
    }
    ++start[r + 1u];
  }
  for (int r = 0; r < pipeline::kMaxRegions; ++r) {
    start[static_cast<std::size_t>(r) + 1] += start[static_cast<std::size_t>(r)];
    const double voxel = r < static_cast<int>(region_voxel_size_m.size()) ? region_voxel_size_m[static_cast<std::size_t>(r)] : 0.0;
    if (!std::isfinite(voxel) || voxel < 0.0) {
      return {ErrorCode::kInvalidInput, "codec: region " + std::to_string(r) + " voxel size is not finite and >= 0"};
    }
    step[static_cast<std::size_t>(r)] = (r == 0 || voxel == 0.0) ? config.fovea_step_m : voxel * config.periphery_step_ratio;
  }
  return Status::ok();
}

// Lattice coordinates (qx, qy, qz) and their bounds per region; `order` gets the
// points grouped by region.
Status ChunkEncoder::State::quantize(const pipeline::FoveatedCloud& cloud, FrameInProgress& frame) {
  std::array<uint32_t, pipeline::kMaxRegions> fill{};
  auto& qmin = frame.qmin;
  auto& qmax = frame.qmax;
  for (int r = 0; r < pipeline::kMaxRegions; ++r) {
    qmin[static_cast<std::size_t>(r)].fill(INT64_MAX);
    qmax[static_cast<std::size_t>(r)].fill(INT64_MIN);
  }
  const Eigen::Vector3d& o = cloud.points.origin_m;
  const float* px = cloud.points.x();
  const float* py = cloud.points.y();
  const float* pz = cloud.points.z();
  std::array<double, pipeline::kMaxRegions> inv_step;
  for (std::size_t r = 0; r < inv_step.size(); ++r) inv_step[r] = 1.0 / step[r];
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const uint8_t r = cloud.region[i];
    const double inv = inv_step[r];
    const double w[3] = {(o.x() + double{px[i]}) * inv, (o.y() + double{py[i]}) * inv, (o.z() + double{pz[i]}) * inv};
    int64_t q[3];
    for (int a = 0; a < 3; ++a) {
      if (!(std::fabs(w[a]) < kMaxLatticeCoord)) {  // also NaN
        if (!std::isfinite(w[a])) {
          return {ErrorCode::kInvalidInput, "codec: point " + std::to_string(i) + " is not finite"};
        }
        return {ErrorCode::kRangeExceeded, "codec: point " + std::to_string(i) + " is beyond 2^50 steps of " +
                                               std::to_string(step[r]) + " m from the world origin"};
      }
      q[a] = static_cast<int64_t>(w[a] >= 0.0 ? w[a] + 0.5 : w[a] - 0.5);  // round half away from zero
      qmin[r][static_cast<std::size_t>(a)] = std::min(qmin[r][static_cast<std::size_t>(a)], q[a]);
      qmax[r][static_cast<std::size_t>(a)] = std::max(qmax[r][static_cast<std::size_t>(a)], q[a]);
    }
    const uint32_t slot = frame.start[r] + fill[r]++;
    qx[slot] = q[0], qy[slot] = q[1], qz[slot] = q[2];
    order[slot] = static_cast<uint32_t>(i);
  }
  return Status::ok();
}

// Region r's points in Morton order, cut greedily into chunks.
Status ChunkEncoder::State::encodeRegion(const pipeline::FoveatedCloud& cloud, int r, FrameInProgress& frame) {
  const std::size_t ru = static_cast<std::size_t>(r);
  const std::size_t begin = frame.start[ru], end = frame.start[ru + 1];
  if (begin == end) return Status::ok();
  const std::array<int64_t, 3>& qmin = frame.qmin[ru];
  int64_t span = 0;
  for (int a = 0; a < 3; ++a) span = std::max(span, frame.qmax[ru][static_cast<std::size_t>(a)] - qmin[static_cast<std::size_t>(a)]);
  if (span > kMaxLatticeSpan) {
    chunk_count = 0;
    return {ErrorCode::kRangeExceeded, "codec: region " + std::to_string(r) + " spans " + std::to_string(span) +
                                           " steps of " + std::to_string(step[ru]) + " m, more than " +
                                           std::to_string(kMaxLatticeSpan) + ": raise the step or narrow the depth range"};
  }
  const std::pair<const uint64_t*, const uint32_t*> sorted = sortByMorton(begin, end, qmin, span);
  const uint32_t* rgb = cloud.points.rgb();
  for (std::size_t k = 0; k < end - begin; ++k) colours[begin + k] = rgb[sorted.second[k]];
  const RegionCut cut{r,
                      sorted.first,
                      sorted.second,
                      end - begin,
                      r > 0 && config.halve_peripheral_chroma,
                      qmin,
                      colours.data() + begin};
  budget = config.max_payload - headerBytes(qmin, frame.brick != nullptr);
  for (std::size_t k = 0; k < cut.points;) {
    const Orders orders = chooseOrders(cut, k);
    std::size_t raw_size = 0;
    const std::size_t points = packChunk(cut, k, orders, raw_size);
    if (points == 0) {
      return {ErrorCode::kCapacityExceeded, "codec: a point does not fit a chunk (bug: budget " +
                                                std::to_string(budget) + ")"};
    }
    if (Status st = storeChunk(cut, points, raw_size, frame); !st) return st;
    k += points;
  }
  return Status::ok();
}

// Morton keys of order[begin, end) relative to the region's lattice origin,
// radix-sorted (stable); the keys and input indices in sorted order (in
// keys/order or in keys_tmp/order_tmp, as the passes end).
std::pair<const uint64_t*, const uint32_t*> ChunkEncoder::State::sortByMorton(std::size_t begin, std::size_t end,
                                                                             const std::array<int64_t, 3>& qmin,
                                                                             int64_t span) {
  // Keys and every pass's histogram in one sweep; then one scatter per pass.
  const int key_bits = 3 * std::bit_width(static_cast<uint64_t>(span));
  const int passes = (key_bits + kRadixBits - 1) / kRadixBits;
  constexpr std::size_t kBins = std::size_t{1} << kRadixBits;
  constexpr uint64_t kMask = kBins - 1;
  std::fill(histogram.begin(), histogram.begin() + static_cast<std::ptrdiff_t>(passes * kBins), 0u);
  const std::size_t m = end - begin;
  // When the key and the point's place in the region fit 64 bits together (always
  // on the mock frames: 33 to 39 bits of key, at most 15 of place), the passes move
  // one word per point instead of a key and an index.
  const int place_bits = std::bit_width(m - 1);
  const bool packed = key_bits + place_bits <= 64;
  for (std::size_t k = begin; k < end; ++k) {
    const uint64_t key = morton(static_cast<uint64_t>(qx[k] - qmin[0]), static_cast<uint64_t>(qy[k] - qmin[1]),
                                static_cast<uint64_t>(qz[k] - qmin[2]));
    keys[k] = packed ? (key << place_bits) | (k - begin) : key;
    for (int p = 0; p < passes; ++p) ++histogram[static_cast<std::size_t>(p) * kBins + ((key >> (p * kRadixBits)) & kMask)];
  }
  uint64_t* k_in = keys.data() + begin;
  uint64_t* k_out = keys_tmp.data() + begin;
  uint32_t* o_in = order.data() + begin;
  uint32_t* o_out = order_tmp.data() + begin;
  if (packed) {
    for (int p = 0; p < passes; ++p) {
      uint32_t* h = histogram.data() + static_cast<std::size_t>(p) * kBins;
      const int shift = p * kRadixBits + place_bits;
      if (h[(k_in[0] >> shift) & kMask] == m) continue;  // one digit for all: the pass would not move a key
      uint32_t sum = 0;
      for (std::size_t d = 0; d < kBins; ++d) {
        const uint32_t c = h[d];
        h[d] = sum;
        sum += c;
      }
      for (std::size_t k = 0; k < m; ++k) k_out[h[(k_in[k] >> shift) & kMask]++] = k_in[k];
      std::swap(k_in, k_out);
    }
    // Unpack in place: keys, and the input index of each.
    const uint64_t place_mask = (uint64_t{1} << place_bits) - 1;
    for (std::size_t k = 0; k < m; ++k) {
      const uint64_t v = k_in[k];
      o_out[k] = o_in[v & place_mask];
      k_in[k] = v >> place_bits;
    }
    return {k_in, o_out};
  }
  for (int p = 0; p < passes; ++p) {
    uint32_t* h = histogram.data() + static_cast<std::size_t>(p) * kBins;
    const int shift = p * kRadixBits;
    if (h[(k_in[0] >> shift) & kMask] == m) continue;  // one digit for all: the pass would not move a key
    uint32_t sum = 0;
    for (std::size_t d = 0; d < kBins; ++d) {
      const uint32_t c = h[d];
      h[d] = sum;
      sum += c;
    }
    for (std::size_t k = 0; k < m; ++k) {
      const uint32_t dst = h[(k_in[k] >> shift) & kMask]++;
      k_out[dst] = k_in[k];
      o_out[dst] = o_in[k];
    }
    std::swap(k_in, k_out);
    std::swap(o_in, o_out);
  }
  return {k_in, o_in};
}

// Exp-Golomb orders from the next (up to) 64 points.
Orders ChunkEncoder::State::chooseOrders(const RegionCut& cut, std::size_t k) {
  const std::size_t probe = std::min<std::size_t>(64, cut.points - k);
  uint64_t* sp = sample.data();
  for (std::size_t j = 1; j < probe; ++j) sp[j - 1] = cut.keys[k + j] - cut.keys[k + j - 1];
  if (cut.half) {
    uint32_t c0 = cut.rgb[k];
    for (std::size_t j = 1; j < probe; ++j) {
      const uint32_t c1 = cut.rgb[k + j];
      sp[64 + j - 1] = zigzag8(static_cast<uint8_t>(luma(c1) - luma(c0)));
      sp[128 + j - 1] = zigzag8(static_cast<uint8_t>(pairCo(c1, c1) - pairCo(c0, c0)));
      sp[192 + j - 1] = zigzag8(static_cast<uint8_t>(pairCg(c1, c1) - pairCg(c0, c0)));
      c0 = c1;
    }
  } else {
    Ycocg a = toYcocg(cut.rgb[k]);
    for (std::size_t j = 1; j < probe; ++j) {
      const Ycocg b = toYcocg(cut.rgb[k + j]);
      sp[64 + j - 1] = zigzag8(static_cast<uint8_t>(b.y - a.y));
      sp[128 + j - 1] = zigzag9(b.co - a.co);
      sp[192 + j - 1] = zigzag9(b.cg - a.cg);
      a = b;
    }
  }
  return {bestOrder(sp, probe - 1, 0, 62),
          {bestOrder(sp + 64, probe - 1, 0, 7), bestOrder(sp + 128, probe - 1, 0, 8), bestOrder(sp + 192, probe - 1, 0, 8)}};
}

// Writes a chunk's data into raw: its orders, then the points from k on, greedily
// along the Morton order while they fit (a point that does not is taken back).
// The points written, 0 when not even one fits; raw_size its bytes.
std::size_t ChunkEncoder::State::packChunk(const RegionCut& cut, std::size_t k, const Orders& orders,
                                           std::size_t& raw_size) {
  uint8_t* bytes = raw.data();  // BitWriter stores whole registers: no need to clear it
  bytes[0] = static_cast<uint8_t>(orders.position);
  for (std::size_t c = 0; c < 3; ++c) bytes[1 + c] = static_cast<uint8_t>(orders.colour[c]);
  BitWriter bw(bytes + kDataHeader);
  const std::size_t budget_bits = 8 * (budget - kDataHeader);
  std::size_t count = 0;
  ColourPrev prev;
  const std::size_t last = std::min(cut.points, k + 0xffff);  // point_count is 16 bits
  for (std::size_t j = k; j < last; ++j) {
    const BitWriter::Mark before = bw.mark();
    ColourPrev next = prev;
    std::size_t extra = 0;
    if (!cut.half && count != 0) {  // the common case
      putPointFull(bw, cut.keys[j] - cut.keys[j - 1], cut.rgb[j], orders, prev, next);
    } else {
      if (count == 0) {
        putFirstCode(bw, cut.keys[j]);
      } else {
        bw.putEg(cut.keys[j] - cut.keys[j - 1], orders.position);
      }
      if (cut.half) {
        extra = putHalfColour(bw, cut, j, count, orders, prev, next);
      } else {
        putFullColour(bw, cut.rgb[j], orders, prev, next);
      }
    }
    if (bw.bits() + extra > budget_bits) {
      bw.rewind(before);
      break;
    }
    prev = next;
    ++count;
  }
  if (count == 0) return 0;
  if (cut.half && count % 2 == 1) {  // a lone last point: its own chroma
    const uint32_t c = cut.rgb[k + count - 1];
    bw.putEg(zigzag8(static_cast<uint8_t>(pairCo(c, c) - prev.co)), orders.colour[1]);
    bw.putEg(zigzag8(static_cast<uint8_t>(pairCg(c, c) - prev.cg)), orders.colour[2]);
  }
  bw.finish();
  raw_size = kDataHeader + (bw.bits() + 7) / 8;
  return count;
}

// The packed chunk, compressed where that pays, with its header into the arena.
Status ChunkEncoder::State::storeChunk(const RegionCut& cut, std::size_t points, std::size_t raw_size,
                                       FrameInProgress& frame) {
  const uint8_t* data = raw.data();
  std::size_t data_size = raw_size;
  uint8_t flags = cut.half ? kChunkFlagHalfChroma : 0;
  if (config.entropy_coding) {
    const std::size_t z = compress(raw_size);
    if (z != 0) data = packed.data(), data_size = z, flags |= kChunkFlagZstd;
  }
  if (chunk_count == max_chunks || chunk_count == 0xffff) {
    chunk_count = 0;
    return {ErrorCode::kCapacityExceeded, "codec: frame needs more than " +
                                              std::to_string(std::min<std::size_t>(max_chunks, 0xffff)) + " chunks"};
  }
  const uint8_t region = static_cast<uint8_t>(cut.region);
  const std::size_t size = buildChunk(frame.arena_used, frame.frame_id, static_cast<uint16_t>(chunk_count), region,
                                      frame.capture_time_ns, cut.origin_q, step[region], static_cast<uint32_t>(points),
                                      flags, data, data_size, frame.brick);
  if (size > config.max_payload) {
    chunk_count = 0;
    return {ErrorCode::kCapacityExceeded, "codec: chunk of " + std::to_string(size) + " bytes over max_payload (bug)"};
  }
  chunks[chunk_count++] = {static_cast<uint32_t>(frame.arena_used), static_cast<uint32_t>(size),
                           static_cast<uint32_t>(points), region};
  frame.arena_used += alignUp(size, kPayloadAlignment);
  return Status::ok();
}

// Every chunk now learns the frame's chunk count (the field is stored: placeholder).
Status ChunkEncoder::State::patchChunkCount() {
  for (std::size_t c = 0; c < chunk_count; ++c) {
    putLe<uint16_t>(arena.data() + chunks[c].offset + kChunkCountOffset, static_cast<uint16_t>(chunk_count));
  }
  return Status::ok();
}

std::span<const uint8_t> ChunkEncoder::encodeSummary(uint32_t frame_id, std::span<const uint16_t> chunks_sent_per_region,
                                                     std::span<const uint16_t> chunks_cut_per_region) {
  State& s = *s_;
  const std::size_t regions = std::min<std::size_t>(
      pipeline::kMaxRegions, std::max(chunks_sent_per_region.size(), chunks_cut_per_region.size()));
  std::array<uint16_t, pipeline::kMaxRegions> sent{}, cut{};
  std::copy_n(chunks_sent_per_region.begin(), std::min(regions, chunks_sent_per_region.size()), sent.begin());
  std::copy_n(chunks_cut_per_region.begin(), std::min(regions, chunks_cut_per_region.size()), cut.begin());
  s.summary_fbb.Clear();
  // A summary's largest scalar has 4 bytes; every payload starts at 8 all the same
  // (net/wire.h kPayloadAlignment), so it decodes in place wherever it is handed.
  s.summary_fbb.TrackMinAlign(kPayloadAlignment);
  const auto sent_v = s.summary_fbb.CreateVector(sent.data(), regions);
  const auto cut_v = s.summary_fbb.CreateVector(cut.data(), regions);
  wire::FrameSummaryBuilder b(s.summary_fbb);
  b.add_frame_id(frame_id);
  b.add_chunk_count(static_cast<uint16_t>(s.chunk_count));
  b.add_chunks_sent(sent_v);
  b.add_chunks_cut(cut_v);
  s.summary_fbb.Finish(b.Finish());
  return {s.summary_fbb.GetBufferPointer(), s.summary_fbb.GetSize()};
}

// ---- decoder ----

namespace {

Status parseError(const char* what) { return {ErrorCode::kParseError, std::string("chunk: ") + what}; }

// Per-thread decompression context and buffer, allocated on first use.
struct ThreadDecoder {
  std::vector<uint8_t> workspace;
  std::vector<uint8_t> buffer;
  ZSTD_DCtx* dctx = nullptr;
  ThreadDecoder() : workspace(ZSTD_estimateDCtxSize()), buffer(kMaxChunkRawBytes) {
    dctx = ZSTD_initStaticDCtx(workspace.data(), workspace.size());
  }
};
ThreadDecoder& threadDecoder() {
  thread_local ThreadDecoder decoder;
  return decoder;
}

}  // namespace

Result<DecodedChunk> decodeChunk(std::span<const uint8_t> payload, pipeline::FoveatedCloud& out) {
  if (payload.size() < 8 || payload.size() > kMaxPayload) return parseError("payload size out of range");
  if (!isPayloadAligned(payload.data())) return parseError("payload not aligned (net/wire.h kPayloadAlignment)");
  HeaderFields h;
  std::size_t header_size = 0;
  if (const char* why = readHeader(payload, h, header_size); why != nullptr) return parseError(why);

  DecodedChunk info;
  info.frame_id = h.frame_id;
  info.chunk_index = h.chunk_index;
  info.chunk_count = h.chunk_count;
  info.region = h.region;
  info.capture_time_ns = h.capture_time_ns;
  info.step_m = h.step_m;
  info.has_brick = h.has_brick;
  info.brick = h.brick;
  const uint32_t n = h.points;
  const uint8_t flags = h.flags;
  if (info.chunk_count == 0 || info.chunk_index >= info.chunk_count) return parseError("chunk index out of range");
  if (!std::isfinite(info.step_m) || !(info.step_m > 0.0)) return parseError("step is not finite and > 0");
  // Exact products: the encoder's origin is the same q * step in double.
  const Eigen::Vector3d o(static_cast<double>(h.origin_q[0]) * info.step_m, static_cast<double>(h.origin_q[1]) * info.step_m,
                          static_cast<double>(h.origin_q[2]) * info.step_m);
  if (!std::isfinite(o.x()) || !std::isfinite(o.y()) || !std::isfinite(o.z())) return parseError("origin not finite");
  const std::span<const uint8_t> data_v = payload.subspan(header_size);
  const bool compressed = (flags & kChunkFlagZstd) != 0;
  std::size_t raw_size = data_v.size();
  if (compressed) {  // zstd frames carry their content size
    const unsigned long long content = ZSTD_getFrameContentSize(data_v.data(), data_v.size());
    if (content == ZSTD_CONTENTSIZE_ERROR || content == ZSTD_CONTENTSIZE_UNKNOWN || content > kMaxChunkRawBytes) {
      return parseError("zstd frame without a valid content size");
    }
    raw_size = static_cast<std::size_t>(content);
  }
  const bool half = (flags & kChunkFlagHalfChroma) != 0;
  // A brick chunk may carry no point: the version of a brick whose surfels all went.
  if (raw_size < kDataHeader || (n == 0 && !info.has_brick) || n > 8 * (raw_size - kDataHeader)) {
    return parseError("point count does not fit the data");
  }

  const uint8_t* data = data_v.data();
  std::size_t size = data_v.size();
  if (compressed) {
    ThreadDecoder& td = threadDecoder();
    if (td.dctx == nullptr) return parseError("zstd context unavailable");
    const std::size_t got = ZSTD_decompressDCtx(td.dctx, td.buffer.data(), raw_size, data, size);
    if (ZSTD_isError(got) || got != raw_size) return parseError("zstd data corrupt or of the wrong size");
    data = td.buffer.data();
    size = got;
  }

  pipeline::PointCloud& pts = out.points;
  if (pts.capacity() - pts.size() < n || out.region.size() < pts.size() + n || out.weight.size() < pts.size() + n) {
    return Result<DecodedChunk>(ErrorCode::kCapacityExceeded, "chunk: output cloud is full");
  }
  const std::size_t first = pts.size();
  const Eigen::Vector3d base = first == 0 ? o : pts.origin_m;

  // The orders, then per point: position (first: 6-bit length + code; then
  // Exp-Golomb deltas of the Morton code) and colour codes.
  const int kp = data[0];
  const int kc[3] = {data[1], data[2], data[3]};
  if (kp > 62 || kc[0] > 7 || kc[1] > 8 || kc[2] > 8) return parseError("Exp-Golomb order out of range");
  BitReader br(data + kDataHeader, size - kDataHeader);
  float* x = pts.x() + first;
  float* y = pts.y() + first;
  float* z = pts.z() + first;
  uint32_t* rgb = pts.rgb() + first;
  const Eigen::Vector3d shift = o - base;
  constexpr uint64_t kMaxCode = (uint64_t{1} << 63) - 1;
  uint64_t code = 0;
  uint8_t p0 = 0, p1 = 0, p2 = 0;
  auto colourDelta = [&br](int k, uint8_t& value) __attribute__((always_inline)) {
    uint64_t zz;
    if (!br.getEg(k, zz) || zz > 255) return false;
    value = static_cast<uint8_t>(value + unzigzag8(static_cast<uint32_t>(zz)));
    return true;
  };
  int fco = 0, fcg = 0;  // full colour: Co, Cg as 9-bit values
  auto chromaDelta = [&br](int k, int& value) __attribute__((always_inline)) {
    uint64_t zz;
    if (!br.getEg(k, zz) || zz > 511) return false;
    value = (value + unzigzag9(static_cast<uint32_t>(zz))) & 511;
    return true;
  };
  auto chroma = [&](uint32_t from, uint32_t to) {  // points [from, to) share (p1, p2) = (Co, Cg)
    for (uint32_t i = from; i < to; ++i) {
      const int Y = static_cast<int>(rgb[i]), Co = int{p1} - 128, Cg = int{p2} - 128;
      rgb[i] = pipeline::packRgb(clampByte(Y + Co - Cg), clampByte(Y + Cg), clampByte(Y - Co - Cg));
    }
  };
  for (uint32_t k = 0; k < n; ++k) {
    uint64_t v;
    if (k == 0) {
      uint64_t len, lo = 0, hi = 0;
      if (!br.get(6, len)) return parseError("position data truncated");
      if (len > 32) {
        if (!br.get(32, lo) || !br.get(static_cast<int>(len - 32), hi)) return parseError("position data truncated");
      } else if (!br.get(static_cast<int>(len), lo)) {
        return parseError("position data truncated");
      }
      code = lo | (hi << 32);
      if (code > kMaxCode) return parseError("Morton code overflow");
    } else {
      if (!br.getEg(kp, v)) return parseError("position data truncated or malformed");
      if (v > kMaxCode - code) return parseError("Morton code overflow");
      code += v;
    }
    const double wx = shift.x() + compact3(code) * info.step_m;
    const double wy = shift.y() + compact3(code >> 1) * info.step_m;
    const double wz = shift.z() + compact3(code >> 2) * info.step_m;
    constexpr double kFloatMax = 3.0e38;
    if (!(std::fabs(wx) < kFloatMax && std::fabs(wy) < kFloatMax && std::fabs(wz) < kFloatMax)) {
      return Result<DecodedChunk>(ErrorCode::kRangeExceeded, "chunk: point too far from the output cloud's origin");
    }
    x[k] = static_cast<float>(wx), y[k] = static_cast<float>(wy), z[k] = static_cast<float>(wz);
    if (!half) {
      if (!colourDelta(kc[0], p0) || !chromaDelta(kc[1], fco) || !chromaDelta(kc[2], fcg)) {
        return parseError("colour data truncated or malformed");
      }
      const int co = fco >= 256 ? fco - 512 : fco, cg = fcg >= 256 ? fcg - 512 : fcg;
      const int t = p0 - (cg >> 1), g = cg + t, b = t - (co >> 1), r = b + co;
      if ((r | g | b) < 0 || r > 255 || g > 255 || b > 255) return parseError("colour out of range");
      rgb[k] = pipeline::packRgb(static_cast<uint8_t>(r), static_cast<uint8_t>(g), static_cast<uint8_t>(b));
    } else {
      if (!colourDelta(kc[0], p0)) return parseError("colour data truncated or malformed");
      rgb[k] = p0;  // luma until the pair's chroma arrives
      if (k % 2 == 1 || k + 1 == n) {
        if (!colourDelta(kc[1], p1) || !colourDelta(kc[2], p2)) return parseError("chroma data truncated or malformed");
        chroma(k - k % 2, k + 1);
      }
    }
  }
  if ((br.bits() + 7) / 8 != size - kDataHeader) return parseError("data length does not match its points");
  if (first == 0) pts.origin_m = base;
  for (uint32_t k = 0; k < n; ++k) {
    out.region[first + k] = info.region;
    out.weight[first + k] = 1;
  }
  (void)pts.resize(first + n);
  info.points = n;
  return info;
}

Result<FrameSummaryInfo> decodeSummary(std::span<const uint8_t> payload) {
  if (payload.size() < 8 || payload.size() > kMaxPayload) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: payload size out of range");
  }
  if (!isPayloadAligned(payload.data())) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: payload not aligned (net/wire.h)");
  }
  flatbuffers::Verifier verifier(payload.data(), payload.size(), 8, 16);
  if (!verifier.VerifyBuffer<wire::FrameSummary>(nullptr)) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: FlatBuffers verification failed");
  }
  const wire::FrameSummary* s = flatbuffers::GetRoot<wire::FrameSummary>(payload.data());
  FrameSummaryInfo info;
  info.frame_id = s->frame_id();
  info.chunk_count = s->chunk_count();
  const auto* sent = s->chunks_sent();
  const auto* cut = s->chunks_cut();
  if (sent == nullptr || cut == nullptr || sent->size() != cut->size() || sent->size() > pipeline::kMaxRegions) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: per-region counts missing or of different sizes");
  }
  info.region_count = static_cast<int>(sent->size());
  uint32_t total = 0;
  for (flatbuffers::uoffset_t r = 0; r < sent->size(); ++r) {
    info.chunks_sent[r] = sent->Get(r);
    info.chunks_cut[r] = cut->Get(r);
    total += uint32_t{info.chunks_sent[r]} + info.chunks_cut[r];
  }
  if (total > info.chunk_count) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: more chunks sent and cut than encoded");
  }
  return info;
}

// ---- frame assembly ----

FrameAssembler::FrameAssembler(std::size_t max_points) : seen_(65536, 0) {
  for (pipeline::FoveatedCloud& c : clouds_) c = pipeline::FoveatedCloud(max_points);
}

Result<FrameAssembler> FrameAssembler::create(std::size_t max_points) {
  if (max_points == 0 || max_points > (std::size_t{1} << 26)) {
    return Result<FrameAssembler>(ErrorCode::kInvalidArgument,
                                  "assembler: max_points " + std::to_string(max_points) + " is outside [1, 2^26]");
  }
  // Warm the per-thread decompression context of the calling thread.
  (void)threadDecoder();
  return FrameAssembler(max_points);
}

void FrameAssembler::startFrame(uint32_t frame_id) {
  current_ = AssembledFrame{};
  current_.frame_id = frame_id;
  // A cloud no ready frame uses.
  for (std::size_t i = 0; i < clouds_.size(); ++i) {
    bool used = false;
    for (std::size_t j = 0; j < ready_count_; ++j) used = used || ready_[j].cloud == &clouds_[i];
    if (!used) {
      current_cloud_ = i;
      break;
    }
  }
  clouds_[current_cloud_].clear();
  current_.cloud = &clouds_[current_cloud_];
  std::fill(seen_.begin(), seen_.end(), uint8_t{0});
  has_current_ = true;
}

void FrameAssembler::completeCurrent(bool summary_received) {
  if (!has_current_) return;
  current_.summary_received = summary_received;
  ready_[ready_count_++] = current_;
  last_completed_id_ = current_.frame_id;
  has_last_completed_ = true;
  has_current_ = false;
  ++counters_.frames;
}

void FrameAssembler::flush() {
  ready_count_ = 0;
  completeCurrent(false);
}

Status FrameAssembler::addChunk(std::span<const uint8_t> payload, int64_t received_ns) {
  ready_count_ = 0;
  // Peek at the frame id through a verified decode into the current cloud; a
  // chunk of a newer frame first completes the current one.
  if (payload.size() < 8 || payload.size() > kMaxPayload) {
    ++counters_.bad_chunks;
    return {ErrorCode::kParseError, "chunk: payload size out of range"};
  }
  if (!isPayloadAligned(payload.data())) {
    ++counters_.bad_chunks;
    return {ErrorCode::kParseError, "chunk: payload not aligned (net/wire.h kPayloadAlignment)"};
  }
  HeaderFields h;
  std::size_t header_size = 0;
  if (const char* why = readHeader(payload, h, header_size); why != nullptr) {
    ++counters_.bad_chunks;
    return {ErrorCode::kParseError, std::string("chunk: ") + why};
  }
  if (h.has_brick) {
    ++counters_.bad_chunks;
    return {ErrorCode::kParseError, "chunk: a brick chunk is no part of a frame"};
  }
  const uint32_t id = h.frame_id;
  if (has_current_ && id != current_.frame_id) {
    if (!serialNewer(id, current_.frame_id)) {
      ++counters_.late_chunks;
      return Status::ok();
    }
    completeCurrent(false);
  } else if (!has_current_ && has_last_completed_ && !serialNewer(id, last_completed_id_)) {
    ++counters_.late_chunks;
    return Status::ok();
  }
  if (!has_current_) startFrame(id);
  const uint16_t index = h.chunk_index;
  if (seen_[index] != 0) {
    ++counters_.duplicate_chunks;
    return Status::ok();
  }
  Result<DecodedChunk> d = decodeChunk(payload, clouds_[current_cloud_]);
  if (!d) {
    ++counters_.bad_chunks;
    return d.status();
  }
  seen_[index] = 1;
  ++counters_.chunks;
  current_.capture_time_ns = d->capture_time_ns;
  current_.chunk_count = d->chunk_count;
  current_.points[d->region] += static_cast<uint32_t>(d->points);
  current_.step_m[d->region] = d->step_m;
  ++current_.chunks_received[d->region];
  current_.last_chunk_received_ns = received_ns;
  return Status::ok();
}

Status FrameAssembler::addSummary(std::span<const uint8_t> payload) {
  ready_count_ = 0;
  Result<FrameSummaryInfo> s = decodeSummary(payload);
  if (!s) {
    ++counters_.bad_summaries;
    return s.status();
  }
  const uint32_t id = s->frame_id;
  if (has_current_ && id != current_.frame_id) {
    if (!serialNewer(id, current_.frame_id)) {
      ++counters_.late_summaries;
      return Status::ok();
    }
    completeCurrent(false);
  } else if (!has_current_ && has_last_completed_ && !serialNewer(id, last_completed_id_)) {
    ++counters_.late_summaries;
    return Status::ok();
  }
  if (!has_current_) startFrame(id);  // every chunk of this frame was lost
  current_.chunk_count = s->chunk_count;
  for (int r = 0; r < s->region_count; ++r) {
    current_.chunks_expected[static_cast<std::size_t>(r)] = s->chunks_sent[static_cast<std::size_t>(r)];
    current_.chunks_cut[static_cast<std::size_t>(r)] = s->chunks_cut[static_cast<std::size_t>(r)];
  }
  completeCurrent(true);
  return Status::ok();
}

}  // namespace fovea::net
