// The fast voxel sampler: same contract and the same output as VoxelSampler (the
// reference), in one pass over the points that accumulates every voxel in place.
//
// 1. Points are taken 2048 at a time. voxelKeyRange (Highway) computes each point's
//    voxel indices (bit-exact with voxelIndex()), the per-region index ranges, the
//    region histogram and a packed key: the region and the indices wrapped to 20 bits,
//    unique within the span the reference allows (a wider region is refused anyway).
//    Points it does not take (an index of 2^51 or more in magnitude, or a bad one) are
//    done by the scalar code, which also finds the reference's first bad point.
// 2. Two passes over the chunk accumulate every voxel in place. The first finds each
//    point's voxel slot through a 1024-entry direct-mapped cache of recent voxels
//    (consecutive pixels mostly share a voxel or revisit one of the last row's), then a
//    preallocated open-addressing table (power of two >= 2 max_voxels, linear probing,
//    multiplicative hash; a frame starts on a prefix sized from the previous frame's
//    voxel count, at least 16 Ki entries, and doubles it when half full). The second
//    adds each point to its slot's accumulator, without a branch on whether the voxel
//    changed (noisy depth makes that branch unpredictable: keeping the current voxel in
//    registers and switching on a change was 8 to 9 % slower on the mock room).
//    The accumulator holds exactly what reduceVoxel() computes (first point, double
//    sums relative to it, float min/max, integer colour sums, count), updated with the
//    same expressions in input order, so centroids are bit-identical.
// 3. Only the occupied voxels are radix-sorted, by the reference's packed key
//    (region, i, j, k relative to the region's smallest index; the voxel's slot packed
//    below it where both fit 64 bits), and written out in that order with
//    reduceVoxel()'s final expressions.
// With a worker pool, step 1 runs on its threads over contiguous ranges (keys kept for
// every point, ranges and first bad point merged in point order); steps 2-3 are
// sequential. All memory is allocated by the constructor; sample() never allocates.
//
// A difference by design: with more than max_voxels occupied voxels it stops
// counting at the first voxel too many (the error says "more than").
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/result.h"
#include "pipeline/acuity.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/kernels/worker_pool.h"
#include "pipeline/point_cloud.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::pipeline {

// The sampler's multiplicative (Fibonacci) hash of a packed voxel key: its top bits
// index the recent-voxel cache and the table.
constexpr uint64_t hashVoxelKey(uint64_t key) { return key * 0x9E3779B97F4A7C15ull; }

// (sum + count / 2) / count, the reference's rounded mean colour, without a 64-bit
// division (tens of cycles each, three a voxel: most of writing the voxels out):
// the quotient from the double reciprocal inv_count = 1.0 / count, at most one off
// for numerators below 2^52 (a colour sum is below 2^40), then corrected with
// integer multiplications. Exact: tests/equivalence/test_sampler_equivalence.cpp.
inline uint8_t roundedMeanColour(uint64_t sum, uint64_t count, double inv_count) {
  const uint64_t numerator = sum + count / 2;
  uint64_t q = static_cast<uint64_t>(static_cast<double>(numerator) * inv_count);
  if (q * count > numerator) {
    --q;
  } else if ((q + 1) * count <= numerator) {
    ++q;
  }
  return static_cast<uint8_t>(q);
}

class HashVoxelSampler {
 public:
  HashVoxelSampler() = default;
  HashVoxelSampler(std::size_t max_points, std::size_t max_voxels);

  // Same contract as VoxelSampler::sample, but for one thing: after an error,
  // representative's contents are unspecified (the sampler works in it).
  Status sample(const PointCloud& in, const uint8_t* region, int region_count,
                const std::array<double, kMaxRegions>& voxel_size_m, FoveatedCloud& out, SampleCounts& counts,
                uint32_t* representative = nullptr);

  // Lets step 1 (voxel keys and checks) share the pool's threads; the output is
  // the same. The pool must outlive the sampler's use of it; null: one thread.
  void setWorkerPool(WorkerPool* pool);

  std::size_t maxPoints() const { return max_points_; }
  std::size_t maxVoxels() const { return max_voxels_; }
  std::size_t tableSize() const { return table_key_.size(); }
  // Points of the last sample() whose voxel was not in the recent-voxel cache: each
  // costs a table probe and a mispredicted branch (benchmarks report it). At least
  // the number of voxels, since a voxel's first point is one.
  std::size_t lastTableLookups() const { return lookups_; }

  static constexpr std::size_t kChunk = 2048;  // points per key batch
  // A voxel's colour sums are 32-bit (8 bytes a voxel less than 64-bit sums):
  // exact while a sample takes at most this many points (255 each). sample()
  // refuses more; Foveator::create() refuses a capacity above it.
  static constexpr std::size_t kMaxPoints = UINT32_MAX / 255;
  // The recent-voxel cache has 2^kRecentBits lines, indexed by the top bits of
  // hashVoxelKey(); the line of kNoVoxelKey (fovea and skipped points) always holds it.
  static constexpr int kRecentBits = 10;

 private:
  // What reduceVoxel() accumulates for one voxel.
  struct Acc {
    double sx, sy, sz;  // sums of (double(p) - first), input order
    float fx, fy, fz;   // the first point
    float lo[3], hi[3];
    uint32_t n;
    uint32_t sr, sg, sb;  // at most 255 kMaxPoints each
  };
  // The first point with a bad voxel index (as the reference reports it).
  struct BadPoint {
    bool bad = false;
    std::size_t point = 0;
    int axis = 0;
    double value = 0.0;
    uint8_t region = 0;
  };
  static constexpr uint64_t kEmpty = kernels::kNoVoxelKey;  // keys never set bit 63
  // The recent-voxel cache's line of kEmpty, which always holds it (slot kNoSlot).
  static constexpr std::size_t kEmptyLine = hashVoxelKey(kEmpty) >> (64 - kRecentBits);
  static constexpr uint32_t kNoSlot = UINT32_MAX;

  struct KeyJob;
  struct KeyPass;
  struct VoxelOrder;
  using RegionLo = std::array<std::array<int64_t, 3>, kMaxRegions>;  // smallest voxel index per region and axis

  // sample()'s steps, in order.
  void startFrame(const PointCloud& in, int region_count, const std::array<double, 256>& inv_voxel);
  // point_slot (null: no representatives asked for) gets each point's voxel
  // slot: the caller's representative array, which sample() then turns into
  // output indices in place (slotsToRepresentatives).
  KeyPass keysThreaded(const PointCloud& in, const uint8_t* region, int parts, uint32_t* point_slot);
  void mergePartStates(int parts);
  KeyPass keysInChunks(const PointCloud& in, const uint8_t* region, int region_count, uint32_t* point_slot);
  Status countAndCheckSpans(int region_count, const std::array<double, kMaxRegions>& voxel_size_m,
                            SampleCounts& counts, RegionLo& lo_index) const;
  VoxelOrder sortVoxels(int region_count, const SampleCounts& counts, const RegionLo& lo_index, std::size_t voxels);
  void writeVoxels(const VoxelOrder& order, std::size_t fovea, std::size_t voxels, FoveatedCloud& out,
                   SampleCounts& counts);
  void slotsToRepresentatives(const uint8_t* region, std::size_t n, uint32_t* representative) const;
  // Keys of points [begin, end) into keys[0, end - begin), with the scalar code for
  // the points the SIMD kernel leaves. False at the first bad point (in `bad`).
  bool computeKeys(const PointCloud& in, const uint8_t* region, std::size_t begin, std::size_t end,
                   kernels::VoxelKeyState& state, uint64_t* keys, BadPoint& bad) const;
  // Accumulates points [begin, end) (keys[i - begin]) into their voxels, and
  // with kRepresentative each point's slot into point_slot[i]. Returns false
  // when a voxel beyond max_voxels appears (nothing more is accumulated).
  template <bool kRepresentative>
  bool accumulate(const PointCloud& in, std::size_t begin, std::size_t end, const uint64_t* keys,
                  uint32_t* point_slot);
  // accumulate() on at most kChunk points (the slot scratch).
  template <bool kRepresentative>
  bool accumulateChunk(const PointCloud& in, std::size_t begin, std::size_t end, const uint64_t* keys,
                       uint32_t* point_slot);
  // The slot of `key` past the recent-voxel cache (updating its line), inserting a
  // fresh voxel; kNoSlot past max_voxels.
  [[gnu::noinline]] uint32_t findSlotInTable(uint64_t key, uint64_t hash, std::size_t line, bool& fresh);
  void clearTable(std::size_t voxels);
  // Doubles the table's active prefix and reinserts the voxels found so far.
  void growTable(std::size_t voxels);

  std::size_t max_voxels_ = 0;
  std::size_t active_ = 0;  // entries of the table in use this frame (a power of two)
  std::size_t table_mask_ = 0;
  std::size_t last_voxels_ = 0;
  std::size_t voxels_ = 0;  // occupied this frame
  std::size_t lookups_ = 0;  // recent-voxel cache misses this frame
  int shift_ = 64;
  // The table: keys (probed; 8 bytes an entry keeps it dense in cache) and, beside
  // them, the slots (read on a match only). It is empty between a frame's
  // accumulation and the next (clearTable), and holds at least 2 max_voxels
  // entries: step 3's sort uses them meanwhile (keys and their scratch, slots and
  // theirs), and sample() empties the keys it wrote again.
  std::vector<uint64_t> table_key_;
  std::vector<uint32_t> table_slot_;
  uint64_t* sortKeys() { return table_key_.data(); }
  uint64_t* sortKeysScratch() { return table_key_.data() + max_voxels_; }
  uint32_t* sortSlots() { return table_slot_.data(); }
  uint32_t* sortSlotsScratch() { return table_slot_.data() + max_voxels_; }
  // Per voxel slot (max_voxels).
  std::vector<uint64_t> voxel_key_;        // the hash key
  std::vector<uint32_t> voxel_table_pos_;  // where it sits in the table
  // Default-initialised (not zeroed): the pages of slots a frame never reaches are not
  // touched, so the resident size follows the voxels actually used, not max_voxels.
  std::unique_ptr<Acc[]> acc_;
  std::vector<uint32_t> rank_;             // place in the output order
  // Per point (max_points; each point's voxel slot goes into the caller's
  // representative array, when asked for: no array of the sampler's own).
  std::size_t max_points_ = 0;
  std::vector<uint64_t> point_key_;   // keys of the whole cloud (threaded key pass only)
  std::vector<uint64_t> chunk_key_;   // kChunk keys (single-threaded)
  std::vector<uint32_t> chunk_slot_;  // kChunk voxel slots (accumulateChunk's first pass)
  std::vector<kernels::VoxelKeyState> part_state_;
  std::vector<BadPoint> part_bad_;
  std::array<uint64_t, std::size_t{1} << kRecentBits> recent_key_{};
  std::array<uint32_t, std::size_t{1} << kRecentBits> recent_slot_{};
  WorkerPool* pool_ = nullptr;
};

}  // namespace fovea::pipeline
