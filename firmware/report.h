// What fovead prints: per-frame lines and summaries of the foveation.
#pragma once

#include <cstdio>
#include <string>
#include <vector>

#include "pipeline/foveator.h"

namespace fovea::firmware {

// Timing samples of one stage, preallocated for the whole run.
class Samples {
 public:
  explicit Samples(std::size_t capacity) { values_.reserve(capacity); }
  void add(double v) {
    if (values_.size() < values_.capacity()) values_.push_back(v);
  }
  std::size_t count() const { return values_.size(); }
  double median() const { return quantile(0.5); }
  double quantile(double q) const;  // nearest rank; 0 when empty
  double max() const;
  double mean() const;

 private:
  std::vector<double> values_;
};

// Per-region totals over a run.
struct RegionTotals {
  std::array<uint64_t, pipeline::kMaxRegions> points_in{};
  std::array<uint64_t, pipeline::kMaxRegions> points_out{};
  std::array<double, pipeline::kMaxRegions> voxel_size_sum_m{};
  uint64_t frames = 0;
  void add(const pipeline::FoveationStats& stats);
};

// "region  ecc<=  voxel  in  out  kept" table, averaged per frame.
void printRegionTable(std::FILE* out, const pipeline::RegionModel& model, const RegionTotals& totals);

}  // namespace fovea::firmware
