// The hash of an integer grid cell (x, y, z) for open-addressing tables: three
// large primes, XORed (Teschner et al. 2003), as voxel-hashing maps do. GridTable's
// (core/grid_table.h).
#pragma once

#include <cstddef>
#include <cstdint>

namespace fovea {

inline std::size_t gridHash(int32_t x, int32_t y, int32_t z) {
  const auto ux = static_cast<uint32_t>(x), uy = static_cast<uint32_t>(y), uz = static_cast<uint32_t>(z);
  return static_cast<std::size_t>((ux * 73856093u) ^ (uy * 19349663u) ^ (uz * 83492791u));
}

}  // namespace fovea
