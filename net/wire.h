// The datagram frame every fovea message travels in (docs/protocol.md).
//
//   offset  size  field
//   0       2     magic "FV"
//   2       1     protocol version (kProtocolVersion)
//   3       1     message type (MessageType)
//   4       8     sender epoch: random, chosen by the sender per session
//   12      8     sequence number, little-endian, per sender, from 1
//   20      n     ciphertext of the payload (FlatBuffers, or a point chunk)
//   20+n    16    authentication tag
//
// The 20 header bytes are authenticated as associated data; the payload is
// encrypted and authenticated (XChaCha20-Poly1305, libsodium).
#pragma once

#include <cstddef>
#include <cstdint>

namespace fovea::net {

inline constexpr uint8_t kProtocolVersion = 2;  // 2: point chunks with a binary header (docs/protocol-chunks.md)

// a is newer than b in serial-number order (RFC 1982 style), so that 32-bit
// counters on the wire (frame ids, brick versions) may wrap.
inline bool serialNewer(uint32_t a, uint32_t b) { return static_cast<int32_t>(a - b) > 0; }

enum class MessageType : uint8_t {
  kHello = 1,         // operator -> robot: asks for a session
  kAccept = 2,        // robot -> operator
  kRefuse = 3,        // robot -> operator, with a reason
  kBye = 4,           // either way: ends the session
  kGaze = 5,          // operator -> robot, up to 200 Hz, with receiver feedback
  kChunk = 6,         // robot -> operator: one chunk of a foveated frame
  kFrameSummary = 7,  // robot -> operator: after each frame, chunks per region
  kStatus = 8,        // robot -> operator, once a second: counters
  kBrickChunk = 9,    // robot -> operator: one part of a map brick (a point chunk with a brick tag)
  kBrickAck = 10,    // operator -> robot: brick parts received, bricks dropped (net/messages.h)
};

inline constexpr std::size_t kHeaderBytes = 20;
inline constexpr std::size_t kTagBytes = 16;
// Bytes a datagram spends besides its payload.
inline constexpr std::size_t kDatagramOverhead = kHeaderBytes + kTagBytes;

// UDP payload sizes: the default keeps clear of fragmentation on any path
// (IPv6 guarantees 1280-byte packets); jumbo frames carry up to 9000-byte IP packets.
inline constexpr std::size_t kDefaultMtu = 1200;
inline constexpr std::size_t kMinMtu = 256;
inline constexpr std::size_t kMaxMtu = 8952;  // 9000 - IPv6 header (40) - UDP header (8)

// FlatBuffers reads a payload's scalars in place (flatbuffers/buffer.h casts the
// bytes to uoffset_t*, double*...), so a payload must start at an address aligned
// for its largest scalar (ulong, double: 8 bytes). The 20-byte header leaves a
// payload unaligned inside its datagram: payloads are decrypted into an aligned
// buffer (net/secure_channel.h PlainBuffer) and the decoders reject unaligned input
// (a point chunk, read byte by byte since protocol version 2, would not need it: its
// decoder keeps the one rule all the same).
inline constexpr std::size_t kPayloadAlignment = 8;
inline bool isPayloadAligned(const uint8_t* payload) {
  return reinterpret_cast<std::uintptr_t>(payload) % kPayloadAlignment == 0;
}

}  // namespace fovea::net
