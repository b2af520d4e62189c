// Per-target body of planSplatsSimd (splat_plan.h); compiled once per Highway
// target by splat_plan_simd.cpp. Bit for bit planSplatsRef: a vector of slots
// at a time, the 32-byte surfels transposed into a vector a field (the pool
// read as structure of arrays), the tables (brick origins and
// culling, normal and radius codes, the frame's depth and weight) gathered by
// index, and every lane computed in the reference's order of operations (Add,
// Sub, Mul, Div, never MulAdd). Lanes past `count` repeat the last surfel and
// store into the plan's room past count (kSize is a multiple of the lanes).
// PlanVector and PlanCentres are not inlined: as one function the emulated
// 128-bit target took clang 9.3 s to compile under ASan, as two 3.5 s, at the
// same speed (docs/kernels.md).

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_MAP_SPLAT_PLAN_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_MAP_SPLAT_PLAN_SIMD_INL_H_
#undef FOVEA_PIPELINE_MAP_SPLAT_PLAN_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_MAP_SPLAT_PLAN_SIMD_INL_H_
#endif

#include <cstddef>

#include "hwy/highway.h"
#include "pipeline/map/depth_sigma_simd-inl.h"
#include "pipeline/map/index_map.h"
#include "pipeline/map/splat_plan.h"
#include "pipeline/map/surfel_simd-inl.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::map {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// roundHalfAwayFromZero (map_kernels.h), per lane.
template <class DF, class V>
HWY_INLINE hn::Vec<hn::RebindToSigned<DF>> RoundHalfAway(DF df, V x) {
  const hn::RebindToSigned<DF> di;
  const auto t = hn::ConvertTo(di, x);
  const auto frac = hn::Sub(x, hn::ConvertTo(df, t));
  const auto up = hn::RebindMask(di, hn::Ge(frac, hn::Set(df, 0.5f)));
  const auto down = hn::RebindMask(di, hn::Le(frac, hn::Set(df, -0.5f)));
  return hn::IfThenElse(up, hn::Add(t, hn::Set(di, 1)), hn::IfThenElse(down, hn::Sub(t, hn::Set(di, 1)), t));
}

// planCentre (splat_plan.cpp) for every lane, stored at j0.
template <class DF, class V, class VI, class VU>
HWY_NOINLINE void PlanCentres(DF df, const SplatFrame& f, VU normal_radius, VU confidence, V px, V py, V pz, VI iu, VI iv,
                            std::size_t j0, SplatPlan& plan) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du;
  const auto radius = hn::GatherIndex(df, kRadiusTable.data(), hn::BitCast(di, hn::And(normal_radius, hn::Set(du, 0xffu))));
  const auto footprint = hn::Div(hn::Mul(hn::Set(df, f.f), radius), pz);
  const auto reach = hn::Min(hn::Max(hn::ConvertTo(di, footprint), hn::Zero(di)), hn::Set(di, kMaxReach));
  hn::StoreU(hn::BitCast(du, reach), du, plan.reach + j0);
  V dx, dy, dz;
  DecodeDirection(df, normal_radius, dx, dy, dz);
  const V nx = RotateRow(df, f.r, dx, dy, dz), ny = RotateRow(df, f.r + 3, dx, dy, dz), nz = RotateRow(df, f.r + 6, dx, dy, dz);
  const auto one = hn::Set(df, 1.0f);
  const auto inv_plane = hn::Div(one, Dot3(nx, ny, nz, px, py, pz));
  const auto rx = hn::Mul(hn::Sub(hn::ConvertTo(df, iu), hn::Set(df, f.cx)), hn::Set(df, f.inv_fx));
  const auto ry = hn::Mul(hn::Sub(hn::ConvertTo(df, iv), hn::Set(df, f.cy)), hn::Set(df, f.inv_fy));
  const auto along = hn::Add(hn::Mul(nx, rx), hn::Add(hn::Mul(ny, ry), nz));
  const auto ray_sq = hn::Add(hn::Add(hn::Mul(rx, rx), hn::Mul(ry, ry)), one);
  const auto n_sq = Dot3(nx, ny, nz, nx, ny, nz);
  const auto steep = hn::Gt(hn::Mul(along, along), hn::Mul(hn::Mul(hn::Set(df, 0.04f), ray_sq), n_sq));
  const auto on_plane = hn::Mul(along, inv_plane);
  const auto sloped = hn::And(hn::And(steep, hn::Le(hn::Mul(on_plane, hn::Set(df, f.min_z)), one)),
                              hn::Gt(on_plane, hn::Zero(df)));
  const auto depth = hn::IfThenElse(sloped, hn::Div(one, on_plane), pz);
  hn::StoreU(hn::IfThenElse(sloped, on_plane, hn::Div(one, pz)), df, plan.inv_depth + j0);
  hn::StoreU(depth, df, plan.depth + j0);
  hn::StoreU(hn::IfThenElseZero(sloped, hn::Mul(hn::Mul(nx, hn::Set(df, f.inv_fx)), inv_plane)), df, plan.grad_u + j0);
  hn::StoreU(hn::IfThenElseZero(sloped, hn::Mul(hn::Mul(ny, hn::Set(df, f.inv_fy)), inv_plane)), df, plan.grad_v + j0);
  hn::StoreU(hn::Mul(hn::Set(df, f.sigmas), DepthSigma(df, depth)), df, plan.same + j0);
  const auto rank = hn::Sub(hn::Set(du, 255u), hn::Min(hn::ShiftRight<5>(confidence), hn::Set(du, 255u)));
  hn::StoreU(rank, du, plan.rank + j0);
}

// The surfels at j0, a field a vector: a whole vector of them loaded and
// transposed (LoadSurfels), the last, partial one gathered with the lanes past
// count repeating the last surfel.
template <class DF, class V, class VU>
HWY_INLINE void SurfelFields(DF df, const Surfel* surfels, std::size_t j0, std::size_t count, V& x, V& y, V& z,
                             VU& normal_radius, VU& colour, VU& confidence_brick, VU& first_seen) {
  const hn::RebindToSigned<DF> di;
#if HWY_TARGET != HWY_SCALAR
  if (j0 + hn::Lanes(df) <= count) {
    LoadSurfels(df, surfels + j0, x, y, z, normal_radius, colour, confidence_brick, first_seen);
    return;
  }
#endif
  const auto lane = hn::Min(hn::Iota(di, static_cast<int32_t>(j0)), hn::Set(di, static_cast<int32_t>(count - 1)));
  const auto word = hn::Mul(lane, hn::Set(di, static_cast<int32_t>(sizeof(Surfel) / sizeof(uint32_t))));
  GatherSurfels(df, surfels, word, x, y, z, normal_radius, colour, confidence_brick, first_seen);
}

// The lanes at j0: their actions, the carved ones' confidence left and the splatted ones' centres.
template <class DF>
HWY_NOINLINE void PlanVector(DF df, const SplatFrame& f, const Surfel* surfels, std::size_t j0, std::size_t count,
                           SplatPlan& plan) {
  const hn::RebindToSigned<DF> di;
  const hn::RebindToUnsigned<DF> du;
  hn::Vec<DF> x, y, z;
  hn::Vec<decltype(du)> normal_radius, colour, confidence_brick, first_seen;
  SurfelFields(df, surfels, j0, count, x, y, z, normal_radius, colour, confidence_brick, first_seen);
  const auto flags = hn::ShiftRight<24>(colour);
  const auto confidence = hn::And(confidence_brick, hn::Set(du, 0xffffu));
  const auto live = hn::Ne(hn::And(flags, hn::Set(du, kSurfelLive)), hn::Zero(du));
  const auto stable = hn::Ne(hn::And(flags, hn::Set(du, kSurfelStable)), hn::Zero(du));
  const auto old = hn::Gt(hn::Sub(hn::Set(du, f.frame), first_seen), hn::Set(du, f.unstable_max));
  const auto remove = hn::AndNot(stable, hn::And(live, old));
  const auto brick = hn::BitCast(di, hn::IfThenElseZero(live, hn::ShiftRight<16>(confidence_brick)));
  const auto visible = hn::Ne(hn::GatherIndex(du, f.brick_visible, brick), hn::Zero(du));
  // A vector of surfels none of which is removed or in a visible brick (a map
  // larger than the view: surfels of one frame share slots and bricks) is
  // skipped whole, as the lanes below would all decide.
  if (hn::AllFalse(du, hn::Or(remove, hn::And(live, visible)))) {
    hn::StoreU(hn::Set(du, SplatPlan::kSkip), du, plan.action + j0);
    return;
  }
  const auto b3 = hn::Mul(brick, hn::Set(di, 3));
  const auto px = hn::Add(hn::GatherIndex(df, f.brick_cam, b3), RotateRow(df, f.r, x, y, z));
  const auto py = hn::Add(hn::GatherIndex(df, f.brick_cam + 1, b3), RotateRow(df, f.r + 3, x, y, z));
  const auto pz = hn::Add(hn::GatherIndex(df, f.brick_cam + 2, b3), RotateRow(df, f.r + 6, x, y, z));
  const auto pu = hn::Add(hn::Div(hn::Mul(hn::Set(df, f.fx), px), pz), hn::Set(df, f.cx));
  const auto pv = hn::Add(hn::Div(hn::Mul(hn::Set(df, f.fy), py), pz), hn::Set(df, f.cy));
  const auto in_view = hn::And(hn::Ge(pz, hn::Set(df, f.min_z)),
                               hn::And(hn::And(hn::Gt(pu, hn::Set(df, f.u_lo)), hn::Lt(pu, hn::Set(df, f.u_hi))),
                                       hn::And(hn::Gt(pv, hn::Set(df, f.v_lo)), hn::Lt(pv, hn::Set(df, f.v_hi)))));
  const auto candidate = hn::AndNot(hn::RebindMask(df, remove), hn::And(hn::RebindMask(df, hn::And(live, visible)), in_view));
  const auto iu = RoundHalfAway(df, pu), iv = RoundHalfAway(df, pv);
  const auto minus_one = hn::Set(di, -1);  // Highway 1.0 has no integer Ge
  const auto in_image = hn::And(hn::And(hn::Gt(iu, minus_one), hn::Gt(iv, minus_one)),
                                hn::And(hn::Lt(iu, hn::Set(di, f.w)), hn::Lt(iv, hn::Set(di, f.h))));
  const auto centre = hn::IfThenElseZero(in_image, hn::Add(hn::Mul(iv, hn::Set(di, f.w)), iu));
  const auto measured = hn::GatherIndex(df, f.measured_z, centre);
  const auto behind = hn::Lt(pz, hn::Sub(measured, hn::Mul(hn::Set(df, f.sigmas), DepthSigma(df, measured))));
  const auto carve = hn::And(candidate, hn::And(hn::RebindMask(df, in_image), hn::And(hn::Gt(measured, hn::Zero(df)), behind)));
  const auto decoded = DecodeConfidence(df, confidence);
  const auto weight = hn::GatherIndex(df, f.weight, centre);
  hn::StoreU(hn::Sub(hn::Mul(hn::Set(df, 0.5f), decoded), hn::Mul(hn::Set(df, f.carve), weight)), df, plan.kept + j0);
  const auto splat = hn::AndNot(carve, candidate);
  auto action = hn::IfThenElseZero(hn::RebindMask(du, splat), hn::Set(du, SplatPlan::kSplat));
  action = hn::IfThenElse(hn::RebindMask(du, carve), hn::Set(du, SplatPlan::kCarve), action);
  action = hn::IfThenElse(remove, hn::Set(du, SplatPlan::kRemoveUnstable), action);
  hn::StoreU(action, du, plan.action + j0);
  hn::StoreU(iu, di, plan.centre_u + j0);
  hn::StoreU(iv, di, plan.centre_v + j0);
  PlanCentres(df, f, normal_radius, confidence, px, py, pz, iu, iv, j0, plan);
}

HWY_NOINLINE void PlanSplatsT(const SplatFrame& frame, const Surfel* surfels, std::size_t count, SplatPlan& plan) {
  const hn::ScalableTag<float> df;
  const std::size_t lanes = hn::Lanes(df);
  for (std::size_t j0 = 0; j0 < count; j0 += lanes) PlanVector(df, frame, surfels, j0, count, plan);
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::map
HWY_AFTER_NAMESPACE();

#endif  // include guard
