// Per-target Highway forms of the surfel's codecs (surfel.h) and the 3-vector
// arithmetic the map's kernels share (splat_plan_simd-inl.h): each the
// scalar's operations in its order, so every kernel keeps its reference's bits. Vectors are passed one component at
// a time (SVE's are sizeless: no struct of them).

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_MAP_SURFEL_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_MAP_SURFEL_SIMD_INL_H_
#undef FOVEA_PIPELINE_MAP_SURFEL_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_MAP_SURFEL_SIMD_INL_H_
#endif

#include <cstddef>

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

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::map
HWY_AFTER_NAMESPACE();

#endif  // include guard
