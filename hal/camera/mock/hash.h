// Small stateless integer hashes for the mock camera: procedural textures and
// sensor noise are pure functions of their inputs (no engines, no global state).
#pragma once

#include <cstdint>

namespace fovea::hal::mock {

// SplitMix64's finaliser (Steele, Lea, Flood 2014): a bijection on 64-bit words
// whose outputs pass BigCrush when fed a counter.
constexpr uint64_t mix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

constexpr uint64_t hash2(uint64_t a, uint64_t b) { return mix64(mix64(a) ^ b); }

// Uniform in [0, 1) from the top 53 bits.
constexpr double unitFromHash(uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

}  // namespace fovea::hal::mock
