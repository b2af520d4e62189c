// Session, gaze and status messages (net/schema/control.fbs) as plain structs,
// and their FlatBuffers encoding. Decoding verifies the buffer and checks the
// values (finite, unit direction...); a message that fails returns a DropReason.
// No heap allocation: names and texts are fixed-size, the encoder reuses one
// builder buffer.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

#include <flatbuffers/flatbuffers.h>

#include "core/grid_table.h"
#include "net/secure_channel.h"

namespace fovea::net {

// A short text with a fixed capacity (operator names, refusal reasons).
struct ShortText {
  static constexpr std::size_t kCapacity = 95;
  std::array<char, kCapacity + 1> chars{};
  std::size_t size = 0;

  ShortText() = default;
  ShortText(std::string_view s) { assign(s); }  // NOLINT: implicit by design
  void assign(std::string_view s);              // truncates to kCapacity
  std::string_view view() const { return {chars.data(), size}; }
};

inline constexpr std::size_t kMaxOperatorNameBytes = 63;

struct HelloMsg {
  uint8_t protocol_version = kProtocolVersion;
  ShortText operator_name;        // at most kMaxOperatorNameBytes
  uint64_t budget_bytes_per_s = 0;  // 0: whatever the robot allows
  uint32_t mtu_bytes = kDefaultMtu;
  Nonce128 client_nonce;
};

struct AcceptMsg {
  Nonce128 client_nonce;
  Nonce128 robot_nonce;
  uint32_t mtu_bytes = kDefaultMtu;
  uint64_t budget_bytes_per_s = 0;
  int64_t robot_stamp_ns = 0;
};

enum class RefuseReason : uint8_t { kBusy = 0, kVersion = 1, kBadRequest = 2 };
const char* refuseReasonName(RefuseReason reason);

struct RefuseMsg {
  Nonce128 client_nonce;
  RefuseReason reason = RefuseReason::kBusy;
  ShortText text;
};

struct ByeMsg {
  ShortText reason;
};

struct Vec3 {
  double x = 0, y = 0, z = 0;
};
struct Quat {
  double w = 1, x = 0, y = 0, z = 0;
};

// What the operator's receiver reports back in every gaze datagram.
struct GazeFeedback {
  uint64_t last_frame_id = 0;
  uint64_t datagrams_lost = 0;
  uint64_t bytes_received = 0;
  int64_t echo_robot_stamp_ns = 0;  // newest robot timestamp received (0: none)
  int64_t echo_delay_ns = 0;        // operator's time between receiving it and sending this
};

struct GazeSample {
  uint64_t sequence = 0;  // from 1; the robot keeps the highest
  int64_t operator_stamp_ns = 0;
  Vec3 gaze_origin_m;
  Vec3 gaze_direction{0, 0, 1};  // unit length (|d| - 1 within kUnitTolerance)
  Vec3 hmd_position_m;
  Quat hmd_orientation;          // unit length
  float confidence = 1.0f;       // [0, 1]
  GazeFeedback feedback;
};

// Tolerance on the length of unit vectors and quaternions.
inline constexpr double kUnitTolerance = 1e-3;

// Robot counters sent about once a second (values -1: not measured yet).
struct StatusReport {
  int64_t robot_stamp_ns = 0;
  uint64_t frames_captured = 0;
  uint64_t frames_sent = 0;
  uint64_t frames_dropped = 0;
  uint64_t chunks_cut = 0;
  uint64_t datagrams_sent = 0;
  uint64_t bytes_sent = 0;
  uint64_t datagrams_received = 0;
  uint64_t datagrams_dropped = 0;
  int64_t gaze_age_ns = -1;
  int64_t rtt_ns = -1;
  int64_t latency_p50_ns = -1;
  int64_t latency_p99_ns = -1;
  // The newest operator gaze the robot holds (one with an eye: confidence > 0).
  std::optional<Vec3> gaze_origin_m;
  std::optional<Vec3> gaze_direction;
};

// A map brick's grid key (pipeline/map/surfel_map.h: origin = key * brick size).
using BrickKey = GridKey;

// One part of a brick version (net/brick_cache.h, net/brick_sender.h).
struct BrickPartId {
  BrickKey key;
  uint32_t version = 0;
  uint16_t part = 0;
  bool operator==(const BrickPartId&) const = default;
};

// The operator's acknowledgement of brick parts, and the bricks it evicted.
struct BrickAckMsg {
  static constexpr std::size_t kMaxParts = 400;   // 20 bytes each: fits the largest MTU
  static constexpr std::size_t kMaxEvicted = 32;  // 12 bytes each
  std::array<BrickPartId, kMaxParts> parts{};
  std::size_t part_count = 0;
  std::array<BrickKey, kMaxEvicted> evicted{};
  std::size_t evicted_count = 0;
  // How many parts fit a payload of max_payload bytes beside `evicted` keys.
  static std::size_t partsThatFit(std::size_t max_payload, std::size_t evicted);
};

// Encodes messages into a builder whose buffer is reserved once (kMaxPayloadBytes).
// The returned span stays valid until the next encode.
class MessageEncoder {
 public:
  MessageEncoder();
  std::span<const uint8_t> encode(const HelloMsg& m);
  std::span<const uint8_t> encode(const AcceptMsg& m);
  std::span<const uint8_t> encode(const RefuseMsg& m);
  std::span<const uint8_t> encode(const ByeMsg& m);
  std::span<const uint8_t> encode(const GazeSample& m);
  std::span<const uint8_t> encode(const StatusReport& m);
  std::span<const uint8_t> encode(const BrickAckMsg& m);

 private:
  void begin();
  std::span<const uint8_t> finish();
  flatbuffers::FlatBufferBuilder builder_;
};

// Verify the FlatBuffers payload (kVerify) and its values (kSemantic). The
// payload must start at a kPayloadAlignment boundary (net/wire.h), else kVerify.
std::optional<DropReason> decode(std::span<const uint8_t> payload, HelloMsg& out);
std::optional<DropReason> decode(std::span<const uint8_t> payload, AcceptMsg& out);
std::optional<DropReason> decode(std::span<const uint8_t> payload, RefuseMsg& out);
std::optional<DropReason> decode(std::span<const uint8_t> payload, ByeMsg& out);
std::optional<DropReason> decode(std::span<const uint8_t> payload, GazeSample& out);
std::optional<DropReason> decode(std::span<const uint8_t> payload, StatusReport& out);
// kSemantic for more parts or evicted keys than BrickAckMsg holds.
std::optional<DropReason> decode(std::span<const uint8_t> payload, BrickAckMsg& out);

}  // namespace fovea::net
