// How the chunk codec codes a point (internal to net/chunk_encoder.cpp and
// net/chunk_decoder.cpp): Morton codes for positions, zigzag and YCoCg-R for
// colours, and the data's order bytes. Each transform and its inverse sit
// together here so that encoder and decoder cannot drift apart.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>

#include "pipeline/point_cloud.h"

namespace fovea::net::codec_detail {

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

// ---- zigzag and YCoCg-R (docs/protocol-chunks.md) ----
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

// ---- a chunk's data ----
// Bytes of a chunk's data before the bitstream: the four Exp-Golomb orders.
inline constexpr std::size_t kDataHeader = 4;
// Bits of the first Morton code: a 6-bit length, then that many bits.
inline std::size_t firstCodeBits(uint64_t code) { return 6 + static_cast<std::size_t>(std::bit_width(code)); }

}  // namespace fovea::net::codec_detail
