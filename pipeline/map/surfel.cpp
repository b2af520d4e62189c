#include "pipeline/map/surfel.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <limits>

namespace fovea::pipeline::map {

namespace {

const float kLogRadiusSpan = std::log(kMaxRadiusM / kMinRadiusM);

}  // namespace

uint8_t encodeRadiusRef(float radius_m) {
  if (!(radius_m > kMinRadiusM)) return 0;
  if (radius_m >= kMaxRadiusM) return 255;
  const float t = std::log(radius_m / kMinRadiusM) / kLogRadiusSpan;
  return static_cast<uint8_t>(std::clamp(t * 255.0f + 0.5f, 0.0f, 255.0f));
}

// The 256 radii (the index map and the association decode a radius per surfel
// per frame; an exp each was a tenth of the index map's time).
std::array<float, 256> makeRadiusTable() {
  const float span = std::log(kMaxRadiusM / kMinRadiusM);
  std::array<float, 256> table{};
  for (int c = 0; c < 256; ++c) table[c] = kMinRadiusM * std::exp(static_cast<float>(c) / 255.0f * span);
  return table;
}

const std::array<float, 256> kRadiusTable = makeRadiusTable();

namespace {

// The smallest float in (kMinRadiusM, kMaxRadiusM) whose reference code is at
// least `code` (1..255): a bisection over the floats' bits, which order
// positive floats as they order their values (the reference is monotonic).
uint32_t lowestBitsOfCode(uint32_t code) {
  // code(lo) < code <= code(hi)
  uint32_t lo = std::bit_cast<uint32_t>(kMinRadiusM), hi = std::bit_cast<uint32_t>(kMaxRadiusM);
  while (hi - lo > 1) {
    const uint32_t mid = lo + (hi - lo) / 2;
    (encodeRadiusRef(std::bit_cast<float>(mid)) >= code ? hi : lo) = mid;
  }
  return hi;
}

}  // namespace

RadiusCodeTables makeRadiusCodeTables() {
  RadiusCodeTables t;
  t.lowest_bits = std::bit_cast<uint32_t>(kMinRadiusM);
  t.lowest_radius[0] = 0.0f;
  for (uint32_t code = 1; code < 256; ++code) t.lowest_radius[code] = std::bit_cast<float>(lowestBitsOfCode(code));
  t.lowest_radius[256] = std::numeric_limits<float>::infinity();
  for (std::size_t b = 0; b < t.bucket_code.size(); ++b) {
    const uint64_t bits = t.lowest_bits + (static_cast<uint64_t>(b) << RadiusCodeTables::kBucketShift);
    const bool past = bits >= std::bit_cast<uint32_t>(kMaxRadiusM);
    t.bucket_code[b] = past ? 255u : encodeRadiusRef(std::bit_cast<float>(static_cast<uint32_t>(bits)));
  }
  return t;
}

const RadiusCodeTables kRadiusCodes = makeRadiusCodeTables();

}  // namespace fovea::pipeline::map
