// Framing, keys, drop reasons and message verification (docs/protocol.md).
#include "net/secure_channel.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <set>
#include <vector>

#include "net/key.h"
#include "net/messages.h"
#include "net/schema/control_generated.h"

namespace fovea::net {
namespace {

std::vector<uint8_t> bytes(std::size_t n, uint8_t seed) {
  std::vector<uint8_t> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<uint8_t>(seed + i * 7);
  return v;
}

// A robot channel and the matching operator channel of one session.
struct Pair {
  Key psk = generateKey();
  Nonce128 client = randomNonce128();
  Nonce128 robot_nonce = randomNonce128();
  uint64_t robot_epoch = randomU64();
  uint64_t operator_epoch = randomU64();
  SessionChannel robot{sessionKeys(psk, Role::kRobot, client, robot_nonce), robot_epoch, operator_epoch};
  SessionChannel op{sessionKeys(psk, Role::kOperator, client, robot_nonce), operator_epoch, robot_epoch};
  std::array<uint8_t, kMaxMtu> out{};
  PlainBuffer plain;

  // Opens at the operator; returns the drop reason or nullopt.
  std::optional<DropReason> openAtOperator(std::span<const uint8_t> d, std::span<const uint8_t>* payload = nullptr) {
    Header h;
    if (auto r = parseHeader(d, h)) return r;
    std::span<const uint8_t> p;
    auto r = op.open(h, d, plain, p);
    if (payload) *payload = p;
    return r;
  }
  std::vector<uint8_t> sealChunk(std::span<const uint8_t> payload) {
    auto d = robot.seal(MessageType::kChunk, payload, out);
    return {d.begin(), d.end()};
  }
};

TEST(SecureChannel, RoundTrip) {
  Pair p;
  const auto payload = bytes(500, 3);
  const auto d = p.sealChunk(payload);
  ASSERT_EQ(d.size(), payload.size() + kDatagramOverhead);
  EXPECT_EQ(d[0], 'F');
  EXPECT_EQ(d[1], 'V');
  EXPECT_EQ(d[2], kProtocolVersion);
  EXPECT_EQ(d[3], static_cast<uint8_t>(MessageType::kChunk));
  std::span<const uint8_t> out;
  ASSERT_EQ(p.openAtOperator(d, &out), std::nullopt);
  EXPECT_TRUE(std::equal(out.begin(), out.end(), payload.begin(), payload.end()));
  // The payload is encrypted: its bytes do not appear in the clear.
  EXPECT_FALSE(std::equal(payload.begin(), payload.begin() + 64, d.begin() + kHeaderBytes));
}

TEST(SecureChannel, EmptyPayloadRoundTrip) {
  Pair p;
  const auto d = p.sealChunk({});
  EXPECT_EQ(d.size(), kDatagramOverhead);
  EXPECT_EQ(p.openAtOperator(d), std::nullopt);
}

TEST(SecureChannel, DatagramTamperedHeaderByteDropped) {
  for (std::size_t i = 4; i < kHeaderBytes; ++i) {  // epoch and sequence bytes
    Pair p;
    auto d = p.sealChunk(bytes(100, 1));
    d[i] ^= 0x02;  // (seq 1 ^ 1 would be 0: too old rather than forged)
    const auto r = p.openAtOperator(d);
    ASSERT_TRUE(r.has_value()) << "byte " << i;
    // An altered epoch no longer names the session; an altered sequence number fails authentication.
    EXPECT_EQ(*r, i < 12 ? DropReason::kNoSession : DropReason::kAuth) << "byte " << i;
  }
  Pair p;
  auto d = p.sealChunk(bytes(100, 1));
  d[3] = static_cast<uint8_t>(MessageType::kStatus);  // type is associated data
  EXPECT_EQ(p.openAtOperator(d), DropReason::kAuth);
}

TEST(SecureChannel, DatagramTamperedPayloadOrTagDropped) {
  for (std::size_t i : {kHeaderBytes, kHeaderBytes + 50, kHeaderBytes + 99, kHeaderBytes + 100, kHeaderBytes + 115}) {
    Pair p;
    auto d = p.sealChunk(bytes(100, 1));
    d[i] ^= 0x80;
    EXPECT_EQ(p.openAtOperator(d), DropReason::kAuth) << "byte " << i;
  }
}

TEST(SecureChannel, DatagramTruncatedDropped) {
  Pair p;
  const auto d = p.sealChunk(bytes(100, 1));
  for (std::size_t n : {std::size_t{0}, std::size_t{3}, kHeaderBytes, kDatagramOverhead - 1}) {
    EXPECT_EQ(p.openAtOperator({d.data(), n}), DropReason::kTooShort) << n;
  }
  for (std::size_t n : {kDatagramOverhead, d.size() - 1}) {
    EXPECT_EQ(p.openAtOperator({d.data(), n}), DropReason::kAuth) << n;
  }
}

TEST(SecureChannel, DatagramOversizedDropped) {
  std::vector<uint8_t> d(kMaxMtu + 1, 0);
  d[0] = 'F';
  d[1] = 'V';
  d[2] = kProtocolVersion;
  d[3] = static_cast<uint8_t>(MessageType::kChunk);
  Header h;
  EXPECT_EQ(parseHeader(d, h), DropReason::kTooLong);
  // And seal refuses to build one.
  Pair p;
  std::vector<uint8_t> big(kMaxPayloadBytes + 1);
  std::vector<uint8_t> out(kMaxMtu + 100);
  EXPECT_TRUE(p.robot.seal(MessageType::kChunk, big, out).empty());
  EXPECT_EQ(p.robot.lastTxSeq(), 0u);  // no sequence number spent
  big.pop_back();
  EXPECT_EQ(p.robot.seal(MessageType::kChunk, big, out).size(), kMaxMtu);
}

TEST(SecureChannel, DatagramBadMagicVersionTypeDropped) {
  Pair p;
  auto d = p.sealChunk(bytes(10, 1));
  auto m = d;
  m[0] = 'X';
  EXPECT_EQ(p.openAtOperator(m), DropReason::kBadMagic);
  m = d;
  m[2] = kProtocolVersion + 1;
  EXPECT_EQ(p.openAtOperator(m), DropReason::kBadVersion);
  m = d;
  m[3] = 0;
  EXPECT_EQ(p.openAtOperator(m), DropReason::kBadType);
  m[3] = 200;
  EXPECT_EQ(p.openAtOperator(m), DropReason::kBadType);
  m[3] = static_cast<uint8_t>(MessageType::kBrickAck) + 1;
  EXPECT_EQ(p.openAtOperator(m), DropReason::kBadType);
  EXPECT_TRUE(isKnownType(static_cast<uint8_t>(MessageType::kBrickChunk)));
  EXPECT_TRUE(isKnownType(static_cast<uint8_t>(MessageType::kBrickAck)));
}

TEST(SecureChannel, WrongKeyDropped) {
  Pair p;
  const auto d = p.sealChunk(bytes(100, 1));
  Pair other;  // another PSK and nonces, same epochs
  other.op = SessionChannel(sessionKeys(other.psk, Role::kOperator, p.client, p.robot_nonce), p.operator_epoch,
                            p.robot_epoch);
  EXPECT_EQ(other.openAtOperator(d), DropReason::kAuth);
}

TEST(SecureChannel, OldSessionDatagramDoesNotAuthenticateInNewSession) {
  Pair p;
  const auto d = p.sealChunk(bytes(100, 1));
  // Same PSK and epochs, a new robot nonce: a new session.
  const Nonce128 new_robot_nonce = randomNonce128();
  SessionChannel op(sessionKeys(p.psk, Role::kOperator, p.client, new_robot_nonce), p.operator_epoch, p.robot_epoch);
  Header h;
  ASSERT_EQ(parseHeader(d, h), std::nullopt);
  std::span<const uint8_t> payload;
  EXPECT_EQ(op.open(h, d, p.plain, payload), DropReason::kAuth);
}

TEST(SecureChannel, ReplayedAndTooOldDropped) {
  Pair p;
  std::vector<std::vector<uint8_t>> sent;
  for (int i = 0; i < 1100; ++i) sent.push_back(p.sealChunk(bytes(20, static_cast<uint8_t>(i))));
  ASSERT_EQ(p.openAtOperator(sent[0]), std::nullopt);
  EXPECT_EQ(p.openAtOperator(sent[0]), DropReason::kReplay);
  // Reordered within the window: accepted.
  ASSERT_EQ(p.openAtOperator(sent[1050]), std::nullopt);
  EXPECT_EQ(p.openAtOperator(sent[1049]), std::nullopt);
  EXPECT_EQ(p.openAtOperator(sent[500]), std::nullopt);
  EXPECT_EQ(p.openAtOperator(sent[500]), DropReason::kReplay);
  // Sequence 1..26 are now below the window (highest 1051).
  EXPECT_EQ(p.openAtOperator(sent[2]), DropReason::kTooOld);
}

TEST(SecureChannel, ForgedDatagramDoesNotMoveTheWindow) {
  Pair p;
  auto d = p.sealChunk(bytes(20, 1));
  auto forged = d;
  // A forged datagram with a huge sequence number must not push real ones out of the window.
  for (int i = 12; i < 20; ++i) forged[i] = 0xff;
  EXPECT_EQ(p.openAtOperator(forged), DropReason::kAuth);
  EXPECT_EQ(p.openAtOperator(d), std::nullopt);
}

TEST(SecureChannel, DirectionsAndKindsUseDifferentKeys) {
  const Key psk = generateKey();
  const Nonce128 c = randomNonce128();
  const Nonce128 r = randomNonce128();
  const DirectionKeys hs_robot = handshakeKeys(psk, Role::kRobot);
  const DirectionKeys hs_op = handshakeKeys(psk, Role::kOperator);
  const DirectionKeys s_robot = sessionKeys(psk, Role::kRobot, c, r);
  const DirectionKeys s_op = sessionKeys(psk, Role::kOperator, c, r);
  EXPECT_EQ(hs_robot.tx, hs_op.rx);
  EXPECT_EQ(hs_robot.rx, hs_op.tx);
  EXPECT_EQ(s_robot.tx, s_op.rx);
  EXPECT_NE(hs_robot.tx, hs_robot.rx);
  EXPECT_NE(s_robot.tx, s_robot.rx);
  EXPECT_NE(s_robot.tx, hs_robot.tx);
  EXPECT_NE(s_robot.tx, psk);
  EXPECT_NE(sessionKeys(psk, Role::kRobot, r, c).tx, s_robot.tx);  // nonces are ordered
}

TEST(SecureChannel, ReflectedDatagramIsWrongDirectionAndFailsAuth) {
  // The type says who sent it; and even with the type rewritten, the robot's
  // transmit key is not its receive key.
  EXPECT_TRUE(isSentBy(MessageType::kChunk, Role::kRobot));
  EXPECT_FALSE(isSentBy(MessageType::kChunk, Role::kOperator));
  EXPECT_TRUE(isSentBy(MessageType::kGaze, Role::kOperator));
  EXPECT_TRUE(isSentBy(MessageType::kBye, Role::kOperator));
  EXPECT_TRUE(isSentBy(MessageType::kBrickChunk, Role::kRobot));
  EXPECT_FALSE(isSentBy(MessageType::kBrickChunk, Role::kOperator));
  Pair p;
  auto d = p.sealChunk(bytes(50, 1));
  Header h;
  ASSERT_EQ(parseHeader(d, h), std::nullopt);
  // The robot opening its own datagram under its receive key (epoch forced to match).
  SessionChannel robot_rx(sessionKeys(p.psk, Role::kRobot, p.client, p.robot_nonce), 1, p.robot_epoch);
  std::span<const uint8_t> payload;
  EXPECT_EQ(robot_rx.open(h, d, p.plain, payload), DropReason::kAuth);
}

TEST(SecureChannel, RandomDatagramsNeverOpen) {
  Pair p;
  std::mt19937 rng(7);
  std::vector<uint8_t> d(kMaxMtu + 10);
  DropCounters counters;
  for (int i = 0; i < 5000; ++i) {
    const std::size_t n = rng() % d.size();
    for (std::size_t k = 0; k < n; ++k) d[k] = static_cast<uint8_t>(rng());
    if (i % 2 == 0 && n >= 4) {  // half look like our frames
      d[0] = 'F';
      d[1] = 'V';
      d[2] = kProtocolVersion;
      d[3] = static_cast<uint8_t>(1 + rng() % 8);
    }
    const auto r = p.openAtOperator({d.data(), n});
    ASSERT_TRUE(r.has_value());
    counters.add(*r);
  }
  EXPECT_EQ(counters.total(), 5000u);
}

TEST(SecureChannel, DropReasonNamesAreDistinct) {
  std::set<std::string> names;
  for (std::size_t i = 0; i < kDropReasonCount; ++i) names.insert(dropReasonName(static_cast<DropReason>(i)));
  EXPECT_EQ(names.size(), kDropReasonCount);
  EXPECT_EQ(names.count("unknown"), 0u);
}

// --- Keys ---------------------------------------------------------------------

class KeyFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("fovea-key-test-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text, mode_t mode = 0600) {
    const auto path = (dir_ / name).string();
    std::ofstream(path) << text;
    ::chmod(path.c_str(), mode);
    return path;
  }
  std::filesystem::path dir_;
};

TEST(Key, ParseHex) {
  const std::string hex = "00112233445566778899aabbccddeeff00112233445566778899AABBCCDDEEFF";
  auto k = parseKeyHex("  \n" + hex + "\n\t ");
  ASSERT_TRUE(k) << k.status().toString();
  EXPECT_EQ(k->bytes[0], 0x00);
  EXPECT_EQ(k->bytes[1], 0x11);
  EXPECT_EQ(k->bytes[31], 0xff);
  EXPECT_FALSE(parseKeyHex(hex.substr(0, 62)));
  EXPECT_FALSE(parseKeyHex(hex + "0"));
  auto bad = parseKeyHex(hex.substr(0, 10) + "g" + hex.substr(11));
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.status().message().find("character 11"), std::string::npos) << bad.status().message();
  EXPECT_FALSE(parseKeyHex(hex.substr(0, 32) + " " + hex.substr(33)));  // inner whitespace
}

TEST(Key, GenerateFormatParse) {
  const Key a = generateKey();
  const Key b = generateKey();
  EXPECT_NE(a, b);
  auto parsed = parseKeyHex(formatKeyHex(a));
  ASSERT_TRUE(parsed);
  EXPECT_EQ(parsed.value(), a);
}

TEST_F(KeyFile, LoadsAndWarnsWhenOthersCanRead) {
  const Key key = generateKey();
  auto loaded = loadKeyFile(write("ok.key", formatKeyHex(key) + "\n"));
  ASSERT_TRUE(loaded) << loaded.status().toString();
  EXPECT_EQ(loaded->key, key);
  EXPECT_TRUE(loaded->warning.empty());
  auto open = loadKeyFile(write("open.key", formatKeyHex(key), 0644));
  ASSERT_TRUE(open);
  EXPECT_NE(open->warning.find("readable by other users"), std::string::npos);
}

TEST_F(KeyFile, ClearErrors) {
  auto missing = loadKeyFile((dir_ / "absent.key").string());
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.status().code(), ErrorCode::kNotFound);
  EXPECT_NE(missing.status().message().find("absent.key"), std::string::npos);
  auto short_key = loadKeyFile(write("short.key", "abcd"));
  ASSERT_FALSE(short_key);
  EXPECT_NE(short_key.status().message().find("64 hex characters"), std::string::npos);
  auto non_hex = loadKeyFile(write("nonhex.key", std::string(64, 'z')));
  ASSERT_FALSE(non_hex);
  EXPECT_NE(non_hex.status().message().find("not a hex digit"), std::string::npos);
  EXPECT_FALSE(loadKeyFile(dir_.string()));  // a directory
}

TEST_F(KeyFile, WriteKeyFileIsPrivateAndRefusesToOverwrite) {
  const auto path = (dir_ / "new.key").string();
  const Key key = generateKey();
  ASSERT_TRUE(writeKeyFile(path, key));
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  auto loaded = loadKeyFile(path);
  ASSERT_TRUE(loaded);
  EXPECT_EQ(loaded->key, key);
  EXPECT_FALSE(writeKeyFile(path, generateKey()));
}

// --- Messages -----------------------------------------------------------------

GazeSample someGaze() {
  GazeSample g;
  g.sequence = 42;
  g.operator_stamp_ns = 123456789;
  g.gaze_origin_m = {1.5, -0.25, 1.75};
  g.gaze_direction = {0.6, 0.0, 0.8};
  g.hmd_position_m = {1.5, -0.2, 1.8};
  g.hmd_orientation = {0.5, 0.5, 0.5, 0.5};
  g.confidence = 0.75f;
  g.feedback = {17, 3, 99999, 555, 12};
  return g;
}

TEST(Messages, GazeRoundTrip) {
  MessageEncoder enc;
  const GazeSample g = someGaze();
  GazeSample out;
  ASSERT_EQ(decode(enc.encode(g), out), std::nullopt);
  EXPECT_EQ(out.sequence, 42u);
  EXPECT_EQ(out.operator_stamp_ns, 123456789);
  EXPECT_EQ(out.gaze_origin_m.y, -0.25);
  EXPECT_EQ(out.gaze_direction.z, 0.8);
  EXPECT_EQ(out.hmd_orientation.w, 0.5);
  EXPECT_EQ(out.confidence, 0.75f);
  EXPECT_EQ(out.feedback.last_frame_id, 17u);
  EXPECT_EQ(out.feedback.datagrams_lost, 3u);
  EXPECT_EQ(out.feedback.bytes_received, 99999u);
  EXPECT_EQ(out.feedback.echo_robot_stamp_ns, 555);
  EXPECT_EQ(out.feedback.echo_delay_ns, 12);
}

TEST(Messages, GazeSemanticChecks) {
  MessageEncoder enc;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<GazeSample> bad(8, someGaze());
  bad[0].gaze_direction = {1, 1, 0};     // not unit
  bad[1].gaze_direction = {0, 0, 0};
  bad[2].gaze_origin_m.x = nan;
  bad[3].hmd_position_m.z = inf;
  bad[4].hmd_orientation = {1, 1, 0, 0};  // not unit
  bad[5].confidence = 1.5f;
  bad[6].sequence = 0;
  bad[7].gaze_direction.y = nan;
  for (std::size_t i = 0; i < bad.size(); ++i) {
    GazeSample out;
    EXPECT_EQ(decode(enc.encode(bad[i]), out), DropReason::kSemantic) << i;
  }
  GazeSample neg = someGaze();
  neg.confidence = -0.1f;
  GazeSample out;
  EXPECT_EQ(decode(enc.encode(neg), out), DropReason::kSemantic);
}

TEST(Messages, GarbageFailsVerification) {
  std::mt19937 rng(3);
  std::vector<uint8_t> buf(300);
  int verified_garbage = 0;
  for (int i = 0; i < 3000; ++i) {
    const std::size_t n = rng() % buf.size();
    for (std::size_t k = 0; k < n; ++k) buf[k] = static_cast<uint8_t>(rng());
    GazeSample g;
    HelloMsg h;
    StatusReport s;
    if (!decode({buf.data(), n}, g)) ++verified_garbage;
    (void)decode({buf.data(), n}, h);
    (void)decode({buf.data(), n}, s);
  }
  EXPECT_EQ(verified_garbage, 0);  // random bytes are never a valid gaze
  GazeSample g;
  EXPECT_EQ(decode(std::span<const uint8_t>{}, g), DropReason::kVerify);
  MessageEncoder enc;
  auto good = enc.encode(someGaze());
  std::vector<uint8_t> truncated(good.begin(), good.begin() + good.size() / 2);
  EXPECT_EQ(decode(truncated, g), DropReason::kVerify);
}

// A message whose text field is absent decodes to an empty text (readText
// assigns an empty view with a null data(); memcpy of it was undefined
// behaviour, which UBSan reports: found by tests/fuzz/fuzz_messages).
TEST(Messages, AbsentTextDecodesEmpty) {
  flatbuffers::FlatBufferBuilder builder;
  builder.Finish(wire::CreateBye(builder));
  const std::vector<uint8_t> payload(builder.GetBufferPointer(), builder.GetBufferPointer() + builder.GetSize());
  ByeMsg bye;
  bye.reason.assign("left over");
  ASSERT_EQ(decode(payload, bye), std::nullopt);
  EXPECT_EQ(bye.reason.view(), "");
  EXPECT_EQ(bye.reason.chars[0], '\0');
  ShortText text("abc");
  text.assign(std::string_view{});
  EXPECT_EQ(text.size, 0u);
  EXPECT_EQ(text.chars[0], '\0');
}

// The datagram's 20-byte header leaves its payload unaligned; FlatBuffers reads
// in place, so payloads are opened into an aligned PlainBuffer, every encoder
// output starts aligned, and a payload off the boundary is dropped unread
// (UBSan found the Hello parsed at an odd address: flatbuffers/buffer.h:124).
TEST(Messages, PayloadUnalignedIsDroppedNotRead) {
  static_assert(alignof(PlainBuffer) >= kPayloadAlignment);
  MessageEncoder enc;
  HelloMsg hello;
  hello.operator_name.assign("alice");
  hello.mtu_bytes = 1200;
  hello.client_nonce = {1, 2};
  const std::span<const uint8_t> good = enc.encode(hello);
  EXPECT_TRUE(isPayloadAligned(good.data()));
  ByeMsg bye;  // no 8-byte field of its own, aligned all the same
  bye.reason.assign("done");
  EXPECT_TRUE(isPayloadAligned(enc.encode(bye).data()));

  const std::span<const uint8_t> hello_bytes = enc.encode(hello);
  std::vector<uint8_t> shifted(hello_bytes.size() + kPayloadAlignment);
  std::copy(hello_bytes.begin(), hello_bytes.end(), shifted.begin() + 1);
  HelloMsg out;
  EXPECT_EQ(decode({shifted.data() + 1, hello_bytes.size()}, out), DropReason::kVerify);
  std::copy(hello_bytes.begin(), hello_bytes.end(), shifted.begin());
  EXPECT_EQ(decode({shifted.data(), hello_bytes.size()}, out), std::nullopt);

  // Through the channel: the opened payload lies at the aligned buffer's start.
  Pair p;
  const auto d = p.sealChunk(hello_bytes);
  std::span<const uint8_t> opened;
  ASSERT_EQ(p.openAtOperator(d, &opened), std::nullopt);
  EXPECT_EQ(opened.data(), p.plain.bytes.data());
  EXPECT_TRUE(isPayloadAligned(opened.data()));
  EXPECT_EQ(decode(opened, out), std::nullopt);
}

TEST(Messages, HelloAcceptRefuseStatusRoundTrip) {
  MessageEncoder enc;
  HelloMsg hello;
  hello.operator_name.assign("alice");
  hello.budget_bytes_per_s = 5'000'000;
  hello.mtu_bytes = 1400;
  hello.client_nonce = {1, 2};
  HelloMsg h2;
  ASSERT_EQ(decode(enc.encode(hello), h2), std::nullopt);
  EXPECT_EQ(h2.operator_name.view(), "alice");
  EXPECT_EQ(h2.budget_bytes_per_s, 5'000'000u);
  EXPECT_EQ(h2.mtu_bytes, 1400u);
  EXPECT_EQ(h2.client_nonce, (Nonce128{1, 2}));

  HelloMsg long_name = hello;
  long_name.operator_name.assign(std::string(80, 'x'));
  EXPECT_EQ(decode(enc.encode(long_name), h2), DropReason::kSemantic);

  AcceptMsg accept{{1, 2}, {3, 4}, 1200, 1000, 77};
  AcceptMsg a2;
  ASSERT_EQ(decode(enc.encode(accept), a2), std::nullopt);
  EXPECT_EQ(a2.robot_nonce, (Nonce128{3, 4}));
  EXPECT_EQ(a2.robot_stamp_ns, 77);
  accept.mtu_bytes = 10;
  EXPECT_EQ(decode(enc.encode(accept), a2), DropReason::kSemantic);

  RefuseMsg refuse;
  refuse.reason = RefuseReason::kBusy;
  refuse.text.assign("busy: serving alice at 127.0.0.1:5000");
  RefuseMsg r2;
  ASSERT_EQ(decode(enc.encode(refuse), r2), std::nullopt);
  EXPECT_EQ(r2.text.view(), "busy: serving alice at 127.0.0.1:5000");

  StatusReport status;
  status.frames_sent = 30;
  status.rtt_ns = 1234;
  StatusReport s2;
  ASSERT_EQ(decode(enc.encode(status), s2), std::nullopt);
  EXPECT_EQ(s2.frames_sent, 30u);
  EXPECT_EQ(s2.rtt_ns, 1234);
  EXPECT_EQ(s2.gaze_age_ns, -1);
  EXPECT_FALSE(s2.gaze_origin_m.has_value());
  EXPECT_FALSE(s2.gaze_direction.has_value());

  // The robot's gaze round-trips; a non-unit direction is refused.
  status.gaze_origin_m = Vec3{3.0, 0.35, 1.55};
  status.gaze_direction = Vec3{0.0, 0.6, 0.8};
  ASSERT_EQ(decode(enc.encode(status), s2), std::nullopt);
  ASSERT_TRUE(s2.gaze_origin_m && s2.gaze_direction);
  EXPECT_EQ(s2.gaze_origin_m->y, 0.35);
  EXPECT_EQ(s2.gaze_direction->z, 0.8);
  status.gaze_direction = Vec3{0.0, 0.0, 2.0};
  StatusReport s3;
  EXPECT_EQ(decode(enc.encode(status), s3), DropReason::kSemantic);
}

}  // namespace
}  // namespace fovea::net
