// The SIMD voxel kernels of the samplers, in double: the voxel indices of one axis
// (the voxel sampler), and the packed voxel keys with their index ranges (the hash
// sampler).
// Per-target bodies, compiled once per Highway target by foveation_simd.cpp, which
// gives the rules every -inl header of these kernels follows (the namespace
// brackets, bit-exactness).

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_VOXEL_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_VOXEL_INL_H_
#undef FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_VOXEL_INL_H_
#else
#define FOVEA_PIPELINE_KERNELS_FOVEATION_SIMD_VOXEL_INL_H_
#endif

#include <algorithm>
#include <cstring>

#include "hwy/highway.h"
#include "pipeline/kernels/foveation_simd.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

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
