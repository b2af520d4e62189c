// Per-target Highway forms of the surfel's loads and codecs (surfel.h) and the
// 3-vector arithmetic the map's kernels share (splat_plan_simd-inl.h,
// association_plan_simd-inl.h): each the scalar's operations in its order, so
// every kernel keeps its reference's bits. Vectors are passed one component at
// a time (SVE's are sizeless: no struct of them).

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_MAP_SURFEL_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_MAP_SURFEL_SIMD_INL_H_
#undef FOVEA_PIPELINE_MAP_SURFEL_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_MAP_SURFEL_SIMD_INL_H_
#endif

#include <cstddef>
#include <cstring>
#include <limits>

#include "hwy/highway.h"
#include "pipeline/map/surfel.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::map {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// One 32-bit field of the surfels at `word` (a surfel's first word, by lane),
// gathered: the pool read as structure of arrays. (Vectors are not members of
// a struct here: SVE's are sizeless.)
template <class D, class VI>
HWY_INLINE hn::Vec<D> GatherField(D d, const Surfel* surfels, std::size_t offset, VI word) {
  return hn::GatherIndex(d, reinterpret_cast<const hn::TFromD<D>*>(surfels) + offset / 4, word);
}

// The surfels at `surfels`, one a lane (as many as DF has), loaded whole and
// transposed into their fields, where GatherField would load each field lane
// by lane: a surfel is four 64-bit words (x|y, z|normal_radius,
// colour|confidence, first_seen|last_seen, the first of each pair in its low
// half on the little-endian targets fovea builds for), which two
// LoadInterleaved4 split by word and ConcatEven and ConcatOdd by half (the
// index map's first pass 0.77x on a pool of 920 000 surfels, docs/map.md).
// `colour`: red, green, blue, flags; `confidence_brick`: confidence | brick << 16.
// (Not on HWY_SCALAR: one lane, no 64-bit half vector.)
#if HWY_TARGET != HWY_SCALAR
template <class DF, class V, class VU>
HWY_INLINE void LoadSurfels(DF df, const Surfel* surfels, V& x, V& y, V& z, VU& normal_radius, VU& colour,
                            VU& confidence_brick, VU& first_seen) {
  static_assert(offsetof(Surfel, y) == 4 && offsetof(Surfel, z) == 8 && offsetof(Surfel, normal_radius) == 12 &&
                offsetof(Surfel, red) == 16 && offsetof(Surfel, confidence) == 20 && offsetof(Surfel, brick) == 22 &&
                offsetof(Surfel, first_seen) == 24);
  const hn::RebindToUnsigned<DF> du;
  const hn::Repartition<uint64_t, DF> d64;
  const auto* words = reinterpret_cast<const uint64_t*>(surfels);
  hn::Vec<decltype(d64)> lo0, lo1, lo2, lo3, hi0, hi1, hi2, hi3;
  hn::LoadInterleaved4(d64, words, lo0, lo1, lo2, lo3);                     // the first half of the surfels
  hn::LoadInterleaved4(d64, words + 4 * hn::Lanes(d64), hi0, hi1, hi2, hi3);  // the second
  x = hn::BitCast(df, hn::ConcatEven(du, hn::BitCast(du, hi0), hn::BitCast(du, lo0)));
  y = hn::BitCast(df, hn::ConcatOdd(du, hn::BitCast(du, hi0), hn::BitCast(du, lo0)));
  z = hn::BitCast(df, hn::ConcatEven(du, hn::BitCast(du, hi1), hn::BitCast(du, lo1)));
  normal_radius = hn::ConcatOdd(du, hn::BitCast(du, hi1), hn::BitCast(du, lo1));
  colour = hn::ConcatEven(du, hn::BitCast(du, hi2), hn::BitCast(du, lo2));
  confidence_brick = hn::ConcatOdd(du, hn::BitCast(du, hi2), hn::BitCast(du, lo2));
  first_seen = hn::ConcatEven(du, hn::BitCast(du, hi3), hn::BitCast(du, lo3));
}
#endif

// The same fields of the surfels at `word` (a surfel's first word, by lane),
// gathered a field at a time.
template <class DF, class VI, class V, class VU>
HWY_INLINE void GatherSurfels(DF df, const Surfel* surfels, VI word, V& x, V& y, V& z, VU& normal_radius, VU& colour,
                              VU& confidence_brick, VU& first_seen) {
  const hn::RebindToUnsigned<DF> du;
  x = GatherField(df, surfels, offsetof(Surfel, x), word);
  y = GatherField(df, surfels, offsetof(Surfel, y), word);
  z = GatherField(df, surfels, offsetof(Surfel, z), word);
  normal_radius = GatherField(du, surfels, offsetof(Surfel, normal_radius), word);
  colour = GatherField(du, surfels, offsetof(Surfel, red), word);
  confidence_brick = GatherField(du, surfels, offsetof(Surfel, confidence), word);
  first_seen = GatherField(du, surfels, offsetof(Surfel, first_seen), word);
}

// The same fields of the surfels at `slot` (a slot a lane, anywhere in the
// pool): each surfel copied whole into a row of a buffer, the rows transposed
// (LoadSurfels), where a gather a field loads lane by lane.
template <class DF, class V, class VU>
HWY_INLINE void LoadSurfelsAt(DF df, const Surfel* surfels, VU slot, V& x, V& y, V& z, VU& normal_radius, VU& colour,
                              VU& confidence_brick, VU& first_seen) {
  const hn::RebindToUnsigned<DF> du;
#if HWY_TARGET != HWY_SCALAR
  constexpr std::size_t kMaxLanes = HWY_MAX_BYTES / sizeof(float);
  HWY_ALIGN uint32_t at[kMaxLanes];
  alignas(sizeof(Surfel)) unsigned char rows[kMaxLanes * sizeof(Surfel)];
  hn::Store(slot, du, at);
  for (std::size_t l = 0; l < hn::Lanes(du); ++l) std::memcpy(rows + l * sizeof(Surfel), &surfels[at[l]], sizeof(Surfel));
  LoadSurfels(df, reinterpret_cast<const Surfel*>(rows), x, y, z, normal_radius, colour, confidence_brick, first_seen);
#else
  const hn::RebindToSigned<DF> di;
  const auto word = hn::BitCast(di, hn::Mul(slot, hn::Set(du, static_cast<uint32_t>(sizeof(Surfel) / sizeof(uint32_t)))));
  GatherSurfels(df, surfels, word, x, y, z, normal_radius, colour, confidence_brick, first_seen);
#endif
}

// A 3-vector dot product in the reference's order, a0 b0 + (a1 b1 + a2 b2).
template <class V>
HWY_INLINE V Dot3(V a0, V a1, V a2, V b0, V b1, V b2) {
  return hn::Add(hn::Mul(a0, b0), hn::Add(hn::Mul(a1, b1), hn::Mul(a2, b2)));
}

// r * (x, y, z), row i (r row-major).
template <class DF, class V>
HWY_INLINE V RotateRow(DF df, const float* r, V x, V y, V z) {
  return Dot3(hn::Set(df, r[0]), hn::Set(df, r[1]), hn::Set(df, r[2]), x, y, z);
}

// decodeDirection (surfel.h) of the normal code (normal_radius >> 8), per lane.
template <class DF, class VU>
HWY_INLINE void DecodeDirection(DF df, VU normal_radius, hn::Vec<DF>& nx, hn::Vec<DF>& ny, hn::Vec<DF>& nz) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du;
  const float* unit = surfel_detail::kUnitTable.data();
  const auto mask = hn::Set(du, 0xfffu);
  const auto u = hn::GatherIndex(df, unit, hn::BitCast(di, hn::And(hn::ShiftRight<20>(normal_radius), mask)));
  const auto v = hn::GatherIndex(df, unit, hn::BitCast(di, hn::And(hn::ShiftRight<8>(normal_radius), mask)));
  const auto one = hn::Set(df, 1.0f);
  const auto z = hn::Sub(hn::Sub(one, hn::Abs(u)), hn::Abs(v));
  const auto sign_u = hn::IfThenElse(hn::Lt(u, hn::Zero(df)), hn::Set(df, -1.0f), one);
  const auto sign_v = hn::IfThenElse(hn::Lt(v, hn::Zero(df)), hn::Set(df, -1.0f), one);
  const auto fold = hn::Lt(z, hn::Zero(df));
  nx = hn::IfThenElse(fold, hn::Mul(hn::Sub(one, hn::Abs(v)), sign_u), u);
  ny = hn::IfThenElse(fold, hn::Mul(hn::Sub(one, hn::Abs(u)), sign_v), v);
  nz = z;
}

// surfel_detail::quantiseUnit, per lane.
template <class DF, class V>
HWY_INLINE hn::Vec<hn::RebindToUnsigned<DF>> QuantiseUnit(DF df, V x) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du;
  const auto half = hn::Set(df, 0.5f), steps = hn::Set(df, surfel_detail::kNormalSteps);
  const auto q = hn::Add(hn::Mul(hn::Add(hn::Mul(x, half), half), steps), half);
  return hn::BitCast(du, hn::ConvertTo(di, hn::Min(hn::Max(q, hn::Zero(df)), steps)));
}

// encodeNormal (surfel.h) of (nx, ny, nz), per lane.
template <class DF, class V>
HWY_INLINE hn::Vec<hn::RebindToUnsigned<DF>> EncodeNormal(DF df, V nx, V ny, V nz) {
  const hn::RebindToUnsigned<DF> du;
  const auto one = hn::Set(df, 1.0f), zero = hn::Zero(df);
  const auto l1 = hn::Add(hn::Add(hn::Abs(nx), hn::Abs(ny)), hn::Abs(nz));
  const auto usable = hn::And(hn::Gt(l1, zero), hn::Lt(l1, hn::Set(df, std::numeric_limits<float>::infinity())));
  const auto inv_l1 = hn::Div(one, l1);
  auto u = hn::Mul(nx, inv_l1), v = hn::Mul(ny, inv_l1);
  const auto sign_u = hn::IfThenElse(hn::Lt(u, zero), hn::Set(df, -1.0f), one);
  const auto sign_v = hn::IfThenElse(hn::Lt(v, zero), hn::Set(df, -1.0f), one);
  const auto fold = hn::Lt(nz, zero);
  const auto fu = hn::Mul(hn::Sub(one, hn::Abs(v)), sign_u);
  const auto fv = hn::Mul(hn::Sub(one, hn::Abs(u)), sign_v);
  u = hn::IfThenElse(fold, fu, u);
  v = hn::IfThenElse(fold, fv, v);
  // An unusable lane's operands may be NaN: quantised as 0 first, then replaced.
  const auto code = hn::Or(hn::ShiftLeft<12>(QuantiseUnit(df, hn::IfThenElseZero(usable, u))),
                           QuantiseUnit(df, hn::IfThenElseZero(usable, v)));
  const uint32_t plus_z = (surfel_detail::quantiseUnit(0.0f) << 12) | surfel_detail::quantiseUnit(0.0f);
  return hn::IfThenElse(hn::RebindMask(du, usable), code, hn::Set(du, plus_z));
}

// encodeRadius (surfel.h), per lane: the tables of kRadiusCodes.
template <class DF, class V>
HWY_INLINE hn::Vec<hn::RebindToUnsigned<DF>> EncodeRadius(DF df, V radius) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du;
  const auto small = hn::Not(hn::Gt(radius, hn::Set(df, kMinRadiusM)));
  const auto large = hn::Ge(radius, hn::Set(df, kMaxRadiusM));
  const auto inside = hn::RebindMask(du, hn::Not(hn::Or(small, large)));
  const auto bucket = hn::IfThenElseZero(
      inside, hn::ShiftRight<RadiusCodeTables::kBucketShift>(hn::Sub(hn::BitCast(du, radius), hn::Set(du, kRadiusCodes.lowest_bits))));
  const auto code = hn::GatherIndex(du, kRadiusCodes.bucket_code.data(), hn::BitCast(di, bucket));
  const auto next = hn::GatherIndex(df, kRadiusCodes.lowest_radius.data(), hn::BitCast(di, hn::Add(code, hn::Set(du, 1u))));
  const auto rounded = hn::IfThenElse(hn::RebindMask(du, hn::Ge(radius, next)), hn::Add(code, hn::Set(du, 1u)), code);
  return hn::IfThenElse(hn::RebindMask(du, small), hn::Zero(du),
                        hn::IfThenElse(hn::RebindMask(du, large), hn::Set(du, 255u), rounded));
}

// decodeConfidence (surfel.h) of 16-bit codes in 32-bit lanes.
template <class DF, class VU>
HWY_INLINE hn::Vec<DF> DecodeConfidence(DF df, VU code) {
  const hn::RebindToSigned<DF> di;
  return hn::Div(hn::ConvertTo(df, hn::BitCast(di, code)), hn::Set(df, kConfidenceScale));
}

// encodeConfidence (surfel.h), per lane, as 32-bit lanes.
template <class DF, class V>
HWY_INLINE hn::Vec<hn::RebindToUnsigned<DF>> EncodeConfidence(DF df, V c) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du;
  const auto scaled = hn::Add(hn::Mul(c, hn::Set(df, kConfidenceScale)), hn::Set(df, 0.5f));
  const auto top = hn::Ge(scaled, hn::Set(df, 65535.0f));
  const auto bottom = hn::Le(scaled, hn::Zero(df));
  const auto inside = hn::Not(hn::Or(top, bottom));
  const auto code = hn::BitCast(du, hn::ConvertTo(di, hn::IfThenElseZero(inside, scaled)));
  return hn::IfThenElse(hn::RebindMask(du, top), hn::Set(du, 65535u), code);
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::map
HWY_AFTER_NAMESPACE();

#endif  // include guard
