// The datagram frame of net/wire.h, sealed and opened (docs/protocol.md).
//
// The core does no socket I/O and keeps no clock: RobotLink and OperatorLink feed
// it datagrams. Payloads are encrypted and authenticated with
// XChaCha20-Poly1305-IETF; the 20 header bytes are the associated data; the
// 24-byte nonce is epoch (8, LE) | sequence number (8, LE) | 8 zero bytes.
//
// Keys (all 32 bytes, derived from the pre-shared key with libsodium's keyed
// BLAKE2b), one per direction so the two directions never share a (key, nonce):
//   handshake keys  Hello (operator->robot), Accept and Refuse (robot->operator)
//   session keys    everything else; derived from the PSK and both the operator's
//                   and the robot's random nonces of Hello/Accept, so datagrams
//                   recorded in one session never authenticate in another.
//
// Every datagram that fails a check is dropped and counted under a DropReason,
// never parsed further.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

#include "net/key.h"
#include "net/replay_window.h"
#include "net/wire.h"

namespace fovea::net {

// Calls sodium_init() once (thread-safe); aborts if libsodium cannot start.
void initCrypto();

enum class Role : uint8_t { kRobot, kOperator };

// Who sends a message type; a datagram of the receiver's own types is a
// reflection (or a confused peer) and is dropped as kWrongDirection.
bool isSentBy(MessageType type, Role role);
// Hello, Accept and Refuse travel under the handshake keys.
bool usesHandshakeKey(MessageType type);
bool isKnownType(uint8_t type);
const char* messageTypeName(MessageType type);

enum class DropReason : uint8_t {
  kTooShort,        // shorter than header + tag
  kTooLong,         // longer than kMaxMtu (or the session MTU)
  kBadMagic,
  kBadVersion,
  kBadType,         // unknown message type
  kWrongDirection,  // a type this side sends itself (e.g. a reflected datagram)
  kNoSession,       // a session message with no session, or from another address or epoch
  kReplay,          // sequence number already seen
  kTooOld,          // sequence number below the replay window (or 0)
  kAuth,            // authentication failed: wrong key, tampered, truncated
  kVerify,          // FlatBuffers verification failed
  kSemantic,        // well-formed but meaningless (NaN, non-unit direction, echo mismatch...)
};
inline constexpr std::size_t kDropReasonCount = 12;
const char* dropReasonName(DropReason reason);

struct DropCounters {
  std::array<uint64_t, kDropReasonCount> by_reason{};
  void add(DropReason r) { ++by_reason[static_cast<std::size_t>(r)]; }
  void add(const DropCounters& other) {
    for (std::size_t i = 0; i < kDropReasonCount; ++i) by_reason[i] += other.by_reason[i];
  }
  uint64_t operator[](DropReason r) const { return by_reason[static_cast<std::size_t>(r)]; }
  uint64_t total() const;
};

struct Header {
  MessageType type = MessageType::kHello;
  uint64_t epoch = 0;
  uint64_t seq = 0;
};

// Largest plaintext a datagram can carry.
inline constexpr std::size_t kMaxPayloadBytes = kMaxMtu - kDatagramOverhead;

// Where a datagram's payload is decrypted to, for every message kind: aligned so
// that the FlatBuffers parsers read it in place (net/wire.h kPayloadAlignment).
// A type rather than a span so an unaligned plaintext buffer cannot be passed.
struct alignas(kPayloadAlignment) PlainBuffer {
  std::array<uint8_t, kMaxPayloadBytes> bytes{};
};

// Checks size, magic, version and type; reads epoch and sequence number.
// Does not authenticate anything.
std::optional<DropReason> parseHeader(std::span<const uint8_t> datagram, Header& header);

// Writes the datagram for (type, epoch, seq, payload) into out; returns its
// bytes, or an empty span when out is too small or the datagram would exceed kMaxMtu.
std::span<const uint8_t> seal(const Key& key, const Header& header, std::span<const uint8_t> payload,
                              std::span<uint8_t> out);

// Authenticates and decrypts a datagram whose header parseHeader() accepted into
// plain; returns the payload (aligned, at plain's start) or nullopt when
// authentication fails or the datagram is longer than kMaxMtu.
std::optional<std::span<const uint8_t>> openSealed(const Key& key, std::span<const uint8_t> datagram,
                                                   PlainBuffer& plain);

// 128-bit random nonces of Hello and Accept.
struct Nonce128 {
  uint64_t lo = 0;
  uint64_t hi = 0;
  bool operator==(const Nonce128&) const = default;
};
Nonce128 randomNonce128();
uint64_t randomU64();

// Per-direction keys for one side.
struct DirectionKeys {
  Key tx;
  Key rx;
};
DirectionKeys handshakeKeys(const Key& psk, Role self);
DirectionKeys sessionKeys(const Key& psk, Role self, const Nonce128& client_nonce, const Nonce128& robot_nonce);

// One side's half of an established session: seals with its own epoch and
// sequence numbers, opens the peer's datagrams of one epoch through a replay window.
class SessionChannel {
 public:
  SessionChannel() = default;
  SessionChannel(const DirectionKeys& keys, uint64_t tx_epoch, uint64_t rx_epoch)
      : keys_(keys), tx_epoch_(tx_epoch), rx_epoch_(rx_epoch) {}

  // Seals with the session key, or with the handshake key given (Accept goes out
  // in the robot's session epoch so the sequence numbers stay one series).
  std::span<const uint8_t> seal(MessageType type, std::span<const uint8_t> payload, std::span<uint8_t> out,
                                const Key* key_override = nullptr);

  // Replay check, authentication, window update. header from parseHeader().
  // On success the payload lies in plain.
  std::optional<DropReason> open(const Header& header, std::span<const uint8_t> datagram, PlainBuffer& plain,
                                 std::span<const uint8_t>& payload,
                                 const Key* key_override = nullptr);

  // New keys and peer epoch (the operator on Accept); the own sequence series goes on.
  void rekey(const DirectionKeys& keys, uint64_t rx_epoch) {
    keys_ = keys;
    rx_epoch_ = rx_epoch;
    window_.reset();
  }

  uint64_t txEpoch() const { return tx_epoch_; }
  uint64_t rxEpoch() const { return rx_epoch_; }
  uint64_t lastTxSeq() const { return tx_seq_; }
  ReplayWindow& window() { return window_; }

 private:
  DirectionKeys keys_;
  uint64_t tx_epoch_ = 0;
  uint64_t tx_seq_ = 0;
  uint64_t rx_epoch_ = 0;
  ReplayWindow window_;
};

}  // namespace fovea::net
