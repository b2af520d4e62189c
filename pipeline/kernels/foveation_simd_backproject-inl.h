// The SIMD back-projection kernels (depth pixels to points, in float): counting
// the valid pixels of rows, and back-projecting them with their colours compacted
// into the output cloud.
// Per-target bodies, compiled once per Highway target by foveation_simd.cpp, which
// gives the rules every -inl header of these kernels follows (the namespace
// brackets, bit-exactness).

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_BACKPROJECT_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_BACKPROJECT_INL_H_
#undef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_BACKPROJECT_INL_H_
#else
#define FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_BACKPROJECT_INL_H_
#endif

#include <cstring>

#include "hwy/highway.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/kernels/store_first_lanes-inl.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// ---- back-projection --------------------------------------------------------

inline std::size_t BackprojectCountRowsT(const BackprojectParams& p, int row0, int row1, std::size_t* no_depth,
                                         std::size_t* out_of_range) {
  const hn::ScalableTag<int32_t> di;
  const hn::Rebind<uint16_t, decltype(di)> du16;
  const hn::RebindToUnsigned<decltype(di)> du32;
  const std::size_t lanes = hn::Lanes(di);
  const auto lo = hn::Set(di, p.raw_min - 1);
  const auto hi = hn::Set(di, p.raw_max + 1);
  const auto zero = hn::Zero(di);
  std::size_t valid = 0, none = 0, pixels = 0;
  for (int v = row0; v < row1; ++v) {
    const uint16_t* row = p.depth + static_cast<std::size_t>(v) * p.width;
    const auto w = static_cast<std::size_t>(p.width);
    std::size_t u = 0;
    for (; u + lanes <= w; u += lanes) {
      const auto raw = hn::BitCast(di, hn::PromoteTo(du32, hn::LoadU(du16, row + u)));
      valid += hn::CountTrue(di, hn::And(hn::Gt(raw, lo), hn::Lt(raw, hi)));
      none += hn::CountTrue(di, hn::Eq(raw, zero));
    }
    for (; u < w; ++u) {  // counting needs no padding trick: it is integer work
      const int32_t raw = row[u];
      valid += (raw >= p.raw_min && raw <= p.raw_max);
      none += (raw == 0);
    }
    pixels += w;
  }
  *no_depth += none;
  *out_of_range += pixels - valid - none;
  return valid;
}

// Compaction of three vectors by one mask. Highway 1.0.3's AVX2 Compress keeps its
// 1 KiB index table as a non-static local, which GCC copies onto the stack at every
// call: three copies per 8 pixels were half of back-projection's time (perf). For
// vectors of at most 8 lanes the indices come from our own static table (one nibble a
// lane, as Highway's) once per mask, and the three vectors share them; wider vectors
// (AVX3, SVE) keep Highway's native compress. Same lanes, same order: the output is
// CompressBlendedStore's, bit for bit.
// kCompressNibbles[bits]: the set lanes of `bits` in ascending order, one nibble each
// from the lowest, the remaining lanes after them.
struct CompressNibbleTable {
  uint32_t nibbles[256];
  constexpr CompressNibbleTable() : nibbles() {
    for (uint32_t bits = 0; bits < 256; ++bits) {
      uint32_t packed = 0;
      int out = 0;
      for (uint32_t lane = 0; lane < 8; ++lane) {
        if (bits & (1u << lane)) packed |= lane << (4 * out++);
      }
      for (uint32_t lane = 0; lane < 8; ++lane) {
        if (!(bits & (1u << lane))) packed |= lane << (4 * out++);
      }
      nibbles[bits] = packed;
    }
  }
};
inline constexpr CompressNibbleTable kCompressNibbles{};

// full: the whole vector may be stored (lanes past the selected ones are don't-care);
// otherwise only the selected lanes are (StoreFirstLanes, store_first_lanes-inl.h).
// colour/oc4: a fourth vector (the packed colours) compacted alike, when oc4 is not null.
template <class DF>
HWY_INLINE std::size_t CompressStore3(DF df, hn::Mask<DF> mask, hn::Vec<DF> a, hn::Vec<DF> b, hn::Vec<DF> c,
                                      float* oa, float* ob, float* oc, bool full,
                                      hn::Vec<hn::RebindToUnsigned<DF>> colour, uint32_t* oc4) {
  const hn::RebindToUnsigned<DF> du;
  if constexpr (hn::MaxLanes(DF()) <= 8) {
    const hn::RebindToSigned<DF> di;
    uint8_t bits[8] = {};
    hn::StoreMaskBits(df, mask, bits);
    const std::size_t count = static_cast<std::size_t>(hwy::PopCount(bits[0]));
    const auto packed = hn::Set(di, static_cast<int32_t>(kCompressNibbles.nibbles[bits[0]]));
    const auto shifts = hn::ShiftLeft<2>(hn::Iota(di, 0));
    const auto lanes = hn::And(hn::Shr(packed, shifts), hn::Set(di, 0xF));
    const auto idx = hn::IndicesFromVec(df, lanes);
    const auto idx_u = hn::IndicesFromVec(du, hn::BitCast(du, lanes));
    if (full) {
      hn::StoreU(hn::TableLookupLanes(a, idx), df, oa);
      hn::StoreU(hn::TableLookupLanes(b, idx), df, ob);
      hn::StoreU(hn::TableLookupLanes(c, idx), df, oc);
      if (oc4 != nullptr) hn::StoreU(hn::TableLookupLanes(colour, idx_u), du, oc4);
    } else {
      StoreFirstLanes(hn::TableLookupLanes(a, idx), df, count, oa);
      StoreFirstLanes(hn::TableLookupLanes(b, idx), df, count, ob);
      StoreFirstLanes(hn::TableLookupLanes(c, idx), df, count, oc);
      if (oc4 != nullptr) StoreFirstLanes(hn::TableLookupLanes(colour, idx_u), du, count, oc4);
    }
    return count;
  } else {
    // SVE, RVV and AVX3: CompressBlendedStore is a true masked store there.
    (void)full;
    hn::CompressBlendedStore(a, mask, df, oa);
    hn::CompressBlendedStore(b, mask, df, ob);
    if (oc4 != nullptr) hn::CompressBlendedStore(colour, hn::RebindMask(du, mask), du, oc4);
    return hn::CompressBlendedStore(c, mask, df, oc);
  }
}

// One vector of pixels starting at column u; depth from `src` (the row, or a padded
// copy of its tail). Writes the valid ones at out + n through CompressStore3 (which
// writes only the selected lanes, or whole vectors below `limit`) and returns the
// new n. With rgb_px (the first lane's colour bytes, not the image's first pixel)
// the colours are gathered and compacted too: 4 bytes from one before each pixel's
// 3, so that no lane reads past the image's last byte.
template <class DF>
HWY_INLINE std::size_t BackprojectVector(DF df, const BackprojectParams& p, const uint16_t* src, int u,
                                         hn::Vec<DF> yn, float* ox, float* oy, float* oz, std::size_t n,
                                         std::size_t limit, const uint8_t* rgb_px = nullptr,
                                         uint32_t* orgb = nullptr) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du32;
  const hn::Rebind<uint16_t, DF> du16;
  const auto raw = hn::BitCast(di, hn::PromoteTo(du32, hn::LoadU(du16, src)));
  const auto valid = hn::And(hn::Gt(raw, hn::Set(di, p.raw_min - 1)), hn::Lt(raw, hn::Set(di, p.raw_max + 1)));
  const auto mask = hn::RebindMask(df, valid);
  // z = float(raw) * scale; x = ((float(u) - cx) * inv_fx) * z; y = yn * z
  const auto z = hn::Mul(hn::ConvertTo(df, raw), hn::Set(df, p.scale));
  const auto uf = hn::ConvertTo(df, hn::Iota(di, u));
  const auto x = hn::Mul(hn::Mul(hn::Sub(uf, hn::Set(df, p.cx)), hn::Set(df, p.inv_fx)), z);
  const auto y = hn::Mul(yn, z);
  // p = (r0 x + r1 y) + r2 z per output axis, no FMA.
  const auto wx = hn::Add(hn::Add(hn::Mul(hn::Set(df, p.r[0]), x), hn::Mul(hn::Set(df, p.r[1]), y)),
                          hn::Mul(hn::Set(df, p.r[2]), z));
  const auto wy = hn::Add(hn::Add(hn::Mul(hn::Set(df, p.r[3]), x), hn::Mul(hn::Set(df, p.r[4]), y)),
                          hn::Mul(hn::Set(df, p.r[5]), z));
  const auto wz = hn::Add(hn::Add(hn::Mul(hn::Set(df, p.r[6]), x), hn::Mul(hn::Set(df, p.r[7]), y)),
                          hn::Mul(hn::Set(df, p.r[8]), z));
  auto colour = hn::Zero(du32);
  if (rgb_px != nullptr && p.has_rgb) {
    // Bytes (b of the pixel before, r, g, b) as a little-endian word: >> 8 gives
    // r | g << 8 | b << 16, and packRgb wants r << 16 | g << 8 | b.
    const auto offsets = hn::Sub(hn::Mul(hn::Iota(di, 0), hn::Set(di, 3)), hn::Set(di, 1));
    const auto word = hn::BitCast(du32, hn::GatherOffset(di, reinterpret_cast<const int32_t*>(rgb_px), offsets));
    const auto rgb = hn::ShiftRight<8>(word);
    const auto byte = hn::Set(du32, 0xFF);
    colour = hn::Or(hn::Or(hn::ShiftLeft<16>(hn::And(rgb, byte)), hn::And(rgb, hn::Set(du32, 0xFF00))),
                    hn::And(hn::ShiftRight<16>(rgb), byte));
  }
  return n + CompressStore3(df, mask, wx, wy, wz, ox + n, oy + n, oz + n, n + hn::Lanes(df) <= limit, colour,
                            orgb != nullptr ? orgb + n : nullptr);
}

// Colours of the valid pixels of columns [q0, q1) of a row, from out + c on (a
// scalar gather of 3 bytes): the image's first vector and the rows' tails.
inline void BackprojectColoursScalar(const BackprojectParams& p, std::size_t row_start, std::size_t q0,
                                     std::size_t q1, std::size_t c) {
  const uint16_t* row = p.depth + row_start;
  for (std::size_t q = q0; q < q1; ++q) {
    const int32_t raw = row[q];
    if (raw < p.raw_min || raw > p.raw_max) continue;
    const uint8_t* px = p.rgb + 3 * (row_start + q);
    p.out_rgb[c++] = p.has_rgb ? packRgb(px[0], px[1], px[2]) : 0u;
  }
}

inline void BackprojectRowsT(const BackprojectParams& p, int row0, int row1, std::size_t out_offset,
                             std::size_t out_limit) {
  const hn::ScalableTag<float> df;
  const std::size_t lanes = hn::Lanes(df);
  const auto w = static_cast<std::size_t>(p.width);
  std::size_t n = out_offset;
  HWY_ALIGN uint16_t tail_depth[HWY_MAX_BYTES / sizeof(float)];
  HWY_ALIGN float tail_x[HWY_MAX_BYTES / sizeof(float)];
  HWY_ALIGN float tail_y[HWY_MAX_BYTES / sizeof(float)];
  HWY_ALIGN float tail_z[HWY_MAX_BYTES / sizeof(float)];
  for (int v = row0; v < row1; ++v) {
    const float yn_scalar = (static_cast<float>(v) - p.cy) * p.inv_fy;  // as the reference
    const auto yn = hn::Set(df, yn_scalar);
    const std::size_t row_start = static_cast<std::size_t>(v) * w;
    const uint16_t* row = p.depth + row_start;
    std::size_t u = 0;
    for (; u + lanes <= w; u += lanes) {
      if (row_start + u > 0) {
        n = BackprojectVector(df, p, row + u, static_cast<int>(u), yn, p.out_x, p.out_y, p.out_z, n, out_limit,
                              p.rgb + 3 * (row_start + u), p.out_rgb);
      } else {  // the image's first pixel has no byte before it
        const std::size_t n0 = n;
        n = BackprojectVector(df, p, row + u, static_cast<int>(u), yn, p.out_x, p.out_y, p.out_z, n, out_limit);
        BackprojectColoursScalar(p, row_start, u, u + lanes, n0);
      }
    }
    if (u < w) {
      // The tail: zero-padded depth (0 is never valid), results staged and copied.
      std::memset(tail_depth, 0, sizeof tail_depth);
      std::memcpy(tail_depth, row + u, (w - u) * sizeof(uint16_t));
      const std::size_t got =
          BackprojectVector(df, p, tail_depth, static_cast<int>(u), yn, tail_x, tail_y, tail_z, 0, lanes);
      std::memcpy(p.out_x + n, tail_x, got * sizeof(float));
      std::memcpy(p.out_y + n, tail_y, got * sizeof(float));
      std::memcpy(p.out_z + n, tail_z, got * sizeof(float));
      BackprojectColoursScalar(p, row_start, u, w, n);
      n += got;
    }
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::kernels
HWY_AFTER_NAMESPACE();

#endif  // include guard
