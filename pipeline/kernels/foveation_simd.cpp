// Dynamic dispatch of the SIMD kernels: foreach_target.h re-includes this file
// once per Highway target, compiling the kernels' -inl headers for each; HWY_EXPORT
// builds the tables and HWY_DYNAMIC_DISPATCH calls the best supported target.
//
// The -inl headers hold the per-target bodies, one header a concern:
// back-projection, the gaze's cones (partition, hit cone), ACUITY's model (levels,
// pyramid merge, refinement) and the samplers' voxel indices and keys. In all of
// them, every function that calls a Highway op sits between HWY_BEFORE_NAMESPACE
// and HWY_AFTER_NAMESPACE (GCC 12 on aarch64 refuses to inline the ops otherwise).
//
// Bit-exactness rules followed there: only correctly rounded IEEE operations
// (Mul, Add, Sub, Neg, Div, Sqrt, Floor) and conversions, in the reference's
// order; never MulAdd (an FMA on AVX2/NEON) nor an approximate reciprocal.
// Tails shorter than a vector run through the same vector code on a padded copy.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/kernels/foveation_simd.cpp"
#include "hwy/foreach_target.h"  // IWYU pragma: keep

#include "hwy/highway.h"
#include "pipeline/kernels/foveation_simd_backproject-inl.h"
#include "pipeline/kernels/foveation_simd_gaze-inl.h"
#include "pipeline/kernels/foveation_simd_acuity-inl.h"
#include "pipeline/kernels/foveation_simd_voxel-inl.h"

#if HWY_ONCE

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <type_traits>

#include "hwy/targets.h"

namespace fovea::pipeline {
namespace kernels {

HWY_EXPORT(BackprojectCountRowsT);
HWY_EXPORT(BackprojectRowsT);
HWY_EXPORT(PartitionRangeT);
HWY_EXPORT(LevelRangeT);
HWY_EXPORT(RefineTestRangeT);
HWY_EXPORT(VoxelIndexRangeT);
HWY_EXPORT(VoxelKeyRangeT);
HWY_EXPORT(HitConeRangeT);
HWY_EXPORT(PyramidMergeRangeT);

namespace {
void voxelIndexDispatch(const float* coord, const uint8_t* region, std::size_t n, double origin_m,
                        const double* inv_voxel_by_region, double* index_out) {
  HWY_DYNAMIC_DISPATCH(VoxelIndexRangeT)(coord, region, n, origin_m, inv_voxel_by_region, index_out);
}
}  // namespace

Status prepareBackprojection(const hal::RgbdFrame& frame, const DepthRange& range, BackprojectParams& p) {
  if (Status s = validateFrame(frame); !s) return s;
  if (Status s = range.validate(); !s) return s;
  // The raw-unit range test of backprojectRef.
  const double scale = frame.depth_scale_m;
  const RawDepthRange raw = rawDepthRange(range, scale);
  const int64_t raw_min = raw.min;
  const int64_t raw_max = raw.max;

  const hal::CameraIntrinsics& k = frame.intrinsics;
  p.depth = frame.depth();
  p.rgb = frame.rgb();
  p.has_rgb = frame.has_rgb;
  p.width = frame.width();
  p.height = frame.height();
  p.raw_min = static_cast<int32_t>(raw_min);
  p.raw_max = static_cast<int32_t>(raw_max);
  p.scale = static_cast<float>(scale);
  p.cx = static_cast<float>(k.cx);
  p.cy = static_cast<float>(k.cy);
  p.inv_fx = static_cast<float>(1.0 / k.fx);
  p.inv_fy = static_cast<float>(1.0 / k.fy);
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col) p.r[3 * row + col] = static_cast<float>(frame.T_world_cam.R_world_cam(row, col));
  }
  return Status::ok();
}

std::size_t backprojectCountRows(const BackprojectParams& params, int row0, int row1, std::size_t* no_depth,
                                 std::size_t* out_of_range) {
  return HWY_DYNAMIC_DISPATCH(BackprojectCountRowsT)(params, row0, row1, no_depth, out_of_range);
}

void pyramidMergeSimd(const PyramidMergeParams& params, const PyramidCellSums& cells, std::size_t count,
                      float* merge) {
  HWY_DYNAMIC_DISPATCH(PyramidMergeRangeT)(params, cells, count, merge);
}

void backprojectRows(const BackprojectParams& params, int row0, int row1, std::size_t out_offset,
                     std::size_t out_limit) {
  HWY_DYNAMIC_DISPATCH(BackprojectRowsT)(params, row0, row1, out_offset, out_limit);
}

namespace {
// origin - H (the large parts cancelled in double, as the references do) and L, in
// the params' own precision (double for the partition, float for the levels).
template <class Params>
void fillEye(const PointCloud& cloud, const Gaze& gaze, Params& p) {
  using T = std::remove_reference_t<decltype(p.l[0])>;
  const Eigen::Vector3d origin_minus_eye = cloud.origin_m - gaze.origin_m;
  for (int a = 0; a < 3; ++a) {
    p.origin_minus_eye[a] = static_cast<T>(origin_minus_eye[a]);
    p.l[a] = static_cast<T>(gaze.direction[a]);
  }
}
}  // namespace

PartitionParams preparePartition(const PointCloud& cloud, const Gaze& gaze, const ConeBounds& bounds) {
  PartitionParams p;
  fillEye(cloud, gaze, p);
  p.bounds = bounds;
  return p;
}

void partitionRange(const PointCloud& cloud, const PartitionParams& params, std::size_t begin, std::size_t end,
                    uint8_t* region_out, uint32_t* histogram256) {
  HWY_DYNAMIC_DISPATCH(PartitionRangeT)(cloud.x(), cloud.y(), cloud.z(), params, begin, end, region_out, histogram256);
}

LevelParams prepareLevels(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds) {
  LevelParams p;
  fillEye(cloud, gaze, p);
  p.bounds = bounds;
  p.growth_deg = static_cast<float>(gaze.fovea_growth_deg);
  p.cull = bounds.cull_region != 0 && gaze.view_known;
  for (int a = 0; a < 3; ++a) p.f[a] = static_cast<float>(gaze.view_forward[a]);
  return p;
}

RefineInputs prepareRefine(const PointCloud& cloud, const PointCloud& out, const uint32_t* representative) {
  RefineInputs inputs;
  inputs.representative = representative;
  inputs.out_size = out.size();
  inputs.ox = out.x();
  inputs.oy = out.y();
  inputs.oz = out.z();
  const Eigen::Vector3f offset = (cloud.origin_m - out.origin_m).cast<float>();
  for (int a = 0; a < 3; ++a) inputs.out_offset[a] = offset[a];
  return inputs;
}

std::size_t refineTestRange(const PointCloud& cloud, const LevelParams& params, const RefineInputs& inputs,
                            const uint8_t* region, std::size_t begin, std::size_t end, uint8_t* state) {
  return HWY_DYNAMIC_DISPATCH(RefineTestRangeT)(cloud.x(), cloud.y(), cloud.z(), params, inputs, region, begin, end,
                                                state);
}

void levelRange(const PointCloud& cloud, const LevelParams& params, std::size_t begin, std::size_t end,
                uint8_t* region_out, uint32_t* histogram256) {
  HWY_DYNAMIC_DISPATCH(LevelRangeT)(cloud.x(), cloud.y(), cloud.z(), params, begin, end, region_out, histogram256);
}

void VoxelKeyState::reset() {
  for (auto& row : lo) std::fill(std::begin(row), std::end(row), HUGE_VAL);
  for (auto& row : hi) std::fill(std::begin(row), std::end(row), -HUGE_VAL);
  std::fill(std::begin(histogram), std::end(histogram), 0u);
}

std::size_t voxelKeyRange(const float* x, const float* y, const float* z, const uint8_t* region, std::size_t n,
                          VoxelKeyState& state, uint64_t* key_out) {
  return HWY_DYNAMIC_DISPATCH(VoxelKeyRangeT)(x, y, z, region, n, state, key_out);
}

std::size_t hitConeRange(const PointCloud& cloud, const uint8_t* region, const double* origin_minus_eye,
                         const double* l, double tan_cone, double* t_out) {
  return HWY_DYNAMIC_DISPATCH(HitConeRangeT)(cloud.x(), cloud.y(), cloud.z(), region, cloud.size(), origin_minus_eye,
                                             l, tan_cone, t_out);
}

}  // namespace kernels

Fixation computeFixationSimd(const PointCloud& cloud, const uint8_t* region, const Gaze& gaze,
                             const FixationConfig& config, double* t_scratch) {
  if (config.mode != FixationMode::kHit) return computeFixation(cloud, region, gaze, config, t_scratch);
  // As hitFixation(): the same tan, the same origin difference, the same t values.
  const double tan_cone = std::tan(config.hit_cone_deg * std::numbers::pi / 180.0);
  const Eigen::Vector3d origin_minus_eye = cloud.origin_m - gaze.origin_m;
  const double ome[3] = {origin_minus_eye.x(), origin_minus_eye.y(), origin_minus_eye.z()};
  const double l[3] = {gaze.direction.x(), gaze.direction.y(), gaze.direction.z()};
  const std::size_t n = kernels::hitConeRange(cloud, region, ome, l, tan_cone, t_scratch);
  // No point in the cone: the reference's own fallbacks (centroid, then fallback_m).
  if (n == 0) return computeFixation(cloud, region, gaze, config, t_scratch);
  Fixation f;
  const auto k = static_cast<std::size_t>(config.hit_percentile * static_cast<double>(n - 1));
  std::nth_element(t_scratch, t_scratch + k, t_scratch + n);
  f.d0_m = t_scratch[k];
  f.source = FixationSource::kHit;
  f.support = static_cast<uint32_t>(n);
  if (!(f.d0_m >= config.min_m)) {
    f.d0_m = config.min_m;
    f.clamped = true;
  }
  return f;
}

Status backprojectSimd(const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out,
                       BackprojectCounts& counts) {
  counts = {};
  out.clear();
  kernels::BackprojectParams p;
  if (Status s = kernels::prepareBackprojection(frame, range, p); !s) return s;
  out.origin_m = frame.T_world_cam.t_world_cam;
  out.has_color = frame.has_rgb;
  counts.pixels = static_cast<std::size_t>(p.width) * p.height;
  const std::size_t valid = kernels::backprojectCountRows(p, 0, p.height, &counts.no_depth, &counts.out_of_range);
  if (valid > out.capacity()) {
    // (counts are unspecified on this error: the reference stops at the first pixel too many)
    return {ErrorCode::kCapacityExceeded, "backproject: frame has more valid pixels than the cloud capacity " +
                                              std::to_string(out.capacity()) + ": raise pipeline.max_points"};
  }
  p.out_x = out.x();
  p.out_y = out.y();
  p.out_z = out.z();
  p.out_rgb = out.rgb();
  kernels::backprojectRows(p, 0, p.height, 0, out.capacity());
  counts.valid = valid;
  (void)out.resize(valid);
  return Status::ok();
}

Status backproject(const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out, BackprojectCounts& counts,
                   KernelSet kernels) {
  return kernels == KernelSet::kRef ? backprojectRef(frame, range, out, counts)
                                    : backprojectSimd(frame, range, out, counts);
}

void partitionSimd(const PointCloud& cloud, const Gaze& gaze, const ConeBounds& bounds, uint8_t* region_out,
                   PartitionCounts& counts) {
  counts = {};
  uint32_t histogram[256] = {};
  const kernels::PartitionParams p = kernels::preparePartition(cloud, gaze, bounds);
  kernels::partitionRange(cloud, p, 0, cloud.size(), region_out, histogram);
  for (int r = 0; r < kMaxRegions; ++r) counts.per_region[r] = histogram[r];
  counts.invalid = histogram[kRegionInvalid];
}

void assignLevelsSimd(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, uint8_t* region_out,
                      PartitionCounts& counts) {
  counts = {};
  uint32_t histogram[256] = {};
  kernels::levelRange(cloud, kernels::prepareLevels(cloud, gaze, bounds), 0, cloud.size(), region_out, histogram);
  for (int r = 0; r < kMaxRegions; ++r) counts.per_region[r] = histogram[r];
  counts.invalid = histogram[kRegionInvalid];
  counts.culled = histogram[kRegionCulled];
}

std::size_t refineTestSimd(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, const PointCloud& out,
                           const uint32_t* representative, const uint8_t* region, uint8_t* state) {
  return kernels::refineTestRange(cloud, kernels::prepareLevels(cloud, gaze, bounds),
                                  kernels::prepareRefine(cloud, out, representative), region, 0, cloud.size(), state);
}

void voxelIndexSimd(const float* coord, const uint8_t* region, std::size_t n, double origin_m,
                    const double* inv_voxel_by_region, double* index_out) {
  kernels::voxelIndexDispatch(coord, region, n, origin_m, inv_voxel_by_region, index_out);
}

std::vector<int64_t> simdTargets() { return hwy::SupportedAndGeneratedTargets(); }
const char* simdTargetName(int64_t target) { return hwy::TargetName(target); }
void forceSimdTarget(int64_t targets) { hwy::SetSupportedTargetsForTest(targets); }
int64_t activeSimdTarget() {
  const int64_t t = hwy::SupportedTargets() & HWY_TARGETS;
  return t & -t;  // lower bits are the better targets
}

}  // namespace fovea::pipeline

#endif  // HWY_ONCE
