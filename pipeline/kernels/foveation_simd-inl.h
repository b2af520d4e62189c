// Per-target bodies of the SIMD kernels; compiled once per Highway target by
// foveation_simd.cpp (through hwy/foreach_target.h). Every function that calls a
// Highway op sits between HWY_BEFORE_NAMESPACE and HWY_AFTER_NAMESPACE (GCC 12 on
// aarch64 refuses to inline the ops otherwise).
//
// Bit-exactness rules followed here: only Mul, Add, Sub, Neg, Sqrt, Floor and
// conversions, in the reference's order; never MulAdd (an FMA on AVX2/NEON).
// Tails shorter than a vector run through the same vector code on a padded copy.

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_INL_H_
#undef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_INL_H_
#endif

#include <algorithm>
#include <cstring>

#include "hwy/highway.h"
#include "pipeline/kernels/foveation_simd.h"

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

// full: the whole vector may be stored (lanes past the selected ones are don't-care).
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
      const auto keep = hn::FirstN(df, count);
      hn::BlendedStore(hn::TableLookupLanes(a, idx), keep, df, oa);
      hn::BlendedStore(hn::TableLookupLanes(b, idx), keep, df, ob);
      hn::BlendedStore(hn::TableLookupLanes(c, idx), keep, df, oc);
      if (oc4 != nullptr) hn::BlendedStore(hn::TableLookupLanes(colour, idx_u), hn::FirstN(du, count), du, oc4);
    }
    return count;
  } else {
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

// ---- the point seen from the eye ------------------------------------------------

// With v = P - H (vx, vy, vz) and the unit gaze L: t = v.L, the part of v along the
// gaze, and d = |v - t L|, its distance from the gaze axis, with axialRadial()'s
// expressions in that order (partition.h): t = vx lx + vy ly + vz lz, left to right;
// r = v - t L; d = sqrt(rx^2 + ry^2 + rz^2). In the vectors' precision (double for
// the partition and the hit cone, float for ACUITY's levels). Two functions, not a
// struct: SVE's vectors are sizeless and cannot be members.
template <class D, typename T>
HWY_INLINE hn::Vec<D> AlongGaze(D d, const T* l, hn::Vec<D> vx, hn::Vec<D> vy, hn::Vec<D> vz) {
  return hn::Add(hn::Add(hn::Mul(vx, hn::Set(d, l[0])), hn::Mul(vy, hn::Set(d, l[1]))), hn::Mul(vz, hn::Set(d, l[2])));
}
template <class D, typename T>
HWY_INLINE hn::Vec<D> FromGazeAxis(D d, const T* l, hn::Vec<D> vx, hn::Vec<D> vy, hn::Vec<D> vz, hn::Vec<D> t) {
  const auto rx = hn::Sub(vx, hn::Mul(t, hn::Set(d, l[0])));
  const auto ry = hn::Sub(vy, hn::Mul(t, hn::Set(d, l[1])));
  const auto rz = hn::Sub(vz, hn::Mul(t, hn::Set(d, l[2])));
  return hn::Sqrt(hn::Add(hn::Add(hn::Mul(rx, rx), hn::Mul(ry, ry)), hn::Mul(rz, rz)));
}

// ---- partition ----------------------------------------------------------------

// Regions of one vector of points (x, y, z: float arrays of at least Lanes(dd)).
template <class DD>
HWY_INLINE hn::Vec<DD> PartitionVector(DD dd, const PartitionParams& p, const float* xs, const float* ys,
                                       const float* zs) {
  const hn::Rebind<float, DD> df;
  const auto px = hn::PromoteTo(dd, hn::LoadU(df, xs));
  const auto py = hn::PromoteTo(dd, hn::LoadU(df, ys));
  const auto pz = hn::PromoteTo(dd, hn::LoadU(df, zs));
  const auto finite = hn::And(hn::And(hn::IsFinite(px), hn::IsFinite(py)), hn::IsFinite(pz));
  const auto vx = hn::Add(hn::Set(dd, p.origin_minus_eye[0]), px);
  const auto vy = hn::Add(hn::Set(dd, p.origin_minus_eye[1]), py);
  const auto vz = hn::Add(hn::Set(dd, p.origin_minus_eye[2]), pz);
  const auto t = AlongGaze(dd, p.l, vx, vy, vz);
  const auto d = FromGazeAxis(dd, p.l, vx, vy, vz, t);
  const auto zero = hn::Zero(dd);
  const auto ahead = hn::Ge(t, zero);
  // The first bound that holds wins: walk them from the outermost inwards.
  auto region = hn::Set(dd, static_cast<double>(p.bounds.count));
  for (int j = p.bounds.count - 1; j >= 0; --j) {
    const auto tan_e = hn::Set(dd, p.bounds.tan_e[j]);
    const ConeBounds::Kind kind = p.bounds.kind[j];
    const auto inside = kind == ConeBounds::Kind::kBelow90 ? hn::Le(d, hn::Mul(tan_e, t))
                        : kind == ConeBounds::Kind::kAt90  ? ahead
                                                           : hn::Or(ahead, hn::Ge(d, hn::Mul(tan_e, hn::Neg(t))));
    region = hn::IfThenElse(inside, hn::Set(dd, static_cast<double>(j)), region);
  }
  return hn::IfThenElse(finite, region, hn::Set(dd, static_cast<double>(kRegionInvalid)));
}

// Runs vector(d, xs, ys, zs) (a vector of T, one region per lane: double for the
// partition, float for ACUITY's levels) over points [begin, end), one vector at a time
// (the tail on a zero-padded copy), writes each result as the point's region byte and
// counts them in histogram. The bytes are narrowed in registers: reading the lanes
// back from a vector store would stall on store forwarding at every point.
template <typename T, class VectorFn>
HWY_INLINE void RegionRange(const float* x, const float* y, const float* z, std::size_t begin, std::size_t end,
                            uint8_t* region_out, uint32_t* histogram, const VectorFn& vector) {
  const hn::ScalableTag<T> d;
  const hn::Rebind<int32_t, decltype(d)> di;
  const hn::Rebind<uint8_t, decltype(d)> du8;
  const auto bytes = [&](auto v) {
    if constexpr (sizeof(T) == sizeof(int32_t)) {
      return hn::DemoteTo(du8, hn::ConvertTo(di, v));
    } else {
      return hn::DemoteTo(du8, hn::DemoteTo(di, v));
    }
  };
  const std::size_t lanes = hn::Lanes(d);
  constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(T);
  std::size_t i = begin;
  for (; i + lanes <= end; i += lanes) hn::StoreU(bytes(vector(d, x + i, y + i, z + i)), du8, region_out + i);
  if (i < end) {
    HWY_ALIGN float tx[kMax] = {}, ty[kMax] = {}, tz[kMax] = {};
    HWY_ALIGN uint8_t tail[kMax];
    const std::size_t rest = end - i;
    std::memcpy(tx, x + i, rest * sizeof(float));
    std::memcpy(ty, y + i, rest * sizeof(float));
    std::memcpy(tz, z + i, rest * sizeof(float));
    hn::Store(bytes(vector(d, tx, ty, tz)), du8, tail);
    std::memcpy(region_out + i, tail, rest);
  }
  // Four histograms, byte k counted in part k % 4: neighbouring points mostly share a
  // region, and one counter would make each increment wait for the previous one.
  uint32_t part[4][256] = {};
  std::size_t k = begin;
  for (; k + 4 <= end; k += 4) {
    ++part[0][region_out[k]];
    ++part[1][region_out[k + 1]];
    ++part[2][region_out[k + 2]];
    ++part[3][region_out[k + 3]];
  }
  for (; k < end; ++k) ++part[0][region_out[k]];
  for (int r = 0; r < 256; ++r) histogram[r] += part[0][r] + part[1][r] + part[2][r] + part[3][r];
}

inline void PartitionRangeT(const float* x, const float* y, const float* z, const PartitionParams& p,
                            std::size_t begin, std::size_t end, uint8_t* region_out, uint32_t* histogram) {
  RegionRange<double>(x, y, z, begin, end, region_out, histogram,
              [&p](auto dd, const float* xs, const float* ys, const float* zs) {
                return PartitionVector(dd, p, xs, ys, zs);
              });
}

// ---- ACUITY's levels -------------------------------------------------------------

// How the eye sees one vector of points at v = P - H: eyeViewSpec's expressions, op
// for op, in float. Two functions, not a struct of two vectors: SVE's vectors cannot
// be members. The distance r:
template <class DF>
HWY_INLINE hn::Vec<DF> EyeDistanceVector(DF /* df */, hn::Vec<DF> vx, hn::Vec<DF> vy, hn::Vec<DF> vz) {
  return hn::Sqrt(hn::Add(hn::Add(hn::Mul(vx, vx), hn::Mul(vy, vy)), hn::Mul(vz, vz)));
}
// ... and the eccentricity (t, d, eccentricitySpecDeg), less the growth, clamped at 0.
template <class DF>
HWY_INLINE hn::Vec<DF> EccentricityVector(DF df, const LevelParams& p, hn::Vec<DF> vx, hn::Vec<DF> vy, hn::Vec<DF> vz) {
  const auto t = AlongGaze(df, p.l, vx, vy, vz);
  const auto d = FromGazeAxis(df, p.l, vx, vy, vz, t);
  // eccentricitySpecDeg(t, d)
  const auto zero = hn::Zero(df);
  const auto negative = hn::Lt(t, zero);
  const auto at = hn::IfThenElse(negative, hn::Neg(t), t);
  const auto at_wins = hn::Gt(at, d);
  const auto hi = hn::IfThenElse(at_wins, at, d);
  const auto lo = hn::IfThenElse(at_wins, d, at);
  const auto q = hn::Div(lo, hi);
  const auto q2 = hn::Mul(q, q);
  auto poly = hn::Set(df, kAtanCoefficients[5]);
  for (int k = 4; k >= 0; --k) poly = hn::Add(hn::Mul(poly, q2), hn::Set(df, kAtanCoefficients[k]));
  auto a = hn::Mul(poly, q);
  a = hn::IfThenElse(hn::Gt(d, at), hn::Sub(hn::Set(df, kLevelsHalfPi), a), a);
  a = hn::IfThenElse(negative, hn::Sub(hn::Set(df, kLevelsPi), a), a);
  auto ecc = hn::IfThenElse(hn::Gt(hi, zero), hn::Mul(a, hn::Set(df, kLevelsRadToDeg)), zero);
  // The fovea's growth: max(0, E - g), written as the reference's compare (NaN stays).
  ecc = hn::Sub(ecc, hn::Set(df, p.growth_deg));
  return hn::IfThenElse(hn::Lt(ecc, zero), zero, ecc);
}

// LevelBounds::allowedM: r sinSpec((m ecc + MAR0) deg-to-rad).
template <class DF>
HWY_INLINE hn::Vec<DF> AllowedVector(DF df, const LevelParams& p, hn::Vec<DF> r, hn::Vec<DF> ecc) {
  const auto x = hn::Mul(hn::Add(hn::Mul(hn::Set(df, p.bounds.slope), ecc), hn::Set(df, kLevelsMar0Deg)),
                         hn::Set(df, kLevelsDegToRad));
  const auto half_pi = hn::Set(df, kLevelsHalfPi);
  const auto y = hn::IfThenElse(hn::Lt(x, half_pi), x, half_pi);
  const auto y2 = hn::Mul(y, y);
  auto sin_poly = hn::Set(df, kSinCoefficients[5]);
  for (int k = 4; k >= 0; --k) sin_poly = hn::Add(hn::Mul(sin_poly, y2), hn::Set(df, kSinCoefficients[k]));
  return hn::Mul(r, hn::Mul(sin_poly, y));
}

// The lowest level the floors allow (LevelBounds::floor_level, noiseFloorLevel).
template <class DF>
HWY_INLINE hn::Vec<DF> LowestLevelVector(DF df, const LevelParams& p, hn::Vec<DF> px, hn::Vec<DF> py, hn::Vec<DF> pz) {
  auto lowest = hn::Set(df, static_cast<float>(p.bounds.floor_level));
  if (p.bounds.floor_b_per_m2 > 0.0f) {
    // s^2 from the sensor (the cloud's origin): px^2 + py^2 + pz^2, left to right.
    const auto one = hn::Set(df, 1.0f);
    const auto s2 = hn::Add(hn::Add(hn::Mul(px, px), hn::Mul(py, py)), hn::Mul(pz, pz));
    const auto floor = hn::Add(hn::Set(df, p.bounds.floor_a_m), hn::Mul(hn::Set(df, p.bounds.floor_b_per_m2), s2));
    auto lift = one;
    for (int n = 1; n < kMaxRegions; ++n) {
      lift = hn::Add(lift, hn::IfThenElseZero(hn::Lt(hn::Set(df, p.bounds.voxel_m[n]), floor), one));
    }
    lowest = hn::Max(lowest, hn::Min(lift, hn::Set(df, static_cast<float>(kMaxRegions - 1))));
  }
  return lowest;
}

// Outside the view cull's cone: v.F < r cos(view_cull_deg) (false without a cull).
template <class DF>
HWY_INLINE hn::Mask<DF> OutsideViewVector(DF df, const LevelParams& p, hn::Vec<DF> vx, hn::Vec<DF> vy, hn::Vec<DF> vz,
                                          hn::Vec<DF> r) {
  if (!p.cull) return hn::Lt(hn::Zero(df), hn::Zero(df));
  const auto ft = hn::Add(hn::Add(hn::Mul(vx, hn::Set(df, p.f[0])), hn::Mul(vy, hn::Set(df, p.f[1]))),
                          hn::Mul(vz, hn::Set(df, p.f[2])));
  return hn::Lt(ft, hn::Mul(r, hn::Set(df, p.bounds.cull_cos)));
}

// Levels of one vector of points: assignLevelsRef's expressions, op for op, in float
// (acuity_levels.h: eyeViewSpec, sinSpec, classify).
template <class DF>
HWY_INLINE hn::Vec<DF> LevelVector(DF df, const LevelParams& p, const float* xs, const float* ys, const float* zs) {
  const auto px = hn::LoadU(df, xs);
  const auto py = hn::LoadU(df, ys);
  const auto pz = hn::LoadU(df, zs);
  const auto finite = hn::And(hn::And(hn::IsFinite(px), hn::IsFinite(py)), hn::IsFinite(pz));
  const auto vx = hn::Add(hn::Set(df, p.origin_minus_eye[0]), px);
  const auto vy = hn::Add(hn::Set(df, p.origin_minus_eye[1]), py);
  const auto vz = hn::Add(hn::Set(df, p.origin_minus_eye[2]), pz);
  const auto r = EyeDistanceVector(df, vx, vy, vz);
  const auto ecc = EccentricityVector(df, p, vx, vy, vz);
  const auto zero = hn::Zero(df);
  const auto allowed = AllowedVector(df, p, r, ecc);
  const auto one = hn::Set(df, 1.0f);
  auto level = zero;
  for (int n = 1; n < kMaxRegions; ++n) {
    level = hn::Add(level, hn::IfThenElseZero(hn::Le(hn::Set(df, p.bounds.min_allowed_m[n]), allowed), one));
  }
  level = hn::Max(level, LowestLevelVector(df, p, px, py, pz));
  level = hn::IfThenElse(OutsideViewVector(df, p, vx, vy, vz, r),
                         hn::Set(df, static_cast<float>(p.bounds.cull_region)), level);
  return hn::IfThenElse(finite, level, hn::Set(df, static_cast<float>(kRegionInvalid)));
}

inline void LevelRangeT(const float* x, const float* y, const float* z, const LevelParams& p, std::size_t begin,
                        std::size_t end, uint8_t* region_out, uint32_t* histogram) {
  RegionRange<float>(x, y, z, begin, end, region_out, histogram,
              [&p](auto df, const float* xs, const float* ys, const float* zs) {
                return LevelVector(df, p, xs, ys, zs);
              });
}

// ---- the image pyramid's rule ------------------------------------------------------

// pyramidMergeRef's expressions, op for op, for one vector of cells.
template <class DF>
HWY_INLINE hn::Vec<DF> PyramidMergeVector(DF df, const PyramidMergeParams& p, const float* n, const float* sx,
                                          const float* sy, const float* sz, const float* m2, const float* zmax) {
  const auto inv_n = hn::Div(hn::Set(df, 1.0f), hn::LoadU(df, n));
  const auto mx = hn::Mul(hn::LoadU(df, sx), inv_n);
  const auto my = hn::Mul(hn::LoadU(df, sy), inv_n);
  const auto mz = hn::Mul(hn::LoadU(df, sz), inv_n);
  const auto variance = hn::Mul(hn::LoadU(df, m2), inv_n);
  // std::max(a, b) as the select it is, (a < b) ? b : a, so that NaN goes the same way.
  const auto lateral = hn::Mul(hn::Set(df, p.lateral), hn::LoadU(df, zmax));
  const auto depth_spread = hn::Mul(hn::Set(df, 2.0f), hn::Sqrt(variance));
  const auto e = hn::IfThenElse(hn::Lt(lateral, depth_spread), depth_spread, lateral);
  const auto diagonal = hn::Mul(hn::Set(df, kPyramidSqrt3), e);
  auto floor_merge = hn::Lt(hn::Zero(df), hn::Zero(df));
  if (p.floors) {
    const auto s2 = hn::Add(hn::Add(hn::Mul(mx, mx), hn::Mul(my, my)), hn::Mul(mz, mz));
    floor_merge = hn::Le(e, hn::Add(hn::Set(df, p.floor_m), hn::Mul(hn::Set(df, p.floor_per_m2), s2)));
  }
  // v = R m + (camera - eye); no lambda: SVE's sizeless vectors cannot be captured.
  const auto vx = hn::Add(hn::Add(hn::Add(hn::Mul(hn::Set(df, p.r[0]), mx), hn::Mul(hn::Set(df, p.r[1]), my)),
                                  hn::Mul(hn::Set(df, p.r[2]), mz)),
                          hn::Set(df, p.eye.origin_minus_eye[0]));
  const auto vy = hn::Add(hn::Add(hn::Add(hn::Mul(hn::Set(df, p.r[3]), mx), hn::Mul(hn::Set(df, p.r[4]), my)),
                                  hn::Mul(hn::Set(df, p.r[5]), mz)),
                          hn::Set(df, p.eye.origin_minus_eye[1]));
  const auto vz = hn::Add(hn::Add(hn::Add(hn::Mul(hn::Set(df, p.r[6]), mx), hn::Mul(hn::Set(df, p.r[7]), my)),
                                  hn::Mul(hn::Set(df, p.r[8]), mz)),
                          hn::Set(df, p.eye.origin_minus_eye[2]));
  const auto r = EyeDistanceVector(df, vx, vy, vz);
  const auto ecc_centre = EccentricityVector(df, p.eye, vx, vy, vz);
  const auto r_min = hn::Sub(r, diagonal);
  const auto spread = hn::Mul(hn::Div(diagonal, r_min), hn::Set(df, kLevelsRadToDeg));
  auto ecc = hn::Sub(hn::Sub(ecc_centre, spread), hn::Set(df, p.growth_deg));
  ecc = hn::IfThenElse(hn::Lt(ecc, hn::Zero(df)), hn::Zero(df), ecc);
  const auto allowed = AllowedVector(df, p.eye, r_min, ecc);
  const auto eye_merge = hn::And(hn::Gt(r, hn::Mul(hn::Set(df, 2.0f), diagonal)),
                                 hn::Le(hn::Mul(hn::Set(df, p.margin), e), allowed));
  return hn::IfThenElseZero(hn::Or(floor_merge, eye_merge), hn::Set(df, 1.0f));
}

inline void PyramidMergeRangeT(const PyramidMergeParams& p, const PyramidCellSums& c, std::size_t count,
                               float* merge) {
  const hn::ScalableTag<float> df;
  const std::size_t lanes = hn::Lanes(df);
  std::size_t i = 0;
  for (; i + lanes <= count; i += lanes) {
    hn::StoreU(PyramidMergeVector(df, p, c.n + i, c.sx + i, c.sy + i, c.sz + i, c.m2 + i, c.zmax + i), df,
               merge + i);
  }
  if (i < count) {  // the tail through the same code, zero-padded (n = 0 never merges)
    constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(float);
    HWY_ALIGN float t[6][kMax] = {};
    const float* in[6] = {c.n, c.sx, c.sy, c.sz, c.m2, c.zmax};
    for (int a = 0; a < 6; ++a) std::memcpy(t[a], in[a] + i, (count - i) * sizeof(float));
    HWY_ALIGN float out[kMax];
    hn::Store(PyramidMergeVector(df, p, t[0], t[1], t[2], t[3], t[4], t[5]), df, out);
    std::memcpy(merge + i, out, (count - i) * sizeof(float));
  }
}

// ---- ACUITY's refinement ---------------------------------------------------------

// refineTestRef's states for points [begin, end), op for op in float. Each vector of
// lanes is first copied into aligned arrays with the representatives' coordinates
// gathered beside the points' (lanes past the end or without a representative get
// level 0: kRefineStay). Returns the points beyond their MAR.
inline std::size_t RefineTestRangeT(const float* x, const float* y, const float* z, const LevelParams& p,
                                    const RefineInputs& in, const uint8_t* region, std::size_t begin,
                                    std::size_t end, uint8_t* state) {
  const hn::ScalableTag<float> df;
  const std::size_t lanes = hn::Lanes(df);
  constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(float);
  HWY_ALIGN float px[kMax], py[kMax], pz[kMax], gx[kMax], gy[kMax], gz[kMax], lv[kMax], st[kMax];
  std::size_t beyond = 0;
  for (std::size_t i = begin; i < end; i += lanes) {
    const std::size_t n = std::min(lanes, end - i);
    bool any = false;
    for (std::size_t k = 0; k < lanes; ++k) {
      const uint8_t level = k < n ? region[i + k] : 0;
      const uint32_t o = k < n ? in.representative[i + k] : kNoRepresentative;
      const bool usable = level >= 1 && level < kMaxRegions && o < in.out_size;
      any = any || usable;
      lv[k] = usable ? static_cast<float>(level) : 0.0f;
      px[k] = k < n ? x[i + k] : 0.0f;
      py[k] = k < n ? y[i + k] : 0.0f;
      pz[k] = k < n ? z[i + k] : 0.0f;
      gx[k] = usable ? in.ox[o] : 0.0f;
      gy[k] = usable ? in.oy[o] : 0.0f;
      gz[k] = usable ? in.oz[o] : 0.0f;
    }
    if (!any) {
      std::fill(state + i, state + i + n, kRefineStay);
      continue;
    }
    const auto vpx = hn::Load(df, px);
    const auto vpy = hn::Load(df, py);
    const auto vpz = hn::Load(df, pz);
    const auto level = hn::Load(df, lv);
    const auto vx = hn::Add(hn::Set(df, p.origin_minus_eye[0]), vpx);
    const auto vy = hn::Add(hn::Set(df, p.origin_minus_eye[1]), vpy);
    const auto vz = hn::Add(hn::Set(df, p.origin_minus_eye[2]), vpz);
    const auto r = EyeDistanceVector(df, vx, vy, vz);
    const auto ecc = EccentricityVector(df, p, vx, vy, vz);
    // e = P - R, b = a - e, e x a; the angle is within the MAR when a.b > 0 and
    // |e x a|^2 <= |b|^2 allowed^2.
    const auto ex = hn::Sub(hn::Add(hn::Set(df, in.out_offset[0]), vpx), hn::Load(df, gx));
    const auto ey = hn::Sub(hn::Add(hn::Set(df, in.out_offset[1]), vpy), hn::Load(df, gy));
    const auto ez = hn::Sub(hn::Add(hn::Set(df, in.out_offset[2]), vpz), hn::Load(df, gz));
    const auto bx = hn::Sub(vx, ex);
    const auto by = hn::Sub(vy, ey);
    const auto bz = hn::Sub(vz, ez);
    const auto cx = hn::Sub(hn::Mul(ey, vz), hn::Mul(ez, vy));
    const auto cy = hn::Sub(hn::Mul(ez, vx), hn::Mul(ex, vz));
    const auto cz = hn::Sub(hn::Mul(ex, vy), hn::Mul(ey, vx));
    const auto allowed = AllowedVector(df, p, r, ecc);
    const auto b2 = hn::Add(hn::Add(hn::Mul(bx, bx), hn::Mul(by, by)), hn::Mul(bz, bz));
    const auto ahead = hn::Gt(hn::Add(hn::Add(hn::Mul(vx, bx), hn::Mul(vy, by)), hn::Mul(vz, bz)), hn::Zero(df));
    const auto c2 = hn::Add(hn::Add(hn::Mul(cx, cx), hn::Mul(cy, cy)), hn::Mul(cz, cz));
    const auto within = hn::And(ahead, hn::Le(c2, hn::Mul(b2, hn::Mul(allowed, allowed))));
    const auto above_floor = hn::Gt(level, LowestLevelVector(df, p, vpx, vpy, vpz));
    const auto movable = hn::AndNot(OutsideViewVector(df, p, vx, vy, vz, r), above_floor);
    const auto code = hn::IfThenElse(within, hn::Set(df, static_cast<float>(kRefineWithin)),
                                     hn::Set(df, static_cast<float>(kRefineBeyond)));
    hn::Store(hn::IfThenElseZero(movable, code), df, st);
    for (std::size_t k = 0; k < n; ++k) {
      state[i + k] = static_cast<uint8_t>(st[k]);
      beyond += st[k] == static_cast<float>(kRefineBeyond) ? 1 : 0;
    }
  }
  return beyond;
}

// ---- voxel indices ------------------------------------------------------------

template <class DD>
HWY_INLINE void VoxelIndexVector(DD dd, const float* coord, const uint8_t* region, double origin,
                                 const double* inv_voxel_by_region, double* out) {
  const hn::Rebind<float, DD> df;
  constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(double);
  HWY_ALIGN double inv[kMax];
  const std::size_t lanes = hn::Lanes(dd);
  for (std::size_t k = 0; k < lanes; ++k) inv[k] = inv_voxel_by_region[region[k]];
  const auto p = hn::PromoteTo(dd, hn::LoadU(df, coord));
  // floor((origin + double(p)) * inv_voxel). Highway emulates Floor where the ISA has
  // no rounding instruction (SSSE3, scalar) and returns +0 for -0; floor(x) always
  // has x's sign, so copying it back restores std::floor's bits exactly.
  const auto scaled = hn::Mul(hn::Add(hn::Set(dd, origin), p), hn::Load(dd, inv));
  hn::StoreU(hn::CopySign(hn::Floor(scaled), scaled), dd, out);
}

inline void VoxelIndexRangeT(const float* coord, const uint8_t* region, std::size_t n, double origin,
                             const double* inv_voxel_by_region, double* out) {
  const hn::ScalableTag<double> dd;
  const std::size_t lanes = hn::Lanes(dd);
  std::size_t i = 0;
  for (; i + lanes <= n; i += lanes) VoxelIndexVector(dd, coord + i, region + i, origin, inv_voxel_by_region, out + i);
  if (i < n) {
    constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(double);
    HWY_ALIGN float tc[kMax] = {};
    HWY_ALIGN uint8_t tr[kMax] = {};
    HWY_ALIGN double to[kMax];
    const std::size_t rest = n - i;
    std::memcpy(tc, coord + i, rest * sizeof(float));
    std::memcpy(tr, region + i, rest);
    VoxelIndexVector(dd, tc, tr, origin, inv_voxel_by_region, to);
    std::memcpy(out + i, to, rest * sizeof(double));
  }
}

// ---- fixation: the hit cone --------------------------------------------------

// t of the fovea's points inside the hit cone (t > 0 and d <= tan_cone t, with
// axialRadial()'s expressions), appended in input order; returns how many.
inline std::size_t HitConeRangeT(const float* x, const float* y, const float* z, const uint8_t* region,
                                 std::size_t n, const double* origin_minus_eye, const double* l, double tan_cone,
                                 double* t_out) {
  const hn::ScalableTag<double> dd;
  const hn::Rebind<float, decltype(dd)> df;
  const std::size_t lanes = hn::Lanes(dd);
  constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(double);
  constexpr std::size_t kBlock = 64;  // a multiple of any vector's lane count
  constexpr uint64_t kOnes = 0x0101010101010101ull, kHighs = 0x8080808080808080ull;
  HWY_ALIGN double reg[kMax];
  HWY_ALIGN float tx[kMax], ty[kMax], tz[kMax];
  const auto zero = hn::Zero(dd);
  std::size_t m = 0;
  for (std::size_t b = 0; b < n; b += kBlock) {
    const std::size_t block_end = std::min(n, b + kBlock);
    if (block_end - b == kBlock) {  // 64 points without a fovea byte: skipped (most, except with FREF)
      uint64_t zero_bytes = 0;
      for (std::size_t w = 0; w < kBlock; w += 8) {
        uint64_t word;
        std::memcpy(&word, region + b + w, sizeof word);
        zero_bytes |= (word - kOnes) & ~word & kHighs;
      }
      if (zero_bytes == 0) continue;
    }
    for (std::size_t i = b; i < block_end; i += lanes) {
      const std::size_t valid = std::min(lanes, block_end - i);
      bool any = false;
      for (std::size_t k = 0; k < lanes; ++k) {
        const bool fovea = k < valid && region[i + k] == 0;
        reg[k] = fovea ? 1.0 : 0.0;
        any |= fovea;
      }
      if (!any) continue;
      const float* xs = x + i;
      const float* ys = y + i;
      const float* zs = z + i;
      if (valid < lanes) {  // the cloud's tail, zero-padded (padding is not in the fovea)
        std::fill(tx, tx + kMax, 0.0f), std::fill(ty, ty + kMax, 0.0f), std::fill(tz, tz + kMax, 0.0f);
        std::memcpy(tx, xs, valid * sizeof(float));
        std::memcpy(ty, ys, valid * sizeof(float));
        std::memcpy(tz, zs, valid * sizeof(float));
        xs = tx, ys = ty, zs = tz;
      }
      const auto vx = hn::Add(hn::Set(dd, origin_minus_eye[0]), hn::PromoteTo(dd, hn::LoadU(df, xs)));
      const auto vy = hn::Add(hn::Set(dd, origin_minus_eye[1]), hn::PromoteTo(dd, hn::LoadU(df, ys)));
      const auto vz = hn::Add(hn::Set(dd, origin_minus_eye[2]), hn::PromoteTo(dd, hn::LoadU(df, zs)));
      const auto t = AlongGaze(dd, l, vx, vy, vz);
      const auto d = FromGazeAxis(dd, l, vx, vy, vz, t);
      const auto inside = hn::And(hn::And(hn::Gt(hn::Load(dd, reg), zero), hn::Gt(t, zero)),
                                  hn::Le(d, hn::Mul(hn::Set(dd, tan_cone), t)));
      m += hn::CompressBlendedStore(t, inside, dd, t_out + m);
    }
  }
  return m;
}

// ---- packed voxel keys (hash sampler) -------------------------------------------

// Index ranges of the region of the last run of single-region vectors, kept in vectors
// and folded into the state when the region changes (and at the end). Vectors are
// separate variables, not arrays or struct members: SVE's vector types are sizeless.
#define FOVEA_KEY_RUN_PARAMS int &run_region, V &run_lo0, V &run_lo1, V &run_lo2, V &run_hi0, V &run_hi1, V &run_hi2
#define FOVEA_KEY_RUN_ARGS run_region, run_lo0, run_lo1, run_lo2, run_hi0, run_hi1, run_hi2

template <class DD, class V>
HWY_INLINE void FlushKeyRanges(DD dd, VoxelKeyState& st, FOVEA_KEY_RUN_PARAMS) {
  if (run_region < 0) return;
  double* lo = st.lo[run_region];
  double* hi = st.hi[run_region];
  lo[0] = std::min(lo[0], hn::GetLane(hn::MinOfLanes(dd, run_lo0)));
  lo[1] = std::min(lo[1], hn::GetLane(hn::MinOfLanes(dd, run_lo1)));
  lo[2] = std::min(lo[2], hn::GetLane(hn::MinOfLanes(dd, run_lo2)));
  hi[0] = std::max(hi[0], hn::GetLane(hn::MaxOfLanes(dd, run_hi0)));
  hi[1] = std::max(hi[1], hn::GetLane(hn::MaxOfLanes(dd, run_hi1)));
  hi[2] = std::max(hi[2], hn::GetLane(hn::MaxOfLanes(dd, run_hi2)));
  run_region = -1;
}

// floor((origin + double(p)) * inv_voxel) along one axis: exactly VoxelIndexVector
// (Highway's emulated Floor returns +0 for -0; floor(x) has x's sign, copied back).
template <class DD, class V>
HWY_INLINE V VoxelIndex1(DD dd, const float* coord, double origin, V inv) {
  const hn::Rebind<float, DD> df;
  const auto p = hn::PromoteTo(dd, hn::LoadU(df, coord));
  const auto scaled = hn::Mul(hn::Add(hn::Set(dd, origin), p), inv);
  return hn::CopySign(hn::Floor(scaled), scaled);
}

// The low 20 bits of an integral index below 2^51 in magnitude: plus 1.5 * 2^52 it is
// exact, and its low mantissa bits are the index modulo 2^52.
template <class DD, class V>
HWY_INLINE auto WrappedIndex(DD dd, V index) {
  const hn::RebindToUnsigned<DD> du;
  return hn::And(hn::BitCast(du, hn::Add(index, hn::Set(dd, 6755399441055744.0))),
                 hn::Set(du, (uint64_t{1} << kVoxelAxisBits) - 1));
}

// One vector of points; `valid` lanes are real (the rest is padding with region
// kRegionInvalid). Returns false, leaving the state and key_out untouched, if a sampled
// lane's index is not below 2^51 in magnitude (the caller then does these points with
// the scalar code, which also tells a bad index from a merely large one).
template <class DD, class V>
HWY_INLINE bool VoxelKeyVector(DD dd, const float* x, const float* y, const float* z, const uint8_t* region,
                               std::size_t valid, VoxelKeyState& st, uint64_t* key_out, FOVEA_KEY_RUN_PARAMS) {
  const hn::RebindToUnsigned<DD> du;
  constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(double);
  const std::size_t lanes = hn::Lanes(dd);
  const auto limit = hn::Set(dd, 2251799813685248.0);  // 2^51
  const uint8_t r0 = region[0];
  bool uniform = valid == lanes;
  for (std::size_t k = 1; k < lanes; ++k) uniform &= region[k] == r0;
  if (uniform) {  // the common case: one region across the vector
    if (r0 < 1 || r0 >= st.region_count) {  // fovea or skipped: no index at all
      hn::StoreU(hn::Set(du, kNoVoxelKey), du, key_out);
      st.histogram[r0] += static_cast<uint32_t>(lanes);
      return true;
    }
    const auto inv = hn::Set(dd, st.inv_voxel[r0]);
    const V i0 = VoxelIndex1(dd, x, st.origin[0], inv);
    const V i1 = VoxelIndex1(dd, y, st.origin[1], inv);
    const V i2 = VoxelIndex1(dd, z, st.origin[2], inv);
    const auto ok = hn::And(hn::And(hn::Lt(hn::Abs(i0), limit), hn::Lt(hn::Abs(i1), limit)), hn::Lt(hn::Abs(i2), limit));
    if (!hn::AllTrue(dd, ok)) return false;
    auto key = hn::Set(du, uint64_t{r0} << (3 * kVoxelAxisBits));
    key = hn::Or(key, hn::ShiftLeft<2 * kVoxelAxisBits>(WrappedIndex(dd, i0)));
    key = hn::Or(key, hn::ShiftLeft<kVoxelAxisBits>(WrappedIndex(dd, i1)));
    key = hn::Or(key, WrappedIndex(dd, i2));
    hn::StoreU(key, du, key_out);
    st.histogram[r0] += static_cast<uint32_t>(lanes);
    if (run_region != r0) {
      FlushKeyRanges(dd, st, FOVEA_KEY_RUN_ARGS);
      run_region = r0;
      run_lo0 = run_hi0 = i0;
      run_lo1 = run_hi1 = i1;
      run_lo2 = run_hi2 = i2;
    } else {
      run_lo0 = hn::Min(run_lo0, i0), run_hi0 = hn::Max(run_hi0, i0);
      run_lo1 = hn::Min(run_lo1, i1), run_hi1 = hn::Max(run_hi1, i1);
      run_lo2 = hn::Min(run_lo2, i2), run_hi2 = hn::Max(run_hi2, i2);
    }
    return true;
  }
  HWY_ALIGN double inv[kMax];
  HWY_ALIGN uint64_t reg[kMax];
  HWY_ALIGN double regd[kMax];
  for (std::size_t k = 0; k < lanes; ++k) {
    inv[k] = st.inv_voxel[region[k]];
    reg[k] = region[k];
    regd[k] = static_cast<double>(region[k]);
  }
  const auto vregd = hn::Load(dd, regd);
  const auto is_sampled = hn::And(hn::Ge(vregd, hn::Set(dd, 1.0)),
                                  hn::Lt(vregd, hn::Set(dd, static_cast<double>(st.region_count))));
  const auto vinv = hn::Load(dd, inv);
  const V i0 = VoxelIndex1(dd, x, st.origin[0], vinv);
  const V i1 = VoxelIndex1(dd, y, st.origin[1], vinv);
  const V i2 = VoxelIndex1(dd, z, st.origin[2], vinv);
  const auto ok = hn::And(hn::And(hn::Lt(hn::Abs(i0), limit), hn::Lt(hn::Abs(i1), limit)), hn::Lt(hn::Abs(i2), limit));
  if (!hn::AllFalse(dd, hn::AndNot(ok, is_sampled))) return false;
  auto key = hn::ShiftLeft<3 * kVoxelAxisBits>(hn::Load(du, reg));
  key = hn::Or(key, hn::ShiftLeft<2 * kVoxelAxisBits>(WrappedIndex(dd, i0)));
  key = hn::Or(key, hn::ShiftLeft<kVoxelAxisBits>(WrappedIndex(dd, i1)));
  key = hn::Or(key, WrappedIndex(dd, i2));
  hn::StoreU(hn::IfThenElse(hn::RebindMask(du, is_sampled), key, hn::Set(du, kNoVoxelKey)), du, key_out);
  HWY_ALIGN double idx[3][kMax];
  hn::Store(i0, dd, idx[0]);
  hn::Store(i1, dd, idx[1]);
  hn::Store(i2, dd, idx[2]);
  for (std::size_t k = 0; k < valid; ++k) {
    const uint8_t r = region[k];
    ++st.histogram[r];
    if (r < 1 || r >= st.region_count) continue;
    for (int a = 0; a < 3; ++a) {
      st.lo[r][a] = std::min(st.lo[r][a], idx[a][k]);
      st.hi[r][a] = std::max(st.hi[r][a], idx[a][k]);
    }
  }
  return true;
}

inline std::size_t VoxelKeyRangeT(const float* x, const float* y, const float* z, const uint8_t* region,
                                  std::size_t n, VoxelKeyState& st, uint64_t* key_out) {
  const hn::ScalableTag<double> dd;
  using V = decltype(hn::Zero(dd));
  const std::size_t lanes = hn::Lanes(dd);
  int run_region = -1;
  V run_lo0 = hn::Zero(dd), run_lo1 = hn::Zero(dd), run_lo2 = hn::Zero(dd);
  V run_hi0 = hn::Zero(dd), run_hi1 = hn::Zero(dd), run_hi2 = hn::Zero(dd);
  std::size_t i = 0;
  for (; i + lanes <= n; i += lanes) {
    if (HWY_UNLIKELY(!VoxelKeyVector(dd, x + i, y + i, z + i, region + i, lanes, st, key_out + i, FOVEA_KEY_RUN_ARGS))) {
      FlushKeyRanges(dd, st, FOVEA_KEY_RUN_ARGS);
      return i;
    }
  }
  FlushKeyRanges(dd, st, FOVEA_KEY_RUN_ARGS);
  if (i < n) {
    constexpr std::size_t kMax = HWY_MAX_BYTES / sizeof(double);
    HWY_ALIGN float tx[kMax] = {}, ty[kMax] = {}, tz[kMax] = {};
    HWY_ALIGN uint8_t tr[kMax];
    HWY_ALIGN uint64_t tk[kMax];
    std::fill(tr, tr + kMax, kRegionInvalid);
    const std::size_t rest = n - i;
    std::memcpy(tx, x + i, rest * sizeof(float));
    std::memcpy(ty, y + i, rest * sizeof(float));
    std::memcpy(tz, z + i, rest * sizeof(float));
    std::memcpy(tr, region + i, rest);
    if (!VoxelKeyVector(dd, tx, ty, tz, tr, rest, st, tk, FOVEA_KEY_RUN_ARGS)) return i;
    std::memcpy(key_out + i, tk, rest * sizeof(uint64_t));
  }
  return n;
}

#undef FOVEA_KEY_RUN_PARAMS
#undef FOVEA_KEY_RUN_ARGS

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::kernels
HWY_AFTER_NAMESPACE();

#endif  // include guard
