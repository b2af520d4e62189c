// The surfel pool's links: per slot the next and previous slot of its brick's
// list (a free slot's next is the next free one), 24 bits each, 6 bytes a slot.
// With 32-bit links they took 8 bytes, and the pool 40 a surfel of capacity: the
// 2 saved are what brings the map under issue 41's 40 bytes a surfel once the
// brick tables and the operator's brick records are counted (docs/map.md). The
// price is the pool's largest size, kMaxSlots (16.7 M surfels, 608 MiB of pool:
// far beyond the boards fovea runs on). Little-endian bytes by shifts, so the
// same on every target; kNoSlot is stored as the one 24-bit value no slot has.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace fovea::pipeline::map {

class SurfelLinks {
 public:
  static constexpr uint32_t kNoSlot = 0xffffffffu;
  static constexpr uint32_t kMaxSlots = (1u << 24) - 1;  // slots 0 .. kMaxSlots - 1; 0xffffff is kNoSlot

  void resize(std::size_t slots) { bytes_.resize(slots * kBytesPerSlot); }
  std::size_t memoryBytes() const { return bytes_.capacity(); }

  uint32_t next(uint32_t slot) const { return load(slot * kBytesPerSlot); }
  uint32_t prev(uint32_t slot) const { return load(slot * kBytesPerSlot + 3); }
  void setNext(uint32_t slot, uint32_t to) { store(slot * kBytesPerSlot, to); }
  void setPrev(uint32_t slot, uint32_t to) { store(slot * kBytesPerSlot + 3, to); }

 private:
  static constexpr std::size_t kBytesPerSlot = 6;
  static constexpr uint32_t kStoredNone = 0xffffffu;

  uint32_t load(std::size_t at) const {
    const uint8_t* b = bytes_.data() + at;
    const uint32_t v = uint32_t{b[0]} | uint32_t{b[1]} << 8 | uint32_t{b[2]} << 16;
    return v == kStoredNone ? kNoSlot : v;
  }
  void store(std::size_t at, uint32_t to) {
    const uint32_t v = to == kNoSlot ? kStoredNone : to;
    uint8_t* b = bytes_.data() + at;
    b[0] = static_cast<uint8_t>(v);
    b[1] = static_cast<uint8_t>(v >> 8);
    b[2] = static_cast<uint8_t>(v >> 16);
  }

  std::vector<uint8_t> bytes_;
};

}  // namespace fovea::pipeline::map
