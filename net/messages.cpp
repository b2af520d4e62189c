#include "net/messages.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "net/schema/control_generated.h"

namespace fovea::net {
namespace {

namespace fb = flatbuffers;

wire::Nonce128 toWire(const Nonce128& n) { return wire::Nonce128(n.lo, n.hi); }
Nonce128 fromWire(const wire::Nonce128* n) { return n ? Nonce128{n->lo(), n->hi()} : Nonce128{}; }
wire::Vec3d toWire(const Vec3& v) { return wire::Vec3d(v.x, v.y, v.z); }
Vec3 fromWire(const wire::Vec3d& v) { return Vec3{v.x(), v.y(), v.z()}; }

bool finite(double v) { return std::isfinite(v); }
bool finite(const Vec3& v) { return finite(v.x) && finite(v.y) && finite(v.z); }
bool finite(const Quat& q) { return finite(q.w) && finite(q.x) && finite(q.y) && finite(q.z); }
bool unit(const Vec3& v) { return std::fabs(std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z) - 1.0) <= kUnitTolerance; }
bool unit(const Quat& q) {
  return std::fabs(std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z) - 1.0) <= kUnitTolerance;
}

template <typename T>
const T* verified(std::span<const uint8_t> payload) {
  // An unaligned payload is the caller's bug (net/wire.h kPayloadAlignment), but
  // reading it would be undefined behaviour: drop it like a malformed one.
  if (payload.empty() || !isPayloadAligned(payload.data())) return nullptr;
  fb::Verifier verifier(payload.data(), payload.size(), /*max_depth=*/8, /*max_tables=*/16);
  if (!verifier.VerifyBuffer<T>(nullptr)) return nullptr;
  return fb::GetRoot<T>(payload.data());
}

// Strings must fit the text; otherwise the message is semantically wrong.
bool readText(const fb::String* s, std::size_t max_bytes, ShortText& out) {
  if (s == nullptr) {
    out.assign({});
    return true;
  }
  if (s->size() > max_bytes) return false;
  out.assign(s->string_view());
  return true;
}

}  // namespace

void ShortText::assign(std::string_view s) {
  size = s.size() < kCapacity ? s.size() : kCapacity;
  // An empty view may have a null data(), which memcpy must not get even for 0
  // bytes (an absent FlatBuffers string is one: fuzz_messages found it).
  if (size > 0) std::memcpy(chars.data(), s.data(), size);
  chars[size] = '\0';
}

const char* refuseReasonName(RefuseReason reason) {
  switch (reason) {
    case RefuseReason::kBusy: return "busy";
    case RefuseReason::kVersion: return "version";
    case RefuseReason::kBadRequest: return "bad-request";
  }
  return "unknown";
}

MessageEncoder::MessageEncoder() : builder_(kMaxPayloadBytes) {}

void MessageEncoder::begin() {
  builder_.Clear();
  // Every payload starts at a kPayloadAlignment boundary (net/wire.h), also those
  // whose largest scalar is smaller (Bye), so the decoders' check holds for them too.
  builder_.TrackMinAlign(kPayloadAlignment);
}

std::span<const uint8_t> MessageEncoder::finish() {
  return {builder_.GetBufferPointer(), builder_.GetSize()};
}

std::span<const uint8_t> MessageEncoder::encode(const HelloMsg& m) {
  begin();
  const auto name = builder_.CreateString(m.operator_name.view());
  const wire::Nonce128 nonce = toWire(m.client_nonce);
  builder_.Finish(wire::CreateHello(builder_, m.protocol_version, name, m.budget_bytes_per_s, m.mtu_bytes, &nonce));
  return finish();
}

std::span<const uint8_t> MessageEncoder::encode(const AcceptMsg& m) {
  begin();
  const wire::Nonce128 client = toWire(m.client_nonce);
  const wire::Nonce128 robot = toWire(m.robot_nonce);
  builder_.Finish(
      wire::CreateAccept(builder_, &client, &robot, m.mtu_bytes, m.budget_bytes_per_s, m.robot_stamp_ns));
  return finish();
}

std::span<const uint8_t> MessageEncoder::encode(const RefuseMsg& m) {
  begin();
  const auto text = builder_.CreateString(m.text.view());
  const wire::Nonce128 client = toWire(m.client_nonce);
  builder_.Finish(wire::CreateRefuse(builder_, &client, static_cast<wire::RefuseReason>(m.reason), text));
  return finish();
}

std::span<const uint8_t> MessageEncoder::encode(const ByeMsg& m) {
  begin();
  const auto reason = builder_.CreateString(m.reason.view());
  builder_.Finish(wire::CreateBye(builder_, reason));
  return finish();
}

std::span<const uint8_t> MessageEncoder::encode(const GazeSample& m) {
  begin();
  const wire::Vec3d origin = toWire(m.gaze_origin_m);
  const wire::Vec3d direction = toWire(m.gaze_direction);
  const wire::Vec3d hmd = toWire(m.hmd_position_m);
  const wire::Quatd q(m.hmd_orientation.w, m.hmd_orientation.x, m.hmd_orientation.y, m.hmd_orientation.z);
  const GazeFeedback& f = m.feedback;
  builder_.Finish(wire::CreateGaze(builder_, m.sequence, m.operator_stamp_ns, &origin, &direction, &hmd, &q,
                                   m.confidence, f.last_frame_id, f.datagrams_lost, f.bytes_received,
                                   f.echo_robot_stamp_ns, f.echo_delay_ns));
  return finish();
}

std::span<const uint8_t> MessageEncoder::encode(const StatusReport& m) {
  begin();
  const bool gaze = m.gaze_origin_m && m.gaze_direction;
  const wire::Vec3d origin = gaze ? toWire(*m.gaze_origin_m) : wire::Vec3d();
  const wire::Vec3d direction = gaze ? toWire(*m.gaze_direction) : wire::Vec3d();
  builder_.Finish(wire::CreateStatus(builder_, m.robot_stamp_ns, m.frames_captured, m.frames_sent,
                                     m.frames_dropped, m.chunks_cut, m.datagrams_sent, m.bytes_sent,
                                     m.datagrams_received, m.datagrams_dropped, m.gaze_age_ns, m.rtt_ns,
                                     m.latency_p50_ns, m.latency_p99_ns, gaze ? &origin : nullptr,
                                     gaze ? &direction : nullptr));
  return finish();
}

std::size_t BrickAckMsg::partsThatFit(std::size_t max_payload, std::size_t evicted) {
  // The table, its vtable and two vector lengths in 64 bytes, then the structs.
  constexpr std::size_t kFixed = 64, kPart = sizeof(wire::BrickPartAck), kKey = sizeof(wire::BrickKey);
  const std::size_t keys = std::min(evicted, kMaxEvicted) * kKey;
  if (max_payload < kFixed + keys) return 0;
  return std::min(kMaxParts, (max_payload - kFixed - keys) / kPart);
}

std::span<const uint8_t> MessageEncoder::encode(const BrickAckMsg& m) {
  begin();
  const std::size_t parts = std::min(m.part_count, BrickAckMsg::kMaxParts);
  const std::size_t evicted = std::min(m.evicted_count, BrickAckMsg::kMaxEvicted);
  wire::BrickKey* keys = nullptr;
  const auto evicted_vec = builder_.CreateUninitializedVectorOfStructs<wire::BrickKey>(evicted, &keys);
  for (std::size_t i = 0; i < evicted; ++i) keys[i] = wire::BrickKey(m.evicted[i].x, m.evicted[i].y, m.evicted[i].z);
  wire::BrickPartAck* acks = nullptr;
  const auto parts_vec = builder_.CreateUninitializedVectorOfStructs<wire::BrickPartAck>(parts, &acks);
  for (std::size_t i = 0; i < parts; ++i) {
    const BrickPartId& p = m.parts[i];
    acks[i] = wire::BrickPartAck(wire::BrickKey(p.key.x, p.key.y, p.key.z), p.version, p.part);
  }
  builder_.Finish(wire::CreateBrickAck(builder_, parts_vec, evicted_vec));
  return finish();
}

std::optional<DropReason> decode(std::span<const uint8_t> payload, HelloMsg& out) {
  const auto* m = verified<wire::Hello>(payload);
  if (m == nullptr) return DropReason::kVerify;
  if (m->client_nonce() == nullptr) return DropReason::kSemantic;
  if (!readText(m->operator_name(), kMaxOperatorNameBytes, out.operator_name)) return DropReason::kSemantic;
  out.protocol_version = m->protocol_version();
  out.budget_bytes_per_s = m->budget_bytes_per_s();
  out.mtu_bytes = m->mtu_bytes();
  out.client_nonce = fromWire(m->client_nonce());
  return std::nullopt;
}

std::optional<DropReason> decode(std::span<const uint8_t> payload, AcceptMsg& out) {
  const auto* m = verified<wire::Accept>(payload);
  if (m == nullptr) return DropReason::kVerify;
  if (m->client_nonce() == nullptr || m->robot_nonce() == nullptr) return DropReason::kSemantic;
  if (m->mtu_bytes() < kMinMtu || m->mtu_bytes() > kMaxMtu) return DropReason::kSemantic;
  out.client_nonce = fromWire(m->client_nonce());
  out.robot_nonce = fromWire(m->robot_nonce());
  out.mtu_bytes = m->mtu_bytes();
  out.budget_bytes_per_s = m->budget_bytes_per_s();
  out.robot_stamp_ns = m->robot_stamp_ns();
  return std::nullopt;
}

std::optional<DropReason> decode(std::span<const uint8_t> payload, RefuseMsg& out) {
  const auto* m = verified<wire::Refuse>(payload);
  if (m == nullptr) return DropReason::kVerify;
  if (m->client_nonce() == nullptr) return DropReason::kSemantic;
  if (static_cast<uint8_t>(m->reason()) > static_cast<uint8_t>(RefuseReason::kBadRequest)) {
    return DropReason::kSemantic;
  }
  if (!readText(m->text(), ShortText::kCapacity, out.text)) return DropReason::kSemantic;
  out.client_nonce = fromWire(m->client_nonce());
  out.reason = static_cast<RefuseReason>(m->reason());
  return std::nullopt;
}

std::optional<DropReason> decode(std::span<const uint8_t> payload, ByeMsg& out) {
  const auto* m = verified<wire::Bye>(payload);
  if (m == nullptr) return DropReason::kVerify;
  if (!readText(m->reason(), ShortText::kCapacity, out.reason)) return DropReason::kSemantic;
  return std::nullopt;
}

std::optional<DropReason> decode(std::span<const uint8_t> payload, GazeSample& out) {
  const auto* m = verified<wire::Gaze>(payload);
  if (m == nullptr) return DropReason::kVerify;
  if (!m->gaze_origin_m() || !m->gaze_direction() || !m->hmd_position_m() || !m->hmd_orientation()) {
    return DropReason::kSemantic;
  }
  GazeSample g;
  g.sequence = m->sequence();
  g.operator_stamp_ns = m->operator_stamp_ns();
  g.gaze_origin_m = fromWire(*m->gaze_origin_m());
  g.gaze_direction = fromWire(*m->gaze_direction());
  g.hmd_position_m = fromWire(*m->hmd_position_m());
  const wire::Quatd* q = m->hmd_orientation();
  g.hmd_orientation = Quat{q->w(), q->x(), q->y(), q->z()};
  g.confidence = m->confidence();
  g.feedback = GazeFeedback{m->last_frame_id(), m->datagrams_lost(), m->bytes_received(),
                            m->echo_robot_stamp_ns(), m->echo_delay_ns()};
  if (g.sequence == 0 || !finite(g.gaze_origin_m) || !finite(g.gaze_direction) || !finite(g.hmd_position_m) ||
      !finite(g.hmd_orientation) || !unit(g.gaze_direction) || !unit(g.hmd_orientation) ||
      !(g.confidence >= 0.0f && g.confidence <= 1.0f) || g.feedback.echo_delay_ns < 0) {
    return DropReason::kSemantic;
  }
  out = g;
  return std::nullopt;
}

std::optional<DropReason> decode(std::span<const uint8_t> payload, BrickAckMsg& out) {
  const auto* m = verified<wire::BrickAck>(payload);
  if (m == nullptr) return DropReason::kVerify;
  const auto* parts = m->parts();
  const auto* evicted = m->evicted();
  if ((parts && parts->size() > BrickAckMsg::kMaxParts) || (evicted && evicted->size() > BrickAckMsg::kMaxEvicted)) {
    return DropReason::kSemantic;
  }
  out.part_count = parts ? parts->size() : 0;
  for (std::size_t i = 0; i < out.part_count; ++i) {
    const wire::BrickPartAck* p = parts->Get(static_cast<flatbuffers::uoffset_t>(i));
    out.parts[i] = BrickPartId{{p->key().x(), p->key().y(), p->key().z()}, p->version(), p->part()};
  }
  out.evicted_count = evicted ? evicted->size() : 0;
  for (std::size_t i = 0; i < out.evicted_count; ++i) {
    const wire::BrickKey* k = evicted->Get(static_cast<flatbuffers::uoffset_t>(i));
    out.evicted[i] = BrickKey{k->x(), k->y(), k->z()};
  }
  return std::nullopt;
}

std::optional<DropReason> decode(std::span<const uint8_t> payload, StatusReport& out) {
  const auto* m = verified<wire::Status>(payload);
  if (m == nullptr) return DropReason::kVerify;
  out = StatusReport{m->robot_stamp_ns(),    m->frames_captured(), m->frames_sent(), m->frames_dropped(),
                     m->chunks_cut(),        m->datagrams_sent(),  m->bytes_sent(),  m->datagrams_received(),
                     m->datagrams_dropped(), m->gaze_age_ns(),     m->rtt_ns(),      m->latency_p50_ns(),
                     m->latency_p99_ns(),    std::nullopt,         std::nullopt};
  if (m->gaze_origin_m() != nullptr && m->gaze_direction() != nullptr) {
    const Vec3 origin = fromWire(*m->gaze_origin_m());
    const Vec3 direction = fromWire(*m->gaze_direction());
    if (!finite(origin) || !finite(direction) || !unit(direction)) return DropReason::kSemantic;
    out.gaze_origin_m = origin;
    out.gaze_direction = direction;
  }
  return std::nullopt;
}

}  // namespace fovea::net
