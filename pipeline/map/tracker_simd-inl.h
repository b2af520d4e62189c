// Per-target body of trackLevelSimd (tracker_kernels.h); compiled once per
// Highway target by tracker_simd.cpp (through hwy/foreach_target.h). Every
// function that calls a Highway op sits between HWY_BEFORE_NAMESPACE and
// HWY_AFTER_NAMESPACE (GCC 12 on aarch64 refuses to inline the ops otherwise).
//
// The reference's arithmetic per pixel (trackPixelRef, tracker_kernels.cpp), a vector
// of pixels at a time: the model is gathered at each lane's projection; lanes
// that do not associate are computed too and zeroed before they are summed.
// The products are summed per lane in float across a row (a lane sees width /
// lanes terms: 80 at 640 columns and 8 lanes), and each row's lanes are added
// to the totals in double; the reference sums every product in double, hence
// kTrackSimdTolerance rather than the same bits. A row's tail runs through the
// same vector code on a zero-padded copy (depth 0 never associates).

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_MAP_TRACKER_SIMD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_MAP_TRACKER_SIMD_INL_H_
#undef FOVEA_PIPELINE_MAP_TRACKER_SIMD_INL_H_
#else
#define FOVEA_PIPELINE_MAP_TRACKER_SIMD_INL_H_
#endif

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <limits>

#include "hwy/highway.h"
#include "core/depth_noise.h"
#include "pipeline/map/tracker_kernels.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::map {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

inline constexpr std::size_t kTrackMaxLanes = HWY_MAX_BYTES / sizeof(float);

// The 29 running sums of a row, a vector's lanes each, in memory (SVE's
// vectors are sizeless: no arrays or members of them): J^T J's upper triangle
// (0..20), J^T r (21..26), the squared ICP (27) and photometric (28) residuals.
inline constexpr int kTrackSums = 29;

template <class DF>
HWY_INLINE void Accumulate(DF df, float* acc, int k, hn::Vec<DF> term) {
  const std::size_t N = hn::Lanes(df);
  float* a = acc + static_cast<std::size_t>(k) * N;
  hn::Store(hn::Add(hn::Load(df, a), term), df, a);
}

// One term's w J^T J and w J^T r into the sums (J = j0..j5, sizeless vectors as
// arguments; w the robust weight, w J rounded to float first as the reference does).
template <class DF, class V = hn::Vec<DF>>
HWY_INLINE void AddTerms(DF df, V j0, V j1, V j2, V j3, V j4, V j5, V r, V w, float* acc) {
  const V w0 = hn::Mul(w, j0), w1 = hn::Mul(w, j1), w2 = hn::Mul(w, j2);
  const V w3 = hn::Mul(w, j3), w4 = hn::Mul(w, j4), w5 = hn::Mul(w, j5);
  Accumulate(df, acc, 0, hn::Mul(w0, j0));
  Accumulate(df, acc, 1, hn::Mul(w0, j1));
  Accumulate(df, acc, 2, hn::Mul(w0, j2));
  Accumulate(df, acc, 3, hn::Mul(w0, j3));
  Accumulate(df, acc, 4, hn::Mul(w0, j4));
  Accumulate(df, acc, 5, hn::Mul(w0, j5));
  Accumulate(df, acc, 6, hn::Mul(w1, j1));
  Accumulate(df, acc, 7, hn::Mul(w1, j2));
  Accumulate(df, acc, 8, hn::Mul(w1, j3));
  Accumulate(df, acc, 9, hn::Mul(w1, j4));
  Accumulate(df, acc, 10, hn::Mul(w1, j5));
  Accumulate(df, acc, 11, hn::Mul(w2, j2));
  Accumulate(df, acc, 12, hn::Mul(w2, j3));
  Accumulate(df, acc, 13, hn::Mul(w2, j4));
  Accumulate(df, acc, 14, hn::Mul(w2, j5));
  Accumulate(df, acc, 15, hn::Mul(w3, j3));
  Accumulate(df, acc, 16, hn::Mul(w3, j4));
  Accumulate(df, acc, 17, hn::Mul(w3, j5));
  Accumulate(df, acc, 18, hn::Mul(w4, j4));
  Accumulate(df, acc, 19, hn::Mul(w4, j5));
  Accumulate(df, acc, 20, hn::Mul(w5, j5));
  Accumulate(df, acc, 21, hn::Mul(w0, r));
  Accumulate(df, acc, 22, hn::Mul(w1, r));
  Accumulate(df, acc, 23, hn::Mul(w2, r));
  Accumulate(df, acc, 24, hn::Mul(w3, r));
  Accumulate(df, acc, 25, hn::Mul(w4, r));
  Accumulate(df, acc, 26, hn::Mul(w5, r));
}

// cauchyWeight() (tracker_kernels.h) of the lanes in `mask`, its operations in
// its order; 1 elsewhere (a lane outside may hold a NaN) and where c is 0.
template <class DF, class M, class V = hn::Vec<DF>>
HWY_INLINE V CauchyWeight(DF df, V r, float c, M mask) {
  const V one = hn::Set(df, 1.0f);
  if (c == 0.0f) return one;
  const V q = hn::Div(r, hn::Set(df, c));
  return hn::IfThenElse(mask, hn::Div(one, hn::Add(one, hn::Mul(q, q))), one);
}

// TrackVector()'s photometric term for the lanes that associate (icp): the
// model's intensity, bilinear at the projection (fu, fv), against the frame's
// (fi_), with its gradient's Jacobian.
template <class DF, class VI, class M>
HWY_INLINE void PhotometricTerms(DF df, const TrackModelLevel& m, const TrackParams& p, hn::Vec<DF> fu, hn::Vec<DF> fv,
                                 hn::Vec<DF> qx, hn::Vec<DF> qy, hn::Vec<DF> qz, hn::Vec<DF> safe_qz, VI j, M icp,
                                 const float* fi_, float* acc, uint32_t& photo_inliers) {
  using V = hn::Vec<DF>;
  const hn::RebindToSigned<DF> di;
  const V zero = hn::Zero(df);
  const V fu0 = hn::Min(hn::Max(hn::Floor(fu), zero), hn::Set(df, static_cast<float>(m.width - 2)));
  const V fv0 = hn::Min(hn::Max(hn::Floor(fv), zero), hn::Set(df, static_cast<float>(m.height - 2)));
  const V one = hn::Set(df, 1.0f);
  const V au = hn::Min(hn::Max(hn::Sub(fu, fu0), zero), one);
  const V av = hn::Min(hn::Max(hn::Sub(fv, fv0), zero), one);
  const auto i00 = hn::Add(hn::Mul(hn::ConvertTo(di, fv0), hn::Set(di, m.width)), hn::ConvertTo(di, fu0));
  const auto i01 = hn::Add(i00, hn::Set(di, 1));
  const auto i10 = hn::Add(i00, hn::Set(di, m.width));
  const auto i11 = hn::Add(i10, hn::Set(di, 1));
  const V I00 = hn::GatherIndex(df, m.intensity, i00), I01 = hn::GatherIndex(df, m.intensity, i01);
  const V I10 = hn::GatherIndex(df, m.intensity, i10), I11 = hn::GatherIndex(df, m.intensity, i11);
  const V top = hn::Add(I00, hn::Mul(au, hn::Sub(I01, I00)));
  const V bottom = hn::Add(I10, hn::Mul(au, hn::Sub(I11, I10)));
  const V r = hn::Sub(hn::Add(top, hn::Mul(av, hn::Sub(bottom, top))), hn::LoadU(df, fi_));
  const auto photo = hn::And(icp, hn::Le(hn::Abs(r), hn::Set(df, p.max_photometric_residual)));
  if (hn::AllFalse(df, photo)) return;
  photo_inliers += static_cast<uint32_t>(hn::CountTrue(df, photo));
  const V inv_z = hn::Div(one, safe_qz);
  const V a = hn::Mul(hn::Mul(hn::GatherIndex(df, m.gx, j), hn::Set(df, m.fx)), inv_z);
  const V b = hn::Mul(hn::Mul(hn::GatherIndex(df, m.gy, j), hn::Set(df, m.fy)), inv_z);
  const V gz = hn::Mul(hn::Neg(hn::Add(hn::Mul(a, qx), hn::Mul(b, qy))), inv_z);
  const V sw = hn::Set(df, p.photometric_sqrt_weight);
  const V gx = hn::Mul(sw, a), gy = hn::Mul(sw, b), gzw = hn::Mul(sw, gz);
  const V r_photo = hn::IfThenElseZero(photo, hn::Mul(sw, r));
  AddTerms(df, hn::IfThenElseZero(photo, gx), hn::IfThenElseZero(photo, gy), hn::IfThenElseZero(photo, gzw),
           hn::IfThenElseZero(photo, hn::Sub(hn::Mul(qy, gzw), hn::Mul(qz, gy))),
           hn::IfThenElseZero(photo, hn::Sub(hn::Mul(qz, gx), hn::Mul(qx, gzw))),
           hn::IfThenElseZero(photo, hn::Sub(hn::Mul(qx, gy), hn::Mul(qy, gx))), r_photo,
           CauchyWeight(df, r, p.photometric_robust_scale, photo), acc);
  Accumulate(df, acc, 28, hn::Mul(r_photo, r_photo));
}

// One vector of pixels (their frame values in fx..fi) against the model.
template <class DF>
HWY_INLINE void TrackVector(DF df, const TrackModelLevel& m, const TrackParams& p, const float* fx_, const float* fy_,
                            const float* fz_, const float* fnx_, const float* fny_, const float* fnz_,
                            const float* fi_, float* acc, uint32_t& inliers, uint32_t& photo_inliers) {
  using V = hn::Vec<DF>;
  const hn::RebindToSigned<DF> di;
  const V zero = hn::Zero(df);
  const V px = hn::LoadU(df, fx_), py = hn::LoadU(df, fy_), pz = hn::LoadU(df, fz_);
  const V nfx = hn::LoadU(df, fnx_), nfy = hn::LoadU(df, fny_), nfz = hn::LoadU(df, fnz_);
  auto valid = hn::And(hn::Gt(pz, zero),
                       hn::Not(hn::And(hn::Eq(nfx, zero), hn::And(hn::Eq(nfy, zero), hn::Eq(nfz, zero)))));
  const auto& R = p.R;
  const V qx = hn::Add(hn::Add(hn::Add(hn::Mul(hn::Set(df, R[0]), px), hn::Mul(hn::Set(df, R[1]), py)),
                               hn::Mul(hn::Set(df, R[2]), pz)), hn::Set(df, p.t[0]));
  const V qy = hn::Add(hn::Add(hn::Add(hn::Mul(hn::Set(df, R[3]), px), hn::Mul(hn::Set(df, R[4]), py)),
                               hn::Mul(hn::Set(df, R[5]), pz)), hn::Set(df, p.t[1]));
  const V qz = hn::Add(hn::Add(hn::Add(hn::Mul(hn::Set(df, R[6]), px), hn::Mul(hn::Set(df, R[7]), py)),
                               hn::Mul(hn::Set(df, R[8]), pz)), hn::Set(df, p.t[2]));
  valid = hn::And(valid, hn::Gt(qz, zero));
  // Lanes behind the camera divide by a safe 1 (they are masked out anyway).
  const V safe_qz = hn::IfThenElse(valid, qz, hn::Set(df, 1.0f));
  V fu = hn::Add(hn::Div(hn::Mul(hn::Set(df, m.fx), qx), safe_qz), hn::Set(df, m.cx));
  V fv = hn::Add(hn::Div(hn::Mul(hn::Set(df, m.fy), qy), safe_qz), hn::Set(df, m.cy));
  const V half = hn::Set(df, 0.5f);
  valid = hn::And(valid, hn::And(hn::Ge(fu, hn::Neg(half)),
                                 hn::Lt(fu, hn::Set(df, static_cast<float>(m.width) - 0.5f))));
  valid = hn::And(valid, hn::And(hn::Ge(fv, hn::Neg(half)),
                                 hn::Lt(fv, hn::Set(df, static_cast<float>(m.height) - 0.5f))));
  if (hn::AllFalse(df, valid)) return;
  fu = hn::IfThenElse(valid, fu, zero);  // gathers stay inside the model
  fv = hn::IfThenElse(valid, fv, zero);
  const auto ui = hn::ConvertTo(di, hn::Add(fu, half)), vi = hn::ConvertTo(di, hn::Add(fv, half));
  const auto j = hn::Add(hn::Mul(vi, hn::Set(di, m.width)), ui);
  const V mx = hn::GatherIndex(df, m.x, j), my = hn::GatherIndex(df, m.y, j), mz = hn::GatherIndex(df, m.z, j);
  const V nx = hn::GatherIndex(df, m.nx, j), ny = hn::GatherIndex(df, m.ny, j), nz = hn::GatherIndex(df, m.nz, j);
  valid = hn::And(valid, hn::And(hn::Gt(mz, zero),
                                 hn::Not(hn::And(hn::Eq(nx, zero), hn::And(hn::Eq(ny, zero), hn::Eq(nz, zero))))));
  const V dx = hn::Sub(qx, mx), dy = hn::Sub(qy, my), dz = hn::Sub(qz, mz);
  const V dist2 = hn::Add(hn::Add(hn::Mul(dx, dx), hn::Mul(dy, dy)), hn::Mul(dz, dz));
  valid = hn::And(valid, hn::Le(dist2, hn::Set(df, p.max_distance * p.max_distance)));
  const V rnx = hn::Add(hn::Add(hn::Mul(hn::Set(df, R[0]), nfx), hn::Mul(hn::Set(df, R[1]), nfy)),
                        hn::Mul(hn::Set(df, R[2]), nfz));
  const V rny = hn::Add(hn::Add(hn::Mul(hn::Set(df, R[3]), nfx), hn::Mul(hn::Set(df, R[4]), nfy)),
                        hn::Mul(hn::Set(df, R[5]), nfz));
  const V rnz = hn::Add(hn::Add(hn::Mul(hn::Set(df, R[6]), nfx), hn::Mul(hn::Set(df, R[7]), nfy)),
                        hn::Mul(hn::Set(df, R[8]), nfz));
  const V cosine = hn::Add(hn::Add(hn::Mul(rnx, nx), hn::Mul(rny, ny)), hn::Mul(rnz, nz));
  const auto icp = hn::And(valid, hn::Ge(cosine, hn::Set(df, p.min_normal_cos)));
  if (hn::AllFalse(df, icp)) return;
  inliers += static_cast<uint32_t>(hn::CountTrue(df, icp));
  V weight = hn::Set(df, 1.0f);
  if (p.noise_weighting) {
    // depthSigma(qz) (core/depth_noise.h), in its order of operations.
    const V wz = hn::Sub(qz, hn::Set(df, kDepthNoiseOffsetF));
    weight = hn::Div(hn::Set(df, kTrackSigmaAt1m),
                     hn::Add(hn::Set(df, kDepthNoiseBaseF), hn::Mul(hn::Set(df, kDepthNoiseQuadraticF), hn::Mul(wz, wz))));
  }
  const V wnx = hn::Mul(weight, nx), wny = hn::Mul(weight, ny), wnz = hn::Mul(weight, nz);
  // Every term of a lane that does not associate: zero (selected, not multiplied
  // by zero: such a lane may hold a NaN or an infinity).
  const V r_icp = hn::IfThenElseZero(icp, hn::Add(hn::Add(hn::Mul(wnx, dx), hn::Mul(wny, dy)), hn::Mul(wnz, dz)));
  AddTerms(df, hn::IfThenElseZero(icp, wnx), hn::IfThenElseZero(icp, wny), hn::IfThenElseZero(icp, wnz),
           hn::IfThenElseZero(icp, hn::Sub(hn::Mul(qy, wnz), hn::Mul(qz, wny))),
           hn::IfThenElseZero(icp, hn::Sub(hn::Mul(qz, wnx), hn::Mul(qx, wnz))),
           hn::IfThenElseZero(icp, hn::Sub(hn::Mul(qx, wny), hn::Mul(qy, wnx))), r_icp,
           CauchyWeight(df, r_icp, p.icp_robust_scale, icp), acc);
  Accumulate(df, acc, 27, hn::Mul(r_icp, r_icp));
  if (!p.use_photometric) return;
  PhotometricTerms(df, m, p, fu, fv, qx, qy, qz, safe_qz, j, icp, fi_, acc, photo_inliers);
}

// computeNormalsRef's arithmetic (tracker_kernels.cpp) on a vector of interior pixels
// starting at i: the same operations in the same order, selects for its
// branches, so the same bits.
template <class DF>
HWY_INLINE void NormalsVector(DF df, const NormalMapIn& in, std::size_t i, float step, float* nx, float* ny,
                              float* nz) {
  using V = hn::Vec<DF>;
  const V zero = hn::Zero(df);
  const std::size_t rs = static_cast<std::size_t>(in.reach), rw = rs * static_cast<std::size_t>(in.width);
  const V zi = hn::LoadU(df, in.z + i);
  const V limit = hn::Mul(hn::Set(df, step), zi);
  auto ok = hn::Gt(zi, zero);
  const V zl = hn::LoadU(df, in.z + i - rs), zr = hn::LoadU(df, in.z + i + rs);
  const V zu = hn::LoadU(df, in.z + i - rw), zd = hn::LoadU(df, in.z + i + rw);
  // Each neighbour (a loop over the four would put SVE's sizeless vectors in an array).
  ok = hn::And(ok, hn::And(hn::Gt(zl, zero), hn::Le(hn::Abs(hn::Sub(zl, zi)), limit)));
  ok = hn::And(ok, hn::And(hn::Gt(zr, zero), hn::Le(hn::Abs(hn::Sub(zr, zi)), limit)));
  ok = hn::And(ok, hn::And(hn::Gt(zu, zero), hn::Le(hn::Abs(hn::Sub(zu, zi)), limit)));
  ok = hn::And(ok, hn::And(hn::Gt(zd, zero), hn::Le(hn::Abs(hn::Sub(zd, zi)), limit)));
  const V ax = hn::Sub(hn::LoadU(df, in.x + i + rs), hn::LoadU(df, in.x + i - rs));
  const V ay = hn::Sub(hn::LoadU(df, in.y + i + rs), hn::LoadU(df, in.y + i - rs));
  const V az = hn::Sub(zr, zl);
  const V bx = hn::Sub(hn::LoadU(df, in.x + i + rw), hn::LoadU(df, in.x + i - rw));
  const V by = hn::Sub(hn::LoadU(df, in.y + i + rw), hn::LoadU(df, in.y + i - rw));
  const V bz = hn::Sub(zd, zu);
  const V cx = hn::Sub(hn::Mul(ay, bz), hn::Mul(az, by));
  const V cy = hn::Sub(hn::Mul(az, bx), hn::Mul(ax, bz));
  const V cz = hn::Sub(hn::Mul(ax, by), hn::Mul(ay, bx));
  const V n = hn::Sqrt(hn::Add(hn::Add(hn::Mul(cx, cx), hn::Mul(cy, cy)), hn::Mul(cz, cz)));
  ok = hn::And(ok, hn::And(hn::Gt(n, zero), hn::Lt(n, hn::Set(df, std::numeric_limits<float>::infinity()))));
  const V safe_n = hn::IfThenElse(ok, n, hn::Set(df, 1.0f));
  V ux = hn::Div(cx, safe_n), uy = hn::Div(cy, safe_n), uz = hn::Div(cz, safe_n);
  const V facing = hn::Add(hn::Add(hn::Mul(ux, hn::LoadU(df, in.x + i)), hn::Mul(uy, hn::LoadU(df, in.y + i))),
                           hn::Mul(uz, zi));
  const auto flip = hn::Gt(facing, zero);
  ux = hn::IfThenElse(flip, hn::Neg(ux), ux);
  uy = hn::IfThenElse(flip, hn::Neg(uy), uy);
  uz = hn::IfThenElse(flip, hn::Neg(uz), uz);
  V out_x = hn::IfThenElseZero(ok, ux), out_y = hn::IfThenElseZero(ok, uy), out_z = hn::IfThenElseZero(ok, uz);
  if (in.skip != nullptr) {
    // Kept pixels: their normal as it is (a byte each, widened to a lane mask).
    const hn::Rebind<uint8_t, DF> d8;
    const hn::RebindToUnsigned<DF> du;
    const auto keep = hn::RebindMask(df, hn::Ne(hn::PromoteTo(du, hn::LoadU(d8, in.skip + i)), hn::Zero(du)));
    out_x = hn::IfThenElse(keep, hn::LoadU(df, nx + i), out_x);
    out_y = hn::IfThenElse(keep, hn::LoadU(df, ny + i), out_y);
    out_z = hn::IfThenElse(keep, hn::LoadU(df, nz + i), out_z);
  }
  hn::StoreU(out_x, df, nx + i);
  hn::StoreU(out_y, df, ny + i);
  hn::StoreU(out_z, df, nz + i);
}

HWY_NOINLINE void ComputeNormalsT(const NormalMapIn& in, float* nx, float* ny, float* nz) {
  using DF = hn::ScalableTag<float>;
  const DF df;
  const std::size_t N = hn::Lanes(df);
  const int w = in.width, h = in.height, reach = in.reach;
  const float step = static_cast<float>(reach) * 2.0f * in.step_share;
  // Border rows and columns, and the row tails a vector does not fill: the reference.
  auto scalar = [&](int v, int u0, int u1) {
    for (int u = u0; u < u1; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      const bool border = u < reach || v < reach || u >= w - reach || v >= h - reach;
      if (in.skip != nullptr && in.skip[i]) continue;
      if (border) {
        nx[i] = ny[i] = nz[i] = 0.0f;
        continue;
      }
      normalAtRef(in, i, step, nx, ny, nz);
    }
  };
  for (int v = 0; v < h; ++v) {
    if (v < reach || v >= h - reach || w <= 2 * reach) {
      scalar(v, 0, w);
      continue;
    }
    scalar(v, 0, reach);
    int u = reach;
    for (; u + static_cast<int>(N) <= w - reach; u += static_cast<int>(N)) {
      NormalsVector(df, in, static_cast<std::size_t>(v) * w + u, step, nx, ny, nz);
    }
    scalar(v, u, w);
  }
}

// downsampleBlockRef's arithmetic (tracker_kernels.h) on a vector of blocks of
// row v starting at block u: the four pixels of each block deinterleaved from
// the two rows, the same operations in the same order, selects for its
// branches (an excluded pixel adds +0, which leaves a sum that started at +0
// as it is), so the same bits.
template <class DF>
HWY_INLINE void DownsampleVector(DF df, const PyramidLevelIn& from, const PyramidLevelOut& to, std::size_t top,
                                 std::size_t o, float step_share, bool normals) {
  using V = hn::Vec<DF>;
  const V zero = hn::Zero(df);
  const std::size_t fw = static_cast<std::size_t>(from.width);
  V z0, z1, z2, z3;
  hn::LoadInterleaved2(df, from.z + top, z0, z1);
  hn::LoadInterleaved2(df, from.z + top + fw, z2, z3);
  V zref = hn::IfThenElseZero(hn::Gt(z3, zero), z3);
  zref = hn::IfThenElse(hn::Gt(z2, zero), z2, zref);
  zref = hn::IfThenElse(hn::Gt(z1, zero), z1, zref);
  zref = hn::IfThenElse(hn::Gt(z0, zero), z0, zref);
  const V limit = hn::Mul(hn::Set(df, step_share), zref);
  const auto has_ref = hn::Gt(zref, zero);
  const auto in0 = hn::And(has_ref, hn::And(hn::Gt(z0, zero), hn::Le(hn::Abs(hn::Sub(z0, zref)), limit)));
  const auto in1 = hn::And(has_ref, hn::And(hn::Gt(z1, zero), hn::Le(hn::Abs(hn::Sub(z1, zref)), limit)));
  const auto in2 = hn::And(has_ref, hn::And(hn::Gt(z2, zero), hn::Le(hn::Abs(hn::Sub(z2, zref)), limit)));
  const auto in3 = hn::And(has_ref, hn::And(hn::Gt(z3, zero), hn::Le(hn::Abs(hn::Sub(z3, zref)), limit)));
  // One channel's block sum over the pixels in the average, in row order.
  const auto blockSum = [&](const float* channel) {
    V a0, a1, a2, a3;
    hn::LoadInterleaved2(df, channel + top, a0, a1);
    hn::LoadInterleaved2(df, channel + top + fw, a2, a3);
    V sum = hn::Add(zero, hn::IfThenElseZero(in0, a0));
    sum = hn::Add(sum, hn::IfThenElseZero(in1, a1));
    sum = hn::Add(sum, hn::IfThenElseZero(in2, a2));
    return hn::Add(sum, hn::IfThenElseZero(in3, a3));
  };
  V i0, i1, i2, i3;
  hn::LoadInterleaved2(df, from.intensity + top, i0, i1);
  hn::LoadInterleaved2(df, from.intensity + top + fw, i2, i3);
  const V si = hn::Add(hn::Add(hn::Add(hn::Add(zero, i0), i1), i2), i3);
  hn::StoreU(hn::Mul(hn::Set(df, 0.25f), si), df, to.intensity + o);
  const V one = hn::Set(df, 1.0f);
  const V n = hn::Add(hn::Add(hn::Add(hn::Add(zero, hn::IfThenElseZero(in0, one)), hn::IfThenElseZero(in1, one)),
                              hn::IfThenElseZero(in2, one)),
                      hn::IfThenElseZero(in3, one));
  const auto some = hn::Gt(n, zero);
  const V inv = hn::Div(one, hn::IfThenElse(some, n, one));
  hn::StoreU(hn::IfThenElseZero(some, hn::Mul(blockSum(from.x), inv)), df, to.x + o);
  hn::StoreU(hn::IfThenElseZero(some, hn::Mul(blockSum(from.y), inv)), df, to.y + o);
  hn::StoreU(hn::IfThenElseZero(some, hn::Mul(blockSum(from.z), inv)), df, to.z + o);
  if (!normals) {  // kept where the block has a vertex, zero where not
    hn::StoreU(hn::IfThenElseZero(some, hn::LoadU(df, to.nx + o)), df, to.nx + o);
    hn::StoreU(hn::IfThenElseZero(some, hn::LoadU(df, to.ny + o)), df, to.ny + o);
    hn::StoreU(hn::IfThenElseZero(some, hn::LoadU(df, to.nz + o)), df, to.nz + o);
    return;
  }
  const V snx = blockSum(from.nx), sny = blockSum(from.ny), snz = blockSum(from.nz);
  const V len = hn::Sqrt(hn::Add(hn::Add(hn::Mul(snx, snx), hn::Mul(sny, sny)), hn::Mul(snz, snz)));
  const auto agree = hn::And(some, hn::Gt(len, hn::Mul(hn::Set(df, 0.5f), n)));
  const V safe_len = hn::IfThenElse(agree, len, one);
  hn::StoreU(hn::IfThenElseZero(agree, hn::Div(snx, safe_len)), df, to.nx + o);
  hn::StoreU(hn::IfThenElseZero(agree, hn::Div(sny, safe_len)), df, to.ny + o);
  hn::StoreU(hn::IfThenElseZero(agree, hn::Div(snz, safe_len)), df, to.nz + o);
}

HWY_NOINLINE void DownsampleT(const PyramidLevelIn& from, const PyramidLevelOut& to, float step_share, bool normals) {
  using DF = hn::ScalableTag<float>;
  const DF df;
  const std::size_t N = hn::Lanes(df);
  const int tw = from.width / 2, th = from.height / 2;
  const std::size_t fw = static_cast<std::size_t>(from.width);
  for (int v = 0; v < th; ++v) {
    int u = 0;
    for (; u + static_cast<int>(N) <= tw; u += static_cast<int>(N)) {
      const std::size_t top = 2 * static_cast<std::size_t>(v) * fw + 2 * static_cast<std::size_t>(u);
      DownsampleVector(df, from, to, top, static_cast<std::size_t>(v) * tw + u, step_share, normals);
    }
    for (; u < tw; ++u) downsampleBlockRef(from, to, u, v, step_share, normals);  // the row's tail
  }
}

// A row's lanes of one sum, added in double.
inline double LaneSum(const float* lanes, std::size_t n) {
  double sum = 0.0;
  for (std::size_t k = 0; k < n; ++k) sum += lanes[k];
  return sum;
}

HWY_NOINLINE void TrackLevelT(const TrackFrameLevel& f, const TrackModelLevel& m, const TrackParams& params,
                              TrackSums& sums) {
  using DF = hn::ScalableTag<float>;
  const DF df;
  const std::size_t N = hn::Lanes(df);
  sums.clear();
  TrackParams p = params;
  if (m.width < 2 || m.height < 2) p.use_photometric = false;  // no bilinear neighbourhood (tracker.cpp never asks)
  HWY_ALIGN float pad[7][kTrackMaxLanes];
  HWY_ALIGN float acc[kTrackSums * kTrackMaxLanes];
  for (int v = 0; v < f.height; ++v) {
    std::fill(acc, acc + kTrackSums * N, 0.0f);
    uint32_t inliers = 0, photo_inliers = 0;
    const std::size_t row = static_cast<std::size_t>(v) * f.width;
    const std::size_t width = static_cast<std::size_t>(f.width);
    std::size_t u = 0;
    for (; u + N <= width; u += N) {
      const std::size_t i = row + u;
      TrackVector(df, m, p, f.x + i, f.y + i, f.z + i, f.nx + i, f.ny + i, f.nz + i, f.intensity + i, acc, inliers,
                  photo_inliers);
    }
    if (u < width) {
      const std::size_t n = width - u, i = row + u;
      const float* src[7] = {f.x + i, f.y + i, f.z + i, f.nx + i, f.ny + i, f.nz + i, f.intensity + i};
      for (int k = 0; k < 7; ++k) {
        std::fill(pad[k], pad[k] + N, 0.0f);
        std::memcpy(pad[k], src[k], n * sizeof(float));
      }
      TrackVector(df, m, p, pad[0], pad[1], pad[2], pad[3], pad[4], pad[5], pad[6], acc, inliers, photo_inliers);
    }
    for (std::size_t k = 0; k < 21; ++k) sums.h[k] += LaneSum(acc + k * N, N);
    for (std::size_t k = 0; k < 6; ++k) sums.b[k] += LaneSum(acc + (21 + k) * N, N);
    sums.icp_sq += LaneSum(acc + 27 * N, N);
    sums.photometric_sq += LaneSum(acc + 28 * N, N);
    sums.inliers += inliers;
    sums.photometric_inliers += photo_inliers;
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::map
HWY_AFTER_NAMESPACE();

#endif  // include guard
