// The foveation pipeline for one cloud: partition (Algorithm 1), fixation
// distance d0, voxel sizes (Eq. 5-6), foveated sampling (Eq. 7).
// All memory is allocated by create(); foveate() allocates nothing.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

#include "core/kernel_set.h"
#include "core/result.h"
#include "pipeline/acuity.h"
#include "pipeline/acuity_levels.h"
#include "pipeline/fixation.h"
#include "pipeline/kernels/hash_voxel_sampler.h"
#include "pipeline/kernels/worker_pool.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::pipeline {

struct PipelineCapacity {
  std::size_t max_points = 640 * 480;  // points per input cloud
  std::size_t max_voxels = 640 * 480;  // occupied voxels per output cloud
  // The kernels foveate() runs: the scalar reference or the SIMD set (identical
  // output; docs/kernels.md). Chosen once at start-up, FOVEA_FORCE_KERNEL overrides.
  KernelSet kernels = defaultKernelSet();
  // Threads that share one frame's partition and voxel sampling (kernels == kSimd;
  // the reference runs on the calling thread). Created once by create(), in
  // [1, 64]; the output does not depend on it.
  int threads = 1;
  // A frame whose sampling needs more voxels than max_voxels, or more points than
  // the output holds, is sampled again with every region's voxel edge doubled, at
  // most this many times (0: the error at once), in [0, 16]: that frame's
  // periphery coarser rather than no frame (FoveationStats::coarsened). A near
  // fixation shrinks F1's voxels with d0 (Eq. 5-6), below the points' spacing,
  // where a doubling merges few: a tracked camera orbiting a world-fixed gaze
  // took more than 0.3 of the pixels, and with the map's live points capped
  // (map.max_live_points) 3 frames in 60 s still did not fit after 3 doublings
  // and none after 6 (docs/service.md).
  int max_coarsenings = 6;
};

struct FoveationConfig {
  AcuityConfig acuity;
  FixationConfig fixation;
};

struct RegionStats {
  uint32_t points_in = 0;
  uint32_t points_out = 0;
  double voxel_size_m = 0.0;  // 0 for the untouched fovea
};

struct FoveationStats {
  int region_count = 0;
  std::array<RegionStats, kMaxRegions> regions{};
  uint32_t points_in = 0;          // valid input points
  uint32_t points_out = 0;
  uint32_t dropped_nonfinite = 0;  // input points with NaN/Inf coordinates
  uint32_t culled = 0;             // ACUITY's view cull (drop): outside the field of view, not sent
  uint32_t refined = 0;            // ACUITY's refinement: level changes over all passes
  int refine_passes = 0;           // ... and the passes that moved a point
  int coarsened = 0;               // voxel edges doubled to fit the capacity (PipelineCapacity::max_coarsenings)
  Fixation fixation;
  int64_t partition_ns = 0;
  int64_t fixation_ns = 0;
  int64_t sample_ns = 0;           // the sampling, with ACUITY's refinement passes
};

// The kernel each stage of foveate() runs, chosen once by the constructor from
// PipelineCapacity::kernels and ::threads (docs/kernels.md). For logs and tests.
struct StageKernels {
  std::string_view partition;    // the cones (Algorithm 1)
  std::string_view levels;       // ACUITY's levels, in place of the cones
  std::string_view fixation;     // d0 (not for the levels)
  std::string_view sample;       // the voxel sampler
  std::string_view refine_test;  // ACUITY's refinement test
};

class Foveator {
 public:
  static Result<Foveator> create(const PipelineCapacity& capacity, const FoveationConfig& config);

  // Replaces the foveation parameters (preset, m, fixation) without allocating;
  // on error the previous configuration stays.
  Status setConfig(const FoveationConfig& config);

  // Foveates `in` for `gaze` into `out` (whose capacity must be at least
  // in.size()). kInvalidInput for a bad gaze; kRangeExceeded as the sampler
  // reports; kCapacityExceeded when the frame does not fit even after
  // capacity().max_coarsenings doublings of the voxel edges. representative,
  // if not null, gets for each input point the index of its output point (see
  // VoxelSampler::sample). Never allocates on success.
  Status foveate(const PointCloud& in, const Gaze& gaze, FoveatedCloud& out, FoveationStats& stats,
                 uint32_t* representative = nullptr);

  const RegionModel& model() const { return model_; }
  const FoveationConfig& config() const { return config_; }
  const PipelineCapacity& capacity() const { return capacity_; }
  // Region of each input point of the last foveate() call.
  const uint8_t* lastRegions() const { return region_.data(); }
  const StageKernels& stageKernels() const { return table_.names; }

 private:
  // One function per stage, filled by the constructor for the kernel set and the
  // pool, so that foveate() runs the entries in order and never asks again. They
  // take the Foveator as an argument rather than capturing it: a moved Foveator
  // (create() returns one by value) keeps a valid table.
  struct KernelTable {
    void (*partition)(Foveator&, const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) = nullptr;
    void (*levels)(Foveator&, const PointCloud& in, const Gaze& gaze, PartitionCounts& counts) = nullptr;
    Fixation (*fixation)(const PointCloud& in, const uint8_t* region, const Gaze& gaze, const FixationConfig& config,
                         double* t_scratch) = nullptr;
    Status (*sample)(Foveator&, const PointCloud& in, const std::array<double, kMaxRegions>& voxel_size_m,
                     FoveatedCloud& out, SampleCounts& counts, uint32_t* representative) = nullptr;
    // Returns the points beyond their MAR (refineState() gets every point's state).
    std::size_t (*refine_test)(Foveator&, const PointCloud& in, const Gaze& gaze, const PointCloud& out,
                               const uint32_t* representative) = nullptr;
    StageKernels names;
  };
  static KernelTable chooseKernels(KernelSet set, bool pooled);

  Foveator(const PipelineCapacity& capacity, const FoveationConfig& config, RegionModel model);
  void partitionParallel(const PointCloud& in, const Gaze& gaze, PartitionCounts& counts);
  void levelsParallel(const PointCloud& in, const Gaze& gaze, PartitionCounts& counts);
  // ACUITY's refinement test split over the pool; returns the points beyond their MAR.
  std::size_t refineTestParallel(const PointCloud& in, const Gaze& gaze, const PointCloud& out,
                                 const uint32_t* representative);
  void sumHistograms(PartitionCounts& counts) const;  // the pool's parts' histograms
  // table_.sample, again with the voxel edges doubled while over the capacity.
  Status sampleWithinCapacity(const PointCloud& in, std::array<double, kMaxRegions>& voxel_size_m,
                              FoveatedCloud& out, SampleCounts& counts, uint32_t* representative,
                              FoveationStats& stats);

  PipelineCapacity capacity_;
  FoveationConfig config_;
  RegionModel model_;
  ConeBounds bounds_;
  LevelBounds levels_;  // Preset::kAcuity
  std::vector<uint8_t> region_;
  // Per point, 8 bytes, for one of two uses a frame never has both of: the
  // cones' fixation (a double per point) or ACUITY's refinement (its three
  // arrays below); every use writes before it reads. 6 bytes a point less
  // than separate arrays (1.8 MB at 640x480).
  std::unique_ptr<std::byte[]> point_scratch_;
  static_assert(sizeof(uint32_t) + 2 <= sizeof(double), "the refinement's arrays fit the fixation's");
  double* fixationScratch() { return reinterpret_cast<double*>(point_scratch_.get()); }
  // ACUITY's refinement: each point's representative when foveate() gets none,
  // each point's state (acuity_levels.h), and per output point whether its
  // voxel is beyond (the output never exceeds the input).
  uint32_t* representativeScratch() { return reinterpret_cast<uint32_t*>(point_scratch_.get()); }
  uint8_t* refineState() {
    return reinterpret_cast<uint8_t*>(point_scratch_.get()) + capacity_.max_points * sizeof(uint32_t);
  }
  uint8_t* voxelBeyond() { return refineState() + capacity_.max_points; }
  VoxelSampler sampler_;           // kernels == kRef (only the one in use is allocated)
  HashVoxelSampler hash_sampler_;  // kernels == kSimd
  std::unique_ptr<WorkerPool> pool_;        // threads > 1 and kernels == kSimd
  std::vector<uint32_t> part_histograms_;  // 256 per thread
  KernelTable table_;
};

}  // namespace fovea::pipeline
