// Per-target body of judgeRowSimd (view_judge.h); compiled once per Highway
// target by view_judge_simd.cpp (through hwy/foreach_target.h). Every function
// that calls a Highway op sits between HWY_BEFORE_NAMESPACE and
// HWY_AFTER_NAMESPACE (GCC 12 on aarch64 refuses to inline the ops otherwise).
//
// Bit for bit the reference (view_judge.cpp): Add, Sub, Mul, Div and
// comparisons in its order, never MulAdd. Every lane is computed; the lanes
// the reference would not look up read pixel 0 and are masked. lround is
// Round (to even) moved up where it left a half below. Tails shorter than a
// vector run on a zero-padded copy of the row (0 is never a valid depth).

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_MAP_VIEW_JUDGE_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_MAP_VIEW_JUDGE_SIMD_INL_H_
#undef FOVEA_PIPELINE_MAP_VIEW_JUDGE_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_MAP_VIEW_JUDGE_SIMD_INL_H_
#endif

#include <cstring>

#include "hwy/highway.h"
#include "pipeline/map/depth_sigma_simd-inl.h"
#include "pipeline/map/view_judge.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::map {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

inline constexpr std::size_t kJudgeMaxLanes = HWY_MAX_BYTES / sizeof(float);

// (m0 a + m1 b) + m2 c, the reference's order.
template <class DF, class V>
HWY_INLINE V RowTimes(DF df, const float* m, V a, V b, V c) {
  const V ab = hn::Add(hn::Mul(hn::Set(df, m[0]), a), hn::Mul(hn::Set(df, m[1]), b));
  return hn::Add(ab, hn::Mul(hn::Set(df, m[2]), c));
}

// lround for c > -0.5: Round ties to even, so a half it left below goes up
// (c - Round(c) is exact there).
template <class DF, class V>
HWY_INLINE V NearestPixel(DF df, V c) {
  const V r = hn::Round(c);
  return hn::IfThenElse(hn::Eq(hn::Sub(c, r), hn::Set(df, 0.5f)), hn::Add(r, hn::Set(df, 1.0f)), r);
}

// The codes of one vector of pixels from column u0 of row v (src: their raw depths).
template <class DF>
HWY_INLINE void JudgeVector(DF df, const ViewJudgeParams& p, const float* r, const float* into, const uint16_t* src,
                            float u0, hn::Vec<DF> yn, uint8_t* out) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du32;
  const hn::Rebind<uint16_t, DF> du16;
  const hn::Rebind<uint8_t, DF> du8;
  const PixelBackprojection& rule = p.rule;
  const ViewLookup& view = p.view;
  const auto raw = hn::BitCast(di, hn::PromoteTo(du32, hn::LoadU(du16, src)));
  const auto valid = hn::RebindMask(df, hn::And(hn::Gt(raw, hn::Set(di, static_cast<int32_t>(rule.raw.min - 1))),
                                                hn::Lt(raw, hn::Set(di, static_cast<int32_t>(rule.raw.max + 1)))));
  // The frame's point, relative to its camera, in the world's axes.
  const auto z = hn::Mul(hn::ConvertTo(df, raw), hn::Set(df, rule.scale));
  const auto x = hn::Mul(hn::Mul(hn::Sub(hn::Iota(df, u0), hn::Set(df, rule.cx)), hn::Set(df, rule.inv_fx)), z);
  const auto y = hn::Mul(yn, z);
  const auto zero = hn::Zero(df);
  const auto px = RowTimes(df, r, x, y, z), py = RowTimes(df, r + 3, x, y, z), pz = RowTimes(df, r + 6, x, y, z);
  // Into the view's camera, projected.
  const auto qx = hn::Add(RowTimes(df, into, px, py, pz), hn::Set(df, p.into.t.x()));
  const auto qy = hn::Add(RowTimes(df, into + 3, px, py, pz), hn::Set(df, p.into.t.y()));
  const auto qz = hn::Add(RowTimes(df, into + 6, px, py, pz), hn::Set(df, p.into.t.z()));
  const auto u = hn::Add(hn::Div(hn::Mul(hn::Set(df, view.fx), qx), qz), hn::Set(df, view.cx));
  const auto v = hn::Add(hn::Div(hn::Mul(hn::Set(df, view.fy), qy), qz), hn::Set(df, view.cy));
  const auto half = hn::Set(df, -0.5f);
  auto inside = hn::And(valid, hn::Gt(qz, zero));
  inside = hn::And(inside, hn::And(hn::Gt(u, half), hn::Lt(u, hn::Set(df, static_cast<float>(view.width) - 0.5f))));
  inside = hn::And(inside, hn::And(hn::Gt(v, half), hn::Lt(v, hn::Set(df, static_cast<float>(view.height) - 0.5f))));
  // The nearest pixel's raw depth: 4 bytes from its element, the low two (little-endian).
  const auto iu = hn::ConvertTo(di, NearestPixel(df, u)), iv = hn::ConvertTo(di, NearestPixel(df, v));
  const auto index = hn::IfThenElseZero(hn::RebindMask(di, inside), hn::Add(hn::Mul(iv, hn::Set(di, view.width)), iu));
  const auto bytes = hn::GatherOffset(di, reinterpret_cast<const int32_t*>(view.raw), hn::ShiftLeft<1>(index));
  const auto seen = hn::Mul(hn::ConvertTo(df, hn::And(bytes, hn::Set(di, 0xffff))), hn::Set(df, view.scale));
  const auto near = hn::Le(hn::Abs(hn::Sub(qz, seen)), hn::Mul(hn::Set(df, view.sigmas), DepthSigma(df, seen)));
  const auto explained = hn::And(inside, hn::And(hn::Gt(seen, zero), near));
  const auto code = hn::IfThenElse(hn::RebindMask(di, explained), hn::Set(di, kJudgedExplained),
                                   hn::IfThenElseZero(hn::RebindMask(di, valid), hn::Set(di, kJudgedUnexplained)));
  hn::StoreU(hn::DemoteTo(du8, code), du8, out);
}

inline void JudgeRowT(const ViewJudgeParams& p, int v, uint8_t* out) {
  const hn::ScalableTag<float> df;
  const std::size_t lanes = hn::Lanes(df);
  const auto w = static_cast<std::size_t>(p.width);
  float r[9], into[9];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) r[3 * i + j] = p.rule.r(i, j), into[3 * i + j] = p.into.R(i, j);
  }
  const auto yn = hn::Set(df, (static_cast<float>(v) - p.rule.cy) * p.rule.inv_fy);
  const uint16_t* row = p.depth + static_cast<std::size_t>(v) * w;
  std::size_t u = 0;
  for (; u + lanes <= w; u += lanes) JudgeVector(df, p, r, into, row + u, static_cast<float>(u), yn, out + u);
  if (u < w) {
    HWY_ALIGN uint16_t tail_depth[kJudgeMaxLanes] = {};
    HWY_ALIGN uint8_t tail_out[kJudgeMaxLanes];
    std::memcpy(tail_depth, row + u, (w - u) * sizeof(uint16_t));
    JudgeVector(df, p, r, into, tail_depth, static_cast<float>(u), yn, tail_out);
    std::memcpy(out + u, tail_out, w - u);
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::map
HWY_AFTER_NAMESPACE();

#endif  // include guard
