// Fuzz target for the control messages (net/messages.h, BrickAck included) and the frame summary
// (net/codec.h): byte 0 picks the parser, the rest is its payload, as it lies
// in a link's buffer after decryption. Oracle: a message that decodes encodes
// to bytes that decode again and re-encode to the same bytes.
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "net/codec.h"
#include "net/messages.h"
#include "tests/fuzz/fuzz_target.h"

namespace {

using namespace fovea;
using namespace fovea::net;

constexpr int kParsers = 8;

[[noreturn]] void fail(const char* what) {
  std::fprintf(stderr, "fuzz_messages: %s\n", what);
  std::abort();
}

MessageEncoder& encoder() {
  static MessageEncoder enc;
  return enc;
}

template <typename Msg>
void roundTrip(std::span<const uint8_t> payload) {
  static Msg m;  // static: BrickAckMsg is 8 KB
  m = Msg{};
  if (decode(payload, m)) return;
  const std::span<const uint8_t> bytes = encoder().encode(m);
  const std::vector<uint8_t> first(bytes.begin(), bytes.end());
  static Msg again;
  again = Msg{};
  if (decode(first, again)) fail("a decoded message, encoded again, does not decode");
  const std::span<const uint8_t> second = encoder().encode(again);
  if (!std::equal(first.begin(), first.end(), second.begin(), second.end())) {
    fail("a decoded message does not survive encode, decode, encode");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  // The payload alone on the heap: aligned as the links' receive buffers are
  // (FlatBuffers reads in place), and ASan sees any read past its end.
  const std::vector<uint8_t> payload(data + 1, data + size);
  switch (data[0] % kParsers) {
    case 0: roundTrip<HelloMsg>(payload); break;
    case 1: roundTrip<AcceptMsg>(payload); break;
    case 2: roundTrip<RefuseMsg>(payload); break;
    case 3: roundTrip<ByeMsg>(payload); break;
    case 4: roundTrip<GazeSample>(payload); break;
    case 5: roundTrip<StatusReport>(payload); break;
    case 6: roundTrip<BrickAckMsg>(payload); break;
    default: (void)decodeSummary(payload); break;
  }
  return 0;
}

// One valid message of each kind, behind its parser's byte.
std::vector<fuzz::Input> fuzz::seeds() {
  MessageEncoder enc;
  std::vector<Input> seeds;
  const auto add = [&](uint8_t parser, std::span<const uint8_t> p) {
    Input in{parser};
    in.insert(in.end(), p.begin(), p.end());
    seeds.push_back(std::move(in));
  };
  HelloMsg hello;
  hello.operator_name.assign("operator-1");
  hello.budget_bytes_per_s = 1'000'000;
  hello.client_nonce = {1, 2};
  add(0, enc.encode(hello));
  AcceptMsg accept;
  accept.client_nonce = {1, 2};
  accept.robot_nonce = {3, 4};
  accept.robot_stamp_ns = 5'000'000'000;
  add(1, enc.encode(accept));
  RefuseMsg refuse;
  refuse.reason = RefuseReason::kVersion;
  refuse.text.assign("version: robot speaks protocol 1");
  add(2, enc.encode(refuse));
  ByeMsg bye;
  bye.reason.assign("timeout");
  add(3, enc.encode(bye));
  GazeSample gaze;
  gaze.sequence = 17;
  gaze.operator_stamp_ns = 1'000;
  gaze.gaze_direction = {0.6, 0.0, 0.8};
  gaze.hmd_orientation = {0.0, 1.0, 0.0, 0.0};
  gaze.confidence = 0.9f;
  gaze.feedback = {5, 1, 12345, 999, 10};
  add(4, enc.encode(gaze));
  StatusReport status;
  status.frames_sent = 100;
  status.rtt_ns = 2'000'000;
  add(5, enc.encode(status));
  static BrickAckMsg ack;  // 8 KB: not on the stack
  ack.part_count = 2;
  ack.parts[0] = {{1, -2, 3}, 7, 0};
  ack.parts[1] = {{1, -2, 3}, 7, 4};
  ack.evicted_count = 1;
  ack.evicted[0] = {-5, 0, 9};
  add(6, enc.encode(ack));
  auto chunk_encoder = ChunkEncoder::create(CodecConfig{}, 16);
  if (chunk_encoder.isOk()) {
    const uint16_t sent[] = {3, 2, 1};
    const uint16_t cut[] = {0, 1, 0};
    add(7, chunk_encoder.value().encodeSummary(9, sent, cut));
  }
  return seeds;
}
