// One surfel of the fused scene map (pipeline/map/surfel_map.h) in 32 bytes, and
// the compact encodings that get it there.
//
// The position is a float relative to the origin of the surfel's brick (a cube
// of the map's brick size, at most a few metres): a float holds that to well under
// a micrometre wherever the brick is, so a map 10 km from the world origin keeps
// the precision of one at the origin (docs/precision.md). The normal is
// octahedral, 12 bits a coordinate (worst error 0.063 degrees, measured); the radius a
// logarithmic byte from 0.1 mm to 100 mm (2.7 % a step); the confidence 8.8
// fixed point (the map caps it far below 256).
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>

#include <Eigen/Core>

namespace fovea::pipeline::map {

// Aligned to its size, so that no surfel of the pool straddles two cache lines:
// with the allocator's 16-byte alignment every other one did, and each of those
// cost two misses where fusion reads a surfel the index map names (at 920 000
// surfels on the mock orbit the association took 13.0 against 9.6 ms a frame).
struct alignas(32) Surfel {
  float x = 0.0f, y = 0.0f, z = 0.0f;  // metres from the brick's origin
  uint32_t normal_radius = 0;          // encodeNormal() << 8 | encodeRadius()
  uint8_t red = 0, green = 0, blue = 0;
  uint8_t flags = 0;                   // kSurfelLive | kSurfelStable | kSurfelSettled
  uint16_t confidence = 0;             // 8.8 fixed point: the summed observation weights
  uint16_t brick = 0;                  // the brick's slot in the map's brick table
  uint32_t first_seen = 0;             // the map's frame number of the first observation
  uint32_t last_seen = 0;              // ... and of the last
};
static_assert(sizeof(Surfel) == 32, "a surfel is 32 bytes");
static_assert(alignof(Surfel) == 32, "a surfel never straddles a cache line");

inline constexpr uint8_t kSurfelLive = 1;
inline constexpr uint8_t kSurfelStable = 2;
// Stable and in the map for SurfelMapConfig::settle_frames: the map's content
// for the operator (what the eye view and the stream of changes send, what
// explains a pixel: with bricks, once its brick went with it,
// SurfelMap::setHeldFrames).
inline constexpr uint8_t kSurfelSettled = 4;
// Merged or carved by an earlier pixel of the association's batch
// (SurfelMap::associate, association_plan.h): its plan is made again. Set and
// cleared within one batch, so that no other pass and no reader sees it.
inline constexpr uint8_t kSurfelTouched = 8;

// The colour a frame without one gives its surfels.
inline constexpr uint8_t kGreyRgb[3] = {128, 128, 128};

// A unit normal as 24 bits: octahedral projection, 12 bits each for u and v.
// Inline (the index map decodes one per surfel per frame and the association
// decodes and encodes one per merged pixel: as calls they were a fifth of
// fusion's time, perf on map/fuse-simd).
namespace surfel_detail {
inline constexpr float kNormalSteps = 4094.0f;  // 12 bits, an odd number of levels: 0 is one of them
inline uint32_t quantiseUnit(float v) {  // [-1, 1] -> [0, 4094]
  const float q = std::clamp((v * 0.5f + 0.5f) * kNormalSteps + 0.5f, 0.0f, kNormalSteps);
  return static_cast<uint32_t>(q);
}
// unquantiseUnit's 4096 values, made at compile time (the same IEEE arithmetic:
// two divisions a normal fewer; 4095 has a value too, for a code no encoder writes).
inline constexpr std::array<float, 4096> kUnitTable = [] {
  std::array<float, 4096> table{};
  for (uint32_t q = 0; q < 4096; ++q) table[q] = static_cast<float>(q) / kNormalSteps * 2.0f - 1.0f;
  return table;
}();
inline float unquantiseUnit(uint32_t q) { return kUnitTable[q & 0xfffu]; }
inline float signNotZero(float v) { return v < 0.0f ? -1.0f : 1.0f; }
}  // namespace surfel_detail

inline uint32_t encodeNormal(const Eigen::Vector3f& n) {
  using namespace surfel_detail;
  const float l1 = std::abs(n.x()) + std::abs(n.y()) + std::abs(n.z());
  if (!(l1 > 0.0f) || !std::isfinite(l1)) return (quantiseUnit(0.0f) << 12) | quantiseUnit(0.0f);  // +z
  const float inv_l1 = 1.0f / l1;  // one division, not two
  float u = n.x() * inv_l1, v = n.y() * inv_l1;
  if (n.z() < 0.0f) {  // the lower half folds over the diagonals
    const float fu = (1.0f - std::abs(v)) * signNotZero(u);
    const float fv = (1.0f - std::abs(u)) * signNotZero(v);
    u = fu;
    v = fv;
  }
  return (quantiseUnit(u) << 12) | quantiseUnit(v);
}

// The normal's direction before normalising (its L1 norm is 1): enough where
// only the direction counts (a plane's depth along a ray is a ratio), without
// the square root and divisions of decodeNormal().
inline Eigen::Vector3f decodeDirection(uint32_t code) {
  using namespace surfel_detail;
  float u = unquantiseUnit((code >> 12) & 0xfffu);
  float v = unquantiseUnit(code & 0xfffu);
  const float z = 1.0f - std::abs(u) - std::abs(v);
  if (z < 0.0f) {
    const float fu = (1.0f - std::abs(v)) * signNotZero(u);
    const float fv = (1.0f - std::abs(u)) * signNotZero(v);
    u = fu;
    v = fv;
  }
  return {u, v, z};
}

inline Eigen::Vector3f decodeNormal(uint32_t code) { return decodeDirection(code).normalized(); }  // unit length

inline constexpr float kMinRadiusM = 1e-4f;
inline constexpr float kMaxRadiusM = 0.1f;
// A radius in metres as a byte on a log scale over [kMinRadiusM, kMaxRadiusM]
// (clamped to it; NaN gives the smallest): the reference, with a logarithm.
uint8_t encodeRadiusRef(float radius_m);

// encodeRadiusRef() without the logarithm (it was 6 % of fusion's time, perf on
// map/fuse-simd): the radius's float bits pick one of 64 buckets an octave, whose
// lowest float's code is tabled; the next code's lowest radius is at most one
// step on (codes are 2.7 % apart, buckets at most 1.6 %). Both tables come from
// encodeRadiusRef() itself at start-up, so the codes are the same for every
// float (tests/unit/pipeline/test_surfel_map.cpp compares them).
struct RadiusCodeTables {
  static constexpr int kBucketShift = 17;  // 23 mantissa bits less 6: 64 buckets an octave
  uint32_t lowest_bits = 0;                // kMinRadiusM's float bits: bucket 0 starts there
  std::array<uint32_t, 1024> bucket_code{};  // the code of each bucket's lowest float (32 bits: gathered)
  std::array<float, 257> lowest_radius{};  // per code, the smallest radius that has it; [256]: infinity
};
RadiusCodeTables makeRadiusCodeTables();
extern const RadiusCodeTables kRadiusCodes;
inline uint8_t encodeRadius(float radius_m) {
  if (!(radius_m > kMinRadiusM)) return 0;
  if (radius_m >= kMaxRadiusM) return 255;
  const uint32_t bits = std::bit_cast<uint32_t>(radius_m);
  const uint32_t code = kRadiusCodes.bucket_code[(bits - kRadiusCodes.lowest_bits) >> RadiusCodeTables::kBucketShift];
  return static_cast<uint8_t>(code + (radius_m >= kRadiusCodes.lowest_radius[code + 1] ? 1u : 0u));
}
// decodeRadius's 256 values, made by surfel.cpp's static initialisation. Not an
// inline variable: that would run makeRadiusTable() in every program that includes
// this header, and a test binary without the pipeline library then fails to link.
// No static initialiser decodes a radius.
std::array<float, 256> makeRadiusTable();
extern const std::array<float, 256> kRadiusTable;
inline float decodeRadius(uint8_t code) { return kRadiusTable[code]; }

inline constexpr float kConfidenceScale = 256.0f;
inline uint16_t encodeConfidence(float c) {
  const float scaled = c * kConfidenceScale + 0.5f;
  return scaled >= 65535.0f ? uint16_t{65535} : scaled <= 0.0f ? uint16_t{0} : static_cast<uint16_t>(scaled);
}
inline float decodeConfidence(uint16_t code) { return static_cast<float>(code) / kConfidenceScale; }

inline Eigen::Vector3f surfelNormal(const Surfel& s) { return decodeNormal(s.normal_radius >> 8); }
inline Eigen::Vector3f surfelDirection(const Surfel& s) { return decodeDirection(s.normal_radius >> 8); }
inline float surfelRadius(const Surfel& s) { return decodeRadius(static_cast<uint8_t>(s.normal_radius & 0xffu)); }
inline void setNormalAndRadius(Surfel& s, const Eigen::Vector3f& unit_normal, float radius_m) {
  s.normal_radius = (encodeNormal(unit_normal) << 8) | encodeRadius(radius_m);
}

}  // namespace fovea::pipeline::map
