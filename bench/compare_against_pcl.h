// fovea-compare's comparison against PCL, voxel by voxel: which voxels the two
// outputs share, how far apart their centroids lie, and which input points fall
// into another voxel on PCL's float lattice (the why of the report's last part).
#pragma once

#include <cstddef>
#include <cstdint>
#include <set>
#include <tuple>

#include "bench/compare_methods.h"
#include "pipeline/point_cloud.h"

namespace fovea::bench::compare {

using VoxelKey = std::tuple<int, int64_t, int64_t, int64_t>;  // region, world voxel index

struct Difference {
  std::size_t fovea_here = 0, fovea_pcl = 0;  // region-0 points
  std::size_t matched = 0, only_here = 0, only_pcl = 0;
  double max_mm = 0, p99_mm = 0, median_mm = 0;  // all matched voxels (max) / unaffected ones (p99, median)
  std::size_t moved_voxels = 0;    // matched voxels that gained or lost a point to PCL's float lattice
  double moved_max_mm = 0;
  double same_members_max_mm = 0;  // the other matched voxels
  bool same_voxel_sizes = true;
};

// `moved`: voxels (by fovea's key) that gained or lost a point to PCL's float
// lattice; their centroids are reported apart.
Difference compareWithPcl(const Output& here, const Output& pcl, const std::set<VoxelKey>* moved = nullptr);

// Sampled input points whose voxel under PCL's float lattice (float world
// coordinate times float 1/leaf, floored: voxel_grid.hpp) differs from fovea's
// double lattice (floor((origin + x) * (1 / v))).
std::size_t latticeDisagreements(const pipeline::PointCloud& cloud, const uint8_t* region, const Output& fovea,
                                 std::size_t& sampled, std::set<VoxelKey>& moved);

}  // namespace fovea::bench::compare
