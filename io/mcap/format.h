// The MCAP v0 container format (https://mcap.dev/spec): the constants and the
// little-endian helpers the Writer and the Reader share, and CRC-32 (the
// IEEE/zlib polynomial the spec names, reflected, 0xEDB88320).
//
// A file: magic, Header, the data section (Schema, Channel, Chunk records, each
// chunk followed by one MessageIndex per channel it holds), DataEnd, the summary
// section (Schema, Channel, ChunkIndex, Statistics), the summary offset section
// (one SummaryOffset per group of the summary), Footer, magic. Every record is
// opcode (u8), length (u64), content; strings are u32 length + bytes, byte
// arrays and maps carry a u32 (u64 for a chunk's records) length in bytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string_view>

namespace fovea::mcap {

inline constexpr uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

enum Opcode : uint8_t {
  kOpHeader = 0x01,
  kOpFooter = 0x02,
  kOpSchema = 0x03,
  kOpChannel = 0x04,
  kOpMessage = 0x05,
  kOpChunk = 0x06,
  kOpMessageIndex = 0x07,
  kOpChunkIndex = 0x08,
  kOpAttachment = 0x09,
  kOpAttachmentIndex = 0x0A,
  kOpStatistics = 0x0B,
  kOpMetadata = 0x0C,
  kOpMetadataIndex = 0x0D,
  kOpSummaryOffset = 0x0E,
  kOpDataEnd = 0x0F,
};

// opcode + length.
inline constexpr std::size_t kRecordPrefixBytes = 9;
// Message record content before its data: channel id, sequence, log and publish time.
inline constexpr std::size_t kMessageHeaderBytes = 2 + 4 + 8 + 8;

// CRC-32 as zlib's crc32(): crc32Update(0, bytes) of "123456789" is 0xCBF43926.
// Chain calls by passing the previous result.
uint32_t crc32Update(uint32_t crc, std::span<const uint8_t> bytes);

inline void storeLe16(uint8_t* p, uint16_t v) {
  p[0] = static_cast<uint8_t>(v);
  p[1] = static_cast<uint8_t>(v >> 8);
}
inline void storeLe32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
inline void storeLe64(uint8_t* p, uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
inline uint16_t loadLe16(const uint8_t* p) { return static_cast<uint16_t>(p[0] | (p[1] << 8)); }
inline uint32_t loadLe32(const uint8_t* p) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
inline uint64_t loadLe64(const uint8_t* p) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

}  // namespace fovea::mcap
