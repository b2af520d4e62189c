// Fuzz target for a datagram's way into fovea (net/secure_channel.h): the
// header, the epoch and replay checks, authentication and decryption, then the
// message parsers, in the order RobotLink::handleDatagram and
// OperatorLink::handle call them, with a fixed pre-shared key and fixed
// session nonces, on both sides.
//
// A fuzzer cannot forge a Poly1305 tag, so bytes it makes never get past
// authentication. Byte 0 picks the mode:
//   even  the rest is one datagram, received by the robot and by the operator
//         (the seeds are valid sealed datagrams of every type: their mutations
//         test the header checks and authentication, which must drop them);
//   odd   the rest is a list of records, each sealed here with the right key
//         and then received, so the fuzzer reaches the replay window and the
//         parsers behind decryption. A record: type (1 byte, any value), flags
//         (1 byte: bit 0 wrong epoch, bit 1 the other side's key), sequence
//         number (2 bytes LE), payload length (2 bytes LE), payload.
// Oracles: what was sealed opens to the same bytes, once: a sequence number
// opened before is dropped as a replay (or too old).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "net/codec.h"
#include "net/messages.h"
#include "net/secure_channel.h"
#include "tests/fuzz/fuzz_target.h"

namespace {

using namespace fovea;
using namespace fovea::net;

constexpr uint64_t kRobotEpoch = 0x1122334455667788;
constexpr uint64_t kOperatorEpoch = 0x0102030405060708;

struct Side {
  Role role;
  DirectionKeys handshake;
  DirectionKeys session;
};

struct Fixture {
  Key psk;
  Side robot;
  Side op;
  Fixture() {
    initCrypto();
    for (std::size_t i = 0; i < psk.bytes.size(); ++i) psk.bytes[i] = static_cast<uint8_t>(7 * i + 1);
    const Nonce128 client{0x1111, 0x2222};
    const Nonce128 robot_nonce{0x3333, 0x4444};
    robot = {Role::kRobot, handshakeKeys(psk, Role::kRobot), sessionKeys(psk, Role::kRobot, client, robot_nonce)};
    op = {Role::kOperator, handshakeKeys(psk, Role::kOperator),
          sessionKeys(psk, Role::kOperator, client, robot_nonce)};
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

[[noreturn]] void fail(const char* what) {
  std::fprintf(stderr, "fuzz_secure_channel: %s\n", what);
  std::abort();
}

// The receiver's channel for one input: the peer's epoch, a fresh replay window.
struct Receiver {
  const Side* side;
  SessionChannel channel;
  PlainBuffer plain;  // aligned, as the links hold it
};

// Parses an authentic payload as the link would for its type.
void parsePayload(MessageType type, std::span<const uint8_t> payload) {
  // Copied: aligned as FlatBuffers needs, and ending where the payload ends (ASan).
  const std::vector<uint8_t> copy(payload.begin(), payload.end());
  switch (type) {
    case MessageType::kHello: { HelloMsg m; (void)decode(copy, m); break; }
    case MessageType::kAccept: { AcceptMsg m; (void)decode(copy, m); break; }
    case MessageType::kRefuse: { RefuseMsg m; (void)decode(copy, m); break; }
    case MessageType::kBye: { ByeMsg m; (void)decode(copy, m); break; }
    case MessageType::kGaze: { GazeSample m; (void)decode(copy, m); break; }
    case MessageType::kStatus: { StatusReport m; (void)decode(copy, m); break; }
    case MessageType::kBrickAck: { static BrickAckMsg m; (void)decode(copy, m); break; }
    case MessageType::kFrameSummary: (void)decodeSummary(copy); break;
    case MessageType::kChunk:
    case MessageType::kBrickChunk: {
      static pipeline::FoveatedCloud out(4096);
      out.clear();
      (void)decodeChunk(copy, out);
      break;
    }
  }
}

// The receive path of RobotLink::handleDatagram / OperatorLink::handle, minus
// sessions and sockets. Returns the payload's bytes when authentic.
std::optional<std::span<const uint8_t>> receive(Receiver& rx, std::span<const uint8_t> datagram) {
  Header header;
  if (parseHeader(datagram, header)) return std::nullopt;
  const Role peer = rx.side->role == Role::kRobot ? Role::kOperator : Role::kRobot;
  if (!isSentBy(header.type, peer)) return std::nullopt;  // kWrongDirection
  std::span<const uint8_t> payload;
  if (header.type == MessageType::kHello) {
    // A new session's Hello: any epoch, no window yet.
    if (header.seq == 0) return std::nullopt;
    auto opened = openSealed(rx.side->handshake.rx, datagram, rx.plain);
    if (!opened) return std::nullopt;
    payload = *opened;
  } else {
    const Key* key = usesHandshakeKey(header.type) ? &rx.side->handshake.rx : nullptr;
    if (rx.channel.open(header, datagram, rx.plain, payload, key)) return std::nullopt;
  }
  parsePayload(header.type, payload);
  return payload;
}

Receiver robotReceiver() {
  const Fixture& f = fixture();
  return {&f.robot, SessionChannel(f.robot.session, kRobotEpoch, kOperatorEpoch), {}};
}
Receiver operatorReceiver() {
  const Fixture& f = fixture();
  return {&f.op, SessionChannel(f.op.session, kOperatorEpoch, kRobotEpoch), {}};
}

void receiveRaw(std::span<const uint8_t> datagram) {
  // Exactly the datagram's bytes on the heap, so reads past it are caught.
  const std::vector<uint8_t> copy(datagram.begin(), datagram.end());
  Receiver robot = robotReceiver();
  Receiver op = operatorReceiver();
  (void)receive(robot, copy);
  (void)receive(op, copy);
}

uint16_t le16(const uint8_t* p) { return static_cast<uint16_t>(p[0] | p[1] << 8); }

void receiveSealed(std::span<const uint8_t> records) {
  const Fixture& f = fixture();
  Receiver robot = robotReceiver();
  Receiver op = operatorReceiver();
  std::vector<uint16_t> opened_by_robot, opened_by_operator;
  std::vector<uint8_t> out(kMaxMtu);
  std::size_t pos = 0;
  while (pos + 6 <= records.size()) {
    const uint8_t type_byte = records[pos];
    const uint8_t flags = records[pos + 1];
    const uint16_t seq = le16(&records[pos + 2]);
    const std::size_t len = std::min<std::size_t>(le16(&records[pos + 4]), records.size() - pos - 6);
    const std::span<const uint8_t> payload = records.subspan(pos + 6, len);
    pos += 6 + len;
    if (!isKnownType(type_byte)) continue;
    const auto type = static_cast<MessageType>(type_byte);
    // Sealed by the side that sends this type, for the other side.
    const bool from_robot = isSentBy(type, Role::kRobot);
    const Side& sender = from_robot ? f.robot : f.op;
    Receiver& rx = from_robot ? op : robot;
    const bool other_key = flags & 2;
    const Side& key_side = other_key ? (from_robot ? f.op : f.robot) : sender;
    const Key& key = usesHandshakeKey(type) ? key_side.handshake.tx : key_side.session.tx;
    uint64_t epoch = from_robot ? kRobotEpoch : kOperatorEpoch;
    if (flags & 1) epoch ^= 1;
    const std::span<const uint8_t> datagram = seal(key, Header{type, epoch, seq}, payload, out);
    if (datagram.empty()) continue;  // too long for a datagram
    const std::vector<uint8_t> copy(datagram.begin(), datagram.end());
    const auto opened = receive(rx, copy);
    // A Hello opens in any epoch (it starts a session); the others only in the peer's.
    const bool authentic = !(flags & 2) && (type == MessageType::kHello || !(flags & 1)) && seq != 0;
    if (!opened) {
      // Only a replay (Hello has no window) or a sequence number below the window may fail.
      std::vector<uint16_t>& seen = from_robot ? opened_by_operator : opened_by_robot;
      const bool replay = std::find(seen.begin(), seen.end(), seq) != seen.end();
      const uint16_t highest = seen.empty() ? 0 : *std::max_element(seen.begin(), seen.end());
      const bool too_old = highest >= ReplayWindow::kWindow && seq <= highest - ReplayWindow::kWindow;
      if (authentic && !replay && !too_old) fail("an authentic datagram with a fresh sequence number was dropped");
      continue;
    }
    if (!authentic) fail("a datagram sealed with the wrong key, epoch or sequence number 0 was accepted");
    if (opened->size() != payload.size() || !std::equal(payload.begin(), payload.end(), opened->begin())) {
      fail("the opened payload differs from the sealed one");
    }
    if (type != MessageType::kHello) {
      std::vector<uint16_t>& seen = from_robot ? opened_by_operator : opened_by_robot;
      if (std::find(seen.begin(), seen.end(), seq) != seen.end()) fail("a replayed datagram was accepted");
      seen.push_back(seq);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::span<const uint8_t> rest(data + 1, size - 1);
  if (data[0] & 1) {
    receiveSealed(rest);
  } else {
    receiveRaw(rest);
  }
  return 0;
}

// Valid datagrams of every type (raw mode) and the same messages as records
// (sealed mode).
std::vector<fuzz::Input> fuzz::seeds() {
  const Fixture& f = fixture();
  MessageEncoder enc;
  struct Message {
    MessageType type;
    std::vector<uint8_t> payload;
  };
  std::vector<Message> messages;
  const auto add = [&](MessageType type, std::span<const uint8_t> p) { messages.push_back({type, {p.begin(), p.end()}}); };
  HelloMsg hello;
  hello.operator_name.assign("fuzz");
  hello.client_nonce = {0x1111, 0x2222};
  add(MessageType::kHello, enc.encode(hello));
  AcceptMsg accept;
  accept.client_nonce = {0x1111, 0x2222};
  accept.robot_nonce = {0x3333, 0x4444};
  accept.robot_stamp_ns = 123456789;
  add(MessageType::kAccept, enc.encode(accept));
  RefuseMsg refuse;
  refuse.reason = RefuseReason::kBusy;
  refuse.text.assign("busy: serving another operator");
  add(MessageType::kRefuse, enc.encode(refuse));
  ByeMsg bye;
  bye.reason.assign("done");
  add(MessageType::kBye, enc.encode(bye));
  GazeSample gaze;
  gaze.sequence = 3;
  gaze.operator_stamp_ns = 42;
  gaze.confidence = 0.5f;
  add(MessageType::kGaze, enc.encode(gaze));
  StatusReport status;
  status.frames_captured = 10;
  add(MessageType::kStatus, enc.encode(status));
  const std::vector<uint8_t> junk = {1, 2, 3, 4, 5, 6, 7, 8};
  add(MessageType::kChunk, junk);

  std::vector<Input> seeds;
  std::vector<uint8_t> out(kMaxMtu);
  Input records{1};
  uint16_t seq = 1;
  for (const Message& m : messages) {
    const bool from_robot = isSentBy(m.type, Role::kRobot);
    const Side& sender = from_robot ? f.robot : f.op;
    const Key& key = usesHandshakeKey(m.type) ? sender.handshake.tx : sender.session.tx;
    const auto d = seal(key, Header{m.type, from_robot ? kRobotEpoch : kOperatorEpoch, seq}, m.payload, out);
    Input raw{0};
    raw.insert(raw.end(), d.begin(), d.end());
    seeds.push_back(std::move(raw));
    records.insert(records.end(), {static_cast<uint8_t>(m.type), 0, static_cast<uint8_t>(seq), 0,
                                   static_cast<uint8_t>(m.payload.size() & 0xff),
                                   static_cast<uint8_t>(m.payload.size() >> 8)});
    records.insert(records.end(), m.payload.begin(), m.payload.end());
    ++seq;
  }
  seeds.push_back(records);
  return seeds;
}
