#include "pipeline/map/surfel.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace fovea::pipeline::map {

namespace {

const float kLogRadiusSpan = std::log(kMaxRadiusM / kMinRadiusM);

}  // namespace

uint8_t encodeRadius(float radius_m) {
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

}  // namespace fovea::pipeline::map
