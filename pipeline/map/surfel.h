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

#include <cstdint>

#include <Eigen/Core>

namespace fovea::pipeline::map {

struct Surfel {
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

inline constexpr uint8_t kSurfelLive = 1;
inline constexpr uint8_t kSurfelStable = 2;
// Stable and in the map for SurfelMapConfig::settle_frames: the map's content
// for the operator (what the eye view and the stream of changes send, what
// explains a pixel).
inline constexpr uint8_t kSurfelSettled = 4;

// A unit normal as 24 bits: octahedral projection, 12 bits each for u and v.
uint32_t encodeNormal(const Eigen::Vector3f& unit_normal);
Eigen::Vector3f decodeNormal(uint32_t code);  // unit length

inline constexpr float kMinRadiusM = 1e-4f;
inline constexpr float kMaxRadiusM = 0.1f;
// A radius in metres as a byte on a log scale over [kMinRadiusM, kMaxRadiusM]
// (clamped to it; NaN gives the smallest).
uint8_t encodeRadius(float radius_m);
float decodeRadius(uint8_t code);

inline constexpr float kConfidenceScale = 256.0f;
inline uint16_t encodeConfidence(float c) {
  const float scaled = c * kConfidenceScale + 0.5f;
  return scaled >= 65535.0f ? uint16_t{65535} : scaled <= 0.0f ? uint16_t{0} : static_cast<uint16_t>(scaled);
}
inline float decodeConfidence(uint16_t code) { return static_cast<float>(code) / kConfidenceScale; }

inline Eigen::Vector3f surfelNormal(const Surfel& s) { return decodeNormal(s.normal_radius >> 8); }
inline float surfelRadius(const Surfel& s) { return decodeRadius(static_cast<uint8_t>(s.normal_radius & 0xffu)); }
inline void setNormalAndRadius(Surfel& s, const Eigen::Vector3f& unit_normal, float radius_m) {
  s.normal_radius = (encodeNormal(unit_normal) << 8) | encodeRadius(radius_m);
}

}  // namespace fovea::pipeline::map
