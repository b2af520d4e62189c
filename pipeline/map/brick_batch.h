// A frame's map bricks on their way from the planner (the foveation stage,
// which owns the map) to the sender (the send stage, which encodes them for the
// session's MTU): each due brick's settled surfels, sampled on the lattice of
// the level the operator's eye needs (issue 26, docs/map-delta.md).
//
// BrickSampler fills a batch: it takes a brick's settled surfels (a surfel is
// the operator's once settled, surfel_map.h) and samples them with the plain
// VoxelSampler at the brick's level (level 0: every surfel as it is; level n:
// one representative per voxel of ACUITY's level-n lattice, the same voxels a
// per-frame ACUITY stream would use). Memory: the batch and the sampler's
// scratch are allocated at construction; append() never allocates.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/result.h"
#include "pipeline/acuity.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/point_cloud.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::pipeline::map {

struct BrickBatchEntry {
  uint16_t brick = 0;  // the map's slot
  SurfelMap::BrickKey key;
  uint32_t version = 0;  // MapDelta::markSent's
  uint8_t level = 0;
  bool fovea = false;     // the plan's fovea brick: sent before the frame's live points
  uint32_t first = 0;     // its points: points[first, first + count)
  uint32_t count = 0;
};

class BrickBatch {
 public:
  BrickBatch() = default;
  BrickBatch(std::size_t max_points, std::size_t max_bricks,
             FoveatedCloud::Weights weights = FoveatedCloud::Weights::kKept)
      : points(max_points, weights), entries_(max_bricks) {}

  // Empties the batch; its points are then written relative to origin_m.
  void clear(const Eigen::Vector3d& origin_m) {
    count_ = 0;
    points.clear();
    points.points.origin_m = origin_m;
  }
  std::span<const BrickBatchEntry> entries() const { return {entries_.data(), count_}; }
  std::size_t maxBricks() const { return entries_.size(); }
  bool full() const { return count_ == entries_.size(); }
  BrickBatchEntry& add() { return entries_[count_++]; }  // caller checks full()
  // Entry e's points are points[e.first, e.first + e.count), their region the
  // entry's level: one brick's encode takes them where they lie
  // (net::EncodeInput::slice).

  FoveatedCloud points;  // every entry's points, region = the entry's level
  // Level n's lattice step (ACUITY's v_n), for the encoder: [0] is 0.
  std::array<double, kMaxRegions> level_step_m{};

 private:
  std::vector<BrickBatchEntry> entries_;
  std::size_t count_ = 0;
};

struct BrickSamplerCounters {
  uint64_t bricks = 0;
  uint64_t surfels_in = 0;
  uint64_t points_out = 0;
  uint64_t truncated = 0;  // bricks with more settled surfels than max_brick_surfels (the rest left out)
};

class BrickSampler {
 public:
  // levels: ACUITY's configuration (MapDeltaConfig::acuity: the levels the plan
  // chose by); max_brick_surfels: a brick's settled surfels taken at most.
  static Result<BrickSampler> create(const AcuityConfig& levels, std::size_t max_brick_surfels);

  // Level n's lattice step (0 for level 0).
  const std::array<double, kMaxRegions>& levelSteps() const { return level_step_m_; }

  // Samples `brick`'s settled surfels at `level` and appends them to `batch` as
  // a new entry. false (nothing added) when the batch has no room for another
  // entry or for the brick's points: the caller stops filling it.
  bool append(const SurfelMap& map, uint16_t brick, uint8_t level, uint32_t version, bool fovea, BrickBatch& batch);

  const BrickSamplerCounters& counters() const { return counters_; }
  std::size_t memoryBytes() const;

 private:
  BrickSampler(const std::array<double, kMaxRegions>& steps, std::size_t max_brick_surfels);

  std::array<double, kMaxRegions> level_step_m_{};
  PointCloud surfels_;
  std::vector<uint8_t> region_;
  VoxelSampler sampler_;
  BrickSamplerCounters counters_;
};

}  // namespace fovea::pipeline::map
