// The fast voxel sampler: same contract and the same output as VoxelSampler (the
// reference), without sorting the points.
//
// Per point, the voxel key (region, i, j, k packed exactly as the reference packs
// it) is looked up in a preallocated open-addressing hash table (power-of-two size
// >= 2 max_voxels, linear probing, multiplicative hash); consecutive points of an
// image usually share a voxel, so the last key and its slot are cached and most
// points skip the lookup. The table in use starts at a cache-friendly size and
// doubles (within the preallocated memory) when half full, so a frame with few
// voxels does not pay for cache misses all over a table sized for the worst case. Each voxel accumulates, in input order, exactly what the
// reference accumulates after its stable sort (sums in double relative to the
// voxel's first point, float min/max, integer colour sums), so centroids, colours
// and weights are bit-identical. Only the occupied voxels (far fewer than points)
// are then radix-sorted by key, which gives the reference's order (region, i, j, k).
// Voxel indices come from voxelIndexSimd in chunks (bit-exact with voxelIndex()),
// computed once per point (the reference computes them twice).
// All memory is allocated by the constructor; sample() never allocates.
//
// Differences from the reference, by design: with more than max_voxels occupied
// voxels it stops at the first voxel too many (the error says "more than"), and
// the error paths leave `out` empty either way.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "hal/result.h"
#include "pipeline/acuity.h"
#include "pipeline/point_cloud.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::pipeline {

class HashVoxelSampler {
 public:
  HashVoxelSampler() = default;
  HashVoxelSampler(std::size_t max_points, std::size_t max_voxels);

  // Same contract as VoxelSampler::sample.
  Status sample(const PointCloud& in, const uint8_t* region, int region_count,
                const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out, SampleCounts& counts,
                uint32_t* representative = nullptr);

  std::size_t maxPoints() const { return max_points_; }
  std::size_t maxVoxels() const { return max_voxels_; }
  std::size_t tableSize() const { return table_.size(); }

  static constexpr std::size_t kChunk = 2048;  // points per voxel-index batch

 private:
  struct Entry {
    uint64_t key;
    uint32_t slot;
  };
  struct Voxel {
    uint64_t key;       // the hash key (indices wrapped to 20 bits)
    int64_t index[3];   // the voxel's world indices
    double sx, sy, sz;
    uint64_t sr, sg, sb;
    float first[3];
    float lo[3], hi[3];
    uint32_t count;
    uint32_t table_pos;
  };
  static constexpr uint64_t kEmpty = UINT64_MAX;  // keys never set bit 63

  void clearTable(std::size_t voxels);
  // Doubles the table's active prefix and reinserts the voxels found so far.
  void growTable(std::size_t voxels);

  std::size_t max_points_ = 0;
  std::size_t max_voxels_ = 0;
  // The table in use this frame is the prefix [0, active_) of table_: it starts
  // small (cache-resident) and doubles when half full, up to table_.size().
  std::size_t active_ = 0;
  int shift_ = 64;
  std::vector<Entry> table_;
  std::vector<Voxel> voxels_;
  std::vector<uint64_t> sort_keys_, sort_keys_scratch_;
  std::vector<uint32_t> sort_slot_, sort_slot_scratch_;
  std::vector<uint32_t> out_pos_;
  std::vector<double> chunk_index_;  // 3 * kChunk voxel indices
  static constexpr int kRecentBits = 10;
  std::array<uint64_t, std::size_t{1} << kRecentBits> recent_key_{};
  std::array<uint32_t, std::size_t{1} << kRecentBits> recent_slot_{};
};

}  // namespace fovea::pipeline
