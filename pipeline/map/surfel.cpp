#include "pipeline/map/surfel.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace fovea::pipeline::map {

namespace {

constexpr float kNormalSteps = 4094.0f;  // 12 bits, an odd number of levels: 0 is one of them

uint32_t quantiseUnit(float v) {  // [-1, 1] -> [0, 4094]
  const float q = std::clamp((v * 0.5f + 0.5f) * kNormalSteps + 0.5f, 0.0f, kNormalSteps);
  return static_cast<uint32_t>(q);
}
float unquantiseUnit(uint32_t q) { return static_cast<float>(q) / kNormalSteps * 2.0f - 1.0f; }
float signNotZero(float v) { return v < 0.0f ? -1.0f : 1.0f; }

const float kLogRadiusSpan = std::log(kMaxRadiusM / kMinRadiusM);

}  // namespace

uint32_t encodeNormal(const Eigen::Vector3f& n) {
  const float l1 = std::abs(n.x()) + std::abs(n.y()) + std::abs(n.z());
  if (!(l1 > 0.0f) || !std::isfinite(l1)) return encodeNormal(Eigen::Vector3f::UnitZ());
  float u = n.x() / l1, v = n.y() / l1;
  if (n.z() < 0.0f) {  // the lower half folds over the diagonals
    const float fu = (1.0f - std::abs(v)) * signNotZero(u);
    const float fv = (1.0f - std::abs(u)) * signNotZero(v);
    u = fu;
    v = fv;
  }
  return (quantiseUnit(u) << 12) | quantiseUnit(v);
}

Eigen::Vector3f decodeNormal(uint32_t code) {
  float u = unquantiseUnit((code >> 12) & 0xfffu);
  float v = unquantiseUnit(code & 0xfffu);
  const float z = 1.0f - std::abs(u) - std::abs(v);
  if (z < 0.0f) {
    const float fu = (1.0f - std::abs(v)) * signNotZero(u);
    const float fv = (1.0f - std::abs(u)) * signNotZero(v);
    u = fu;
    v = fv;
  }
  return Eigen::Vector3f(u, v, z).normalized();
}

uint8_t encodeRadius(float radius_m) {
  if (!(radius_m > kMinRadiusM)) return 0;
  if (radius_m >= kMaxRadiusM) return 255;
  const float t = std::log(radius_m / kMinRadiusM) / kLogRadiusSpan;
  return static_cast<uint8_t>(std::clamp(t * 255.0f + 0.5f, 0.0f, 255.0f));
}

float decodeRadius(uint8_t code) {
  // A table of the 256 values (the index map and the association decode a radius
  // per surfel per frame; an exp each was a tenth of the index map's time).
  static const std::array<float, 256> kTable = [] {
    std::array<float, 256> table{};
    for (int c = 0; c < 256; ++c) table[c] = kMinRadiusM * std::exp(static_cast<float>(c) / 255.0f * kLogRadiusSpan);
    return table;
  }();
  return kTable[code];
}

}  // namespace fovea::pipeline::map
