// fovea-compare's comparison against PCL, voxel by voxel.
#include "bench/compare_against_pcl.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <vector>

#include "pipeline/voxel_sampler.h"

namespace fovea::bench::compare {
namespace {

VoxelKey keyOf(const Output& o, std::size_t i) {
  const int r = o.region[i];
  const double inv = 1.0 / o.voxel_size_m[r];
  return {r, static_cast<int64_t>(std::floor(o.world[i][0] * inv)),
          static_cast<int64_t>(std::floor(o.world[i][1] * inv)), static_cast<int64_t>(std::floor(o.world[i][2] * inv))};
}

}  // namespace

Difference compareWithPcl(const Output& here, const Output& pcl, const std::set<VoxelKey>* moved) {
  Difference d;
  for (int r = 1; r < here.region_count; ++r) {
    d.same_voxel_sizes = d.same_voxel_sizes && here.voxel_size_m[r] == pcl.voxel_size_m[r];
  }
  std::map<VoxelKey, std::array<double, 3>> pcl_voxels;
  for (std::size_t i = 0; i < pcl.world.size(); ++i) {
    if (pcl.region[i] == 0) {
      ++d.fovea_pcl;
      continue;
    }
    // Two PCL centroids can floor into one voxel when PCL's float lattice
    // disagrees with the double one near a face; the second counts as unmatched.
    if (!pcl_voxels.emplace(keyOf(pcl, i), pcl.world[i]).second) ++d.only_pcl;
  }
  std::vector<double> diffs_mm;
  std::size_t found = 0;
  for (std::size_t i = 0; i < here.world.size(); ++i) {
    if (here.region[i] == 0) {
      ++d.fovea_here;
      continue;
    }
    const auto it = pcl_voxels.find(keyOf(here, i));
    if (it == pcl_voxels.end()) {
      ++d.only_here;
      continue;
    }
    ++found;
    const double dx = here.world[i][0] - it->second[0];
    const double dy = here.world[i][1] - it->second[1];
    const double dz = here.world[i][2] - it->second[2];
    const double mm = 1000.0 * std::sqrt(dx * dx + dy * dy + dz * dz);
    if (moved != nullptr && moved->count(it->first) != 0) {
      ++d.moved_voxels;
      d.moved_max_mm = std::max(d.moved_max_mm, mm);
      d.max_mm = std::max(d.max_mm, mm);
      continue;
    }
    diffs_mm.push_back(mm);
  }
  d.matched = found;
  d.only_pcl += pcl_voxels.size() - found;
  if (!diffs_mm.empty()) {
    std::sort(diffs_mm.begin(), diffs_mm.end());
    d.same_members_max_mm = diffs_mm.back();
    d.max_mm = std::max(d.max_mm, diffs_mm.back());
    d.p99_mm = diffs_mm[std::min(diffs_mm.size() - 1, diffs_mm.size() * 99 / 100)];
    d.median_mm = diffs_mm[diffs_mm.size() / 2];
  }
  return d;
}

std::size_t latticeDisagreements(const pipeline::PointCloud& cloud, const uint8_t* region, const Output& fovea,
                                 std::size_t& sampled, std::set<VoxelKey>& moved) {
  std::size_t differ = 0;
  sampled = 0;
  const double origin[3] = {cloud.origin_m.x(), cloud.origin_m.y(), cloud.origin_m.z()};
  const float* coord[3] = {cloud.x(), cloud.y(), cloud.z()};
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const int r = region[i];
    if (r == 0 || r >= fovea.region_count) continue;
    ++sampled;
    const double inv = 1.0 / fovea.voxel_size_m[r];
    const float inv_f = 1.0f / static_cast<float>(fovea.voxel_size_m[r]);
    int64_t k_double[3], k_float[3];
    for (int a = 0; a < 3; ++a) {
      k_double[a] = static_cast<int64_t>(pipeline::voxelIndex(origin[a], coord[a][i], inv));
      const float world_f = static_cast<float>(origin[a] + static_cast<double>(coord[a][i]));
      k_float[a] = static_cast<int64_t>(std::floor(world_f * inv_f));
    }
    if (k_double[0] != k_float[0] || k_double[1] != k_float[1] || k_double[2] != k_float[2]) {
      ++differ;
      moved.insert({r, k_double[0], k_double[1], k_double[2]});
      moved.insert({r, k_float[0], k_float[1], k_float[2]});
    }
  }
  return differ;
}

}  // namespace fovea::bench::compare
