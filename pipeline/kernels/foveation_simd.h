// SIMD kernels (Google Highway, dynamic dispatch) for the per-point stages.
//
// Each kernel reproduces its scalar reference BIT FOR BIT (docs/kernels.md):
//   backprojectSimd  == backprojectRef   (float; same operation order, Mul and Add, never MulAdd)
//   partitionSimd    == partitionRef     (double; t, rejection vector, sqrt, ConeBounds::inside)
//   assignLevelsSimd == assignLevelsRef  (double; ACUITY's levels, acuity_levels.h's polynomials)
//   voxelIndexSimd   == voxelIndex()     (double floor((origin + double(p)) * inv_voxel))
// The best target the CPU supports is picked at the first call (Highway's
// HWY_DYNAMIC_DISPATCH); forceSimdTarget() restricts it (tests, benchmarks).
//
// The *Range/*Rows functions are the building blocks the multi-threaded pipeline
// splits a frame into; they are public so that benchmarks can time one kernel.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/kernel_set.h"
#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/acuity_levels.h"
#include "pipeline/backproject.h"
#include "pipeline/fixation.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::pipeline {

// ---- Whole-cloud entry points ---------------------------------------------

// Same contract as backprojectRef (validation, errors, counts, output).
Status backprojectSimd(const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out,
                       BackprojectCounts& counts);
// backprojectRef or backprojectSimd as `kernels` says.
Status backproject(const hal::RgbdFrame& frame, const DepthRange& range, PointCloud& out, BackprojectCounts& counts,
                   KernelSet kernels = defaultKernelSet());

// Same contract as partitionRef.
void partitionSimd(const PointCloud& cloud, const Gaze& gaze, const ConeBounds& bounds, uint8_t* region_out,
                   PartitionCounts& counts);

// Same contract as assignLevelsRef.
void assignLevelsSimd(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, uint8_t* region_out,
                      PartitionCounts& counts);
// Same contract and states as refineTestRef.
std::size_t refineTestSimd(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds, const PointCloud& out,
                           const uint32_t* representative, const uint8_t* region, uint8_t* state);

// index_out[i] = voxelIndex(origin_m, coord[i], inv_voxel_by_region[region[i]]) for i in [0, n).
// inv_voxel_by_region has 256 entries (any region byte, kRegionInvalid included).
void voxelIndexSimd(const float* coord, const uint8_t* region, std::size_t n, double origin_m,
                    const double* inv_voxel_by_region, double* index_out);

// Same contract and result as computeFixation (bit for bit: the hit mode's t values are
// computed with axialRadial()'s expressions in SIMD and the same percentile is taken; the
// other modes and the fallbacks are computeFixation's own code).
Fixation computeFixationSimd(const PointCloud& cloud, const uint8_t* region, const Gaze& gaze,
                             const FixationConfig& config, double* t_scratch);

// ---- Highway targets ------------------------------------------------------

// Targets compiled into this binary and supported by this CPU (HWY_* bits), best first.
std::vector<int64_t> simdTargets();
const char* simdTargetName(int64_t target);
// Restricts dispatch to `targets` (a mask of HWY_* bits; 0 restores the CPU's own set).
// Not thread-safe with kernels running: call between frames (tests, benchmarks).
void forceSimdTarget(int64_t targets);
// The target the next SIMD call dispatches to.
int64_t activeSimdTarget();

// ---- Building blocks (ranges of rows or points) ---------------------------
namespace kernels {

// Everything back-projection needs per frame, derived once from the frame.
struct BackprojectParams {
  const uint16_t* depth = nullptr;
  const uint8_t* rgb = nullptr;
  bool has_rgb = false;
  int width = 0;
  int height = 0;
  int32_t raw_min = 1;  // valid raw depth: raw_min <= raw <= raw_max (raw_min >= 1)
  int32_t raw_max = 0;
  float scale = 0, cx = 0, cy = 0, inv_fx = 0, inv_fy = 0;
  float r[9] = {};  // row-major R_world_cam as float
  float* out_x = nullptr;
  float* out_y = nullptr;
  float* out_z = nullptr;
  uint32_t* out_rgb = nullptr;
};

// Validates the frame and range exactly like backprojectRef and fills params
// (without the output pointers).
Status prepareBackprojection(const hal::RgbdFrame& frame, const DepthRange& range, BackprojectParams& params);

// Valid pixels of rows [row0, row1); adds the rejected ones to *no_depth and *out_of_range.
std::size_t backprojectCountRows(const BackprojectParams& params, int row0, int row1, std::size_t* no_depth,
                                 std::size_t* out_of_range);
// Writes the valid pixels of rows [row0, row1) at out_* + out_offset on, in image
// order. out_limit: the end of what the call may write (its rows' last point + 1, or
// the cloud's capacity): below it, whole vectors are stored, lanes past the last point
// included, because a full store costs a fraction of a masked one (AVX2's
// vmaskmovps); nothing at or past out_limit is read or written, so threads may write
// neighbouring ranges of one cloud. The points are the same either way.
void backprojectRows(const BackprojectParams& params, int row0, int row1, std::size_t out_offset,
                     std::size_t out_limit);

struct PartitionParams {
  double origin_minus_eye[3] = {};
  double l[3] = {};
  ConeBounds bounds;
};
PartitionParams preparePartition(const PointCloud& cloud, const Gaze& gaze, const ConeBounds& bounds);
// Regions of points [begin, end); histogram[r] += points of region r (r = kRegionInvalid too).
void partitionRange(const PointCloud& cloud, const PartitionParams& params, std::size_t begin, std::size_t end,
                    uint8_t* region_out, uint32_t* histogram256);

// In float, as assignLevelsRef (origin - H is the double difference, rounded).
struct LevelParams {
  float origin_minus_eye[3] = {};
  float l[3] = {};
  LevelBounds bounds;
  float growth_deg = 0.0f;  // Gaze::fovea_growth_deg
  bool cull = false;        // bounds.cull_region != 0 and the gaze knows the view
  float f[3] = {};          // Gaze::view_forward
};
LevelParams prepareLevels(const PointCloud& cloud, const Gaze& gaze, const LevelBounds& bounds);
// What the refinement reads besides the points: each point's representative in the
// sampled cloud (its coordinates and size) and cloud.origin_m - out.origin_m as float.
struct RefineInputs {
  const uint32_t* representative = nullptr;
  std::size_t out_size = 0;
  const float* ox = nullptr;
  const float* oy = nullptr;
  const float* oz = nullptr;
  float out_offset[3] = {};
};
RefineInputs prepareRefine(const PointCloud& cloud, const PointCloud& out, const uint32_t* representative);
// refineTestRef's states of points [begin, end); returns the points beyond their MAR.
std::size_t refineTestRange(const PointCloud& cloud, const LevelParams& params, const RefineInputs& inputs,
                            const uint8_t* region, std::size_t begin, std::size_t end, uint8_t* state);
// The image pyramid's rule (pipeline/pyramid_sampler.h) for cells of one level: what
// it needs besides the cells' sums. eye.l, eye.origin_minus_eye (camera - eye) and
// eye.bounds.slope are used; eye.growth_deg is 0 (the growth is applied after the
// cell's spread, growth_deg below).
inline constexpr float kPyramidSqrt3 = 1.7320508f;  // a cube's diagonal per side
struct PyramidMergeParams {
  LevelParams eye;
  float r[9] = {};          // R_world_cam, row-major
  float growth_deg = 0.0f;  // Gaze::fovea_growth_deg
  float margin = 0.5f;
  bool floors = false;      // floor_m or floor_per_m2 > 0
  float floor_m = 0.0f;
  float floor_per_m2 = 0.0f;
  float lateral = 0.0f;     // 2^k max(1/fx, 1/fy): the cell's side per metre of depth
};
// The sums of `count` cells, one array each (camera frame).
struct PyramidCellSums {
  const float* n = nullptr;
  const float* sx = nullptr;
  const float* sy = nullptr;
  const float* sz = nullptr;
  const float* m2 = nullptr;
  const float* zmax = nullptr;
};
// merge[i] = 1 where cell i merges, 0 where it splits: pyramidMergeRef's arithmetic,
// bit for bit (pyramid_sampler.h).
void pyramidMergeSimd(const PyramidMergeParams& params, const PyramidCellSums& cells, std::size_t count,
                      float* merge);

// Levels of points [begin, end); histogram[r] += points of level r (r = kRegionInvalid too).
void levelRange(const PointCloud& cloud, const LevelParams& params, std::size_t begin, std::size_t end,
                uint8_t* region_out, uint32_t* histogram256);

// Packed voxel keys for the hash sampler, with the reference's checks' inputs.
// key_out[i] = (region << 60) | (i & M) << 40 | (j & M) << 20 | (k & M), M = 2^20 - 1,
// with (i, j, k) = voxelIndex() of the point along x, y, z, for points whose region r
// is in [1, region_count); kNoVoxelKey for the others (fovea, skipped). histogram[r]
// counts every point's region byte; lo/hi[r][a] are the smallest and largest index of
// region r's points along axis a (+/-inf while the region has none).
inline constexpr uint64_t kNoVoxelKey = UINT64_MAX;
struct VoxelKeyState {
  const double* inv_voxel = nullptr;  // 256 entries, by region byte
  double origin[3] = {};
  int region_count = 1;
  double lo[kMaxRegions][3];
  double hi[kMaxRegions][3];
  uint32_t histogram[256];
  void reset();  // ranges empty, histogram zero
};
// Points [0, n). Returns n, or (when a sampled point's index is not below 2^52 in
// magnitude: NaN, infinite or absurd) a position at or before the first such point, from
// which the caller rescans with voxelIndex(); the state is then incomplete.
std::size_t voxelKeyRange(const float* x, const float* y, const float* z, const uint8_t* region, std::size_t n,
                          VoxelKeyState& state, uint64_t* key_out);

}  // namespace kernels
}  // namespace fovea::pipeline
