// The chunk header (internal to the codec: net/chunk_encoder.cpp writes it,
// net/chunk_decoder.cpp and net/frame_assembler.cpp read it), and the payload
// sizes every part of the codec checks. docs/protocol-chunks.md is the spec.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <span>
#include <type_traits>

#include "net/codec.h"
#include "net/wire.h"
#include "pipeline/acuity.h"

namespace fovea::net::codec_detail {

// A chunk payload's size bounds: the MTU's, less the datagram's own bytes.
inline constexpr std::size_t kMinPayload = kMinMtu - kDatagramOverhead;
inline constexpr std::size_t kMaxPayload = kMaxMtu - kDatagramOverhead;

// ---- the chunk header (docs/protocol-chunks.md, "Chunk header") ----
// Little-endian, byte-aligned, no padding:
//   0  u32  frame_id            4  u64  capture_time_ns
//   12 u16  chunk_index         14 u16  chunk_count (patched in once the frame is cut)
//   16 u16  point_count         18 u8   region (bits 0-2) and flags (bits 3-5)
//   19 f64  step_m              27      origin: 3 zigzag LEB128 varints, the region's
//                                       smallest lattice point (origin_m = q * step_m)
//   then, with kChunkFlagBrick: i32 x, y, z, u32 version, u8 level (17 bytes);
//   then the data (4 order bytes and the bit stream, or their zstd frame).
inline constexpr std::size_t kFixedHeader = 27;
inline constexpr std::size_t kChunkCountOffset = 14;
inline constexpr std::size_t kBrickTagBytes = 17;
inline constexpr std::size_t kMaxVarint = 8;  // a zigzagged lattice coordinate below 2^51: 8 groups of 7 bits
inline constexpr std::size_t kMaxHeader = kFixedHeader + 3 * kMaxVarint + kBrickTagBytes;
// Flags in the header byte (region in its low 3 bits).
inline constexpr uint8_t kHeaderFlagZstd = 1u << 3;
inline constexpr uint8_t kHeaderFlagHalf = 1u << 4;
inline constexpr uint8_t kHeaderFlagBrick = 1u << 5;
inline constexpr uint8_t kHeaderKnownBits = 0x3f;

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

}  // namespace fovea::net::codec_detail
