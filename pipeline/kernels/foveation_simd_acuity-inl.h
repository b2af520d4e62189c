// The SIMD kernels of ACUITY's model, in float: the levels of points, the image
// pyramid's merge rule, and the refinement test. They build on the gaze geometry and
// the region driver of foveation_simd_gaze-inl.h.
// Per-target bodies, compiled once per Highway target by foveation_simd.cpp, which
// gives the rules every -inl header of these kernels follows (the namespace
// brackets, bit-exactness).

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_ACUITY_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_ACUITY_INL_H_
#undef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_ACUITY_INL_H_
#else
#define FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_ACUITY_INL_H_
#endif

#include <algorithm>
#include <cstring>

#include "hwy/highway.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/kernels/foveation_simd_gaze-inl.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

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

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::kernels
HWY_AFTER_NAMESPACE();

#endif  // include guard
