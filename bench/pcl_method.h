// The paper's method with PCL (fovea-compare's baseline): fovea's partition
// (Algorithm 1, partitionRef) and fixation distance give the regions and voxel
// sizes; the fovea is left untouched and every other region goes through its own
// pcl::VoxelGrid with leaf = that region's voxel size. Built only when PCL is
// found (FOVEA_WITH_PCL); this header keeps PCL's headers out of the caller.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/result.h"
#include "pipeline/foveator.h"
#include "pipeline/partition.h"
#include "pipeline/point_cloud.h"

namespace fovea::bench {

class PclFoveation {
 public:
  // Allocates scratch for clouds of up to max_points.
  PclFoveation(std::size_t max_points, const pipeline::FoveationConfig& config);
  ~PclFoveation();
  PclFoveation(const PclFoveation&) = delete;
  PclFoveation& operator=(const PclFoveation&) = delete;

  // Partition, d0, per-region VoxelGrid (the gaze is normalised as Foveator does).
  Status run(const pipeline::PointCloud& cloud, const pipeline::Gaze& gaze);

  // The last run's output: world coordinates (as PCL computed them, in float),
  // the region of each point, and the voxel size of each region.
  std::size_t outputSize() const;
  void output(std::vector<std::array<double, 3>>& world, std::vector<uint8_t>& region) const;
  const std::array<double, pipeline::kMaxRegions>& voxelSizes() const { return voxel_size_m_; }
  int regionCount() const;
  double d0() const { return d0_m_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::array<double, pipeline::kMaxRegions> voxel_size_m_{};
  double d0_m_ = 0.0;
};

}  // namespace fovea::bench
