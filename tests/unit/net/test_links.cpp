// RobotLink and OperatorLink over loopback (IPv4 and IPv6): handshake, refusal,
// replays, gaze delivery, timeouts, garbage floods (docs/protocol.md).
#include <gtest/gtest.h>

#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <functional>
#include <atomic>
#include <future>
#include <thread>
#include <limits>
#include <random>
#include <vector>

#include "net/operator_link.h"
#include "net/robot_link.h"
#include "tests/support/test_time.h"

namespace fovea::net {
namespace {

using namespace std::chrono_literals;
using Datagram = std::vector<uint8_t>;

std::unique_ptr<RobotLink> makeRobot(const Key& key, const char* listen = "127.0.0.1:0",
                                     int64_t timeout_ns = 3'000'000'000) {
  RobotLinkConfig config;
  config.listen = listen;
  config.key = key;
  config.session_timeout_ns = timeout_ns;
  auto robot = RobotLink::create(config);
  if (!robot) {
    ADD_FAILURE() << robot.status().toString();
    return nullptr;
  }
  return std::move(robot).value();
}

OperatorLinkConfig operatorConfig(const Key& key, const char* name) {
  OperatorLinkConfig config;
  config.key = key;
  config.name = name;
  config.connect_timeout_ms = 2000;
  config.first_retry_ms = 50;
  return config;
}

// Forwards between one client and the robot, recording every datagram; a
// datagram is dropped when drop(to_robot, index) says so.
struct Relay {
  UdpSocket socket;
  Endpoint robot;
  Endpoint client;
  std::vector<Datagram> to_robot;
  std::vector<Datagram> to_client;
  std::function<bool(bool to_robot, std::size_t index)> drop;

  explicit Relay(const Endpoint& robot_endpoint) : robot(robot_endpoint) {
    auto s = UdpSocket::bind(Endpoint::parse("127.0.0.1:0").value());
    socket = std::move(s).value();
  }
  std::string address() const { return socket.localEndpoint().toString(); }
  void pump() {
    std::array<uint8_t, kMaxMtu + 1> buf;
    Endpoint from;
    long n;
    while ((n = socket.receive(buf, from)) >= 0) {
      Datagram d(buf.begin(), buf.begin() + n);
      const bool from_robot = from == robot;
      if (!from_robot) client = from;
      auto& log = from_robot ? to_client : to_robot;
      log.push_back(d);
      if (drop && drop(!from_robot, log.size() - 1)) continue;
      if (from_robot && !client.valid()) continue;
      (void)socket.sendTo(d, from_robot ? client : robot);
    }
  }
};

Result<std::unique_ptr<OperatorLink>> connectWhilePolling(RobotLink& robot, const std::string& address,
                                                          const OperatorLinkConfig& config, Relay* relay = nullptr) {
  auto pending = std::async(std::launch::async, [&] { return OperatorLink::connect(address, config); });
  while (pending.wait_for(0ms) != std::future_status::ready) {
    robot.poll(1);
    if (relay) relay->pump();
  }
  return pending.get();
}

// Polls the robot (and relay) until pred() or timeout.
bool pollUntil(RobotLink& robot, const std::function<bool()>& pred, int timeout_ms = 1000, Relay* relay = nullptr) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (!pred()) {
    if (std::chrono::steady_clock::now() > end) return false;
    if (relay) relay->pump();
    robot.poll(1);
  }
  return true;
}

GazeSample gazeTowards(double x, double y, double z) {
  GazeSample g;
  const double n = std::sqrt(x * x + y * y + z * z);
  g.gaze_direction = {x / n, y / n, z / n};
  g.gaze_origin_m = {0.1, 0.2, 1.6};
  return g;
}

Datagram chunkPayload(std::size_t n, uint8_t seed) {
  Datagram d(n);
  for (std::size_t i = 0; i < n; ++i) d[i] = static_cast<uint8_t>(seed ^ i);
  return d;
}

// Receives at the operator until a payload of the type arrives.
std::optional<Received> receiveType(OperatorLink& op, MessageType type, int timeout_ms = 500) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < end) {
    auto r = op.receive(20);
    if (r && r->type == type) return r;
  }
  return std::nullopt;
}

bool ipv6Available() {
  const int fd = ::socket(AF_INET6, SOCK_DGRAM, 0);
  if (fd < 0) return false;
  sockaddr_in6 a{};
  a.sin6_family = AF_INET6;
  a.sin6_addr = in6addr_loopback;
  const bool ok = ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  ::close(fd);
  return ok;
}

void expectHandshakeAndChunk(const char* listen) {
  const Key key = generateKey();
  auto robot = makeRobot(key, listen);
  ASSERT_TRUE(robot);
  OperatorLinkConfig config = operatorConfig(key, "alice");
  config.mtu_bytes = 9000 - 48;  // asks for jumbo; the robot allows 1200
  auto op = connectWhilePolling(*robot, robot->localEndpoint().toString(), config);
  ASSERT_TRUE(op) << op.status().toString();
  ASSERT_TRUE(robot->hasSession());
  EXPECT_EQ(robot->session()->operator_name.view(), "alice");
  EXPECT_EQ(robot->session()->peer.port(), (*op)->localPort());
  EXPECT_EQ((*op)->mtuBytes(), kDefaultMtu);
  EXPECT_EQ(robot->maxPayloadBytes(), kDefaultMtu - kDatagramOverhead);
  EXPECT_EQ((*op)->budgetBytesPerS(), RobotLinkConfig{}.max_budget_bytes_per_s);
  EXPECT_FALSE(robot->session()->confirmed);

  const Datagram payload = chunkPayload(robot->maxPayloadBytes(), 9);
  ASSERT_EQ(robot->send(MessageType::kChunk, payload), SendResult::kSent);
  auto r = receiveType(**op, MessageType::kChunk);
  ASSERT_TRUE(r);
  EXPECT_TRUE(std::equal(r->payload.begin(), r->payload.end(), payload.begin(), payload.end()));
  const Datagram too_big = chunkPayload(robot->maxPayloadBytes() + 1, 1);
  EXPECT_EQ(robot->send(MessageType::kChunk, too_big), SendResult::kTooLarge);
  EXPECT_EQ(robot->send(MessageType::kGaze, payload), SendResult::kWrongType);
  // A map brick's part travels as its own type (the link does not look inside).
  ASSERT_EQ(robot->send(MessageType::kBrickChunk, payload), SendResult::kSent);
  r = receiveType(**op, MessageType::kBrickChunk);
  ASSERT_TRUE(r);
  EXPECT_TRUE(std::equal(r->payload.begin(), r->payload.end(), payload.begin(), payload.end()));

  ASSERT_TRUE((*op)->sendGaze(gazeTowards(0, 0, 1)));
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->latestGaze().has_value(); }));
  EXPECT_TRUE(robot->session()->confirmed);
  EXPECT_EQ(robot->counters().dropped.total(), 0u);
  EXPECT_EQ((*op)->counters().dropped.total(), 0u);
}

TEST(Links, HandshakeIpv4) { expectHandshakeAndChunk("127.0.0.1:0"); }

TEST(Links, HandshakeIpv6) {
  if (!ipv6Available()) GTEST_SKIP() << "no IPv6 loopback in this container";
  expectHandshakeAndChunk("[::1]:0");
}

TEST(Links, NoKeyRefusedUnlessInsecure) {
  RobotLinkConfig config;
  config.listen = "127.0.0.1:0";
  auto refused = RobotLink::create(config);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.status().message().find("--insecure"), std::string::npos);
  config.insecure = true;
  auto robot = RobotLink::create(config);
  ASSERT_TRUE(robot) << robot.status().toString();
  EXPECT_NE((*robot)->notice().find("INSECURE"), std::string::npos);
  OperatorLinkConfig op_config;
  op_config.insecure = true;
  op_config.first_retry_ms = 50;
  auto op = connectWhilePolling(**robot, (*robot)->localEndpoint().toString(), op_config);
  ASSERT_TRUE(op) << op.status().toString();
  EXPECT_FALSE((*op)->notice().empty());
}

TEST(Links, BindFailureNamesTheAddress) {
  const Key key = generateKey();
  auto first = makeRobot(key);
  ASSERT_TRUE(first);
  RobotLinkConfig config;
  config.key = key;
  config.listen = first->localEndpoint().toString();
  auto second = RobotLink::create(config);
  ASSERT_FALSE(second);
  EXPECT_NE(second.status().message().find(config.listen), std::string::npos) << second.status().message();
  config.listen = "nonsense";
  EXPECT_FALSE(RobotLink::create(config));
}

TEST(Links, EndpointForms) {
  for (const char* text : {"127.0.0.1:7000", "0.0.0.0:7000", "localhost:7000", "[::1]:7000", "[::]:7000"}) {
    auto e = Endpoint::parse(text);
    ASSERT_TRUE(e) << text << ": " << e.status().toString();
    EXPECT_EQ(e->port(), 7000);
  }
  EXPECT_EQ(Endpoint::parse("[::1]:7000")->toString(), "[::1]:7000");
  EXPECT_EQ(Endpoint::parse("localhost:7000")->toString(), "127.0.0.1:7000");
  for (const char* bad : {"", "7000", "127.0.0.1", "127.0.0.1:", "127.0.0.1:70000", "::1:7000", "[::1]7000",
                          "127.0.0.1:7x", "no.such.host.invalid:7000"}) {
    EXPECT_FALSE(Endpoint::parse(bad)) << bad;
  }
}

TEST(Links, SecondOperatorRefusedWhileFirstKeepsReceiving) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  const std::string address = robot->localEndpoint().toString();
  auto alice = connectWhilePolling(*robot, address, operatorConfig(key, "alice"));
  ASSERT_TRUE(alice) << alice.status().toString();
  auto bob = connectWhilePolling(*robot, address, operatorConfig(key, "bob"));
  ASSERT_FALSE(bob);
  const std::string& why = bob.status().message();
  EXPECT_NE(why.find("busy: serving alice at 127.0.0.1:" + std::to_string((*alice)->localPort())), std::string::npos)
      << why;
  // Each Hello bob sent before the refusal reached him is refused and counted: one,
  // or two when the poll lags past his first retry (100 ms; under qemu it did).
  EXPECT_GE(robot->counters().refusals, 1u);
  EXPECT_EQ(robot->session()->operator_name.view(), "alice");
  ASSERT_EQ(robot->send(MessageType::kChunk, chunkPayload(100, 1)), SendResult::kSent);
  EXPECT_TRUE(receiveType(**alice, MessageType::kChunk));
}

TEST(Links, WrongKeyOperatorGetsNoAnswer) {
  auto robot = makeRobot(generateKey());
  ASSERT_TRUE(robot);
  OperatorLinkConfig config = operatorConfig(generateKey(), "mallory");
  config.connect_timeout_ms = 300;
  auto op = connectWhilePolling(*robot, robot->localEndpoint().toString(), config);
  ASSERT_FALSE(op);
  EXPECT_NE(op.status().message().find("no answer"), std::string::npos) << op.status().message();
  EXPECT_GE(robot->counters().dropped[DropReason::kAuth], 1u);
  EXPECT_FALSE(robot->hasSession());
}

TEST(Links, ReplayedHelloDoesNotBreakSession) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  Relay relay(robot->localEndpoint());
  auto op = connectWhilePolling(*robot, relay.address(), operatorConfig(key, "alice"), &relay);
  ASSERT_TRUE(op) << op.status().toString();
  ASSERT_FALSE(relay.to_robot.empty());
  const Datagram hello = relay.to_robot.front();
  ASSERT_EQ(hello[3], static_cast<uint8_t>(MessageType::kHello));
  ASSERT_TRUE((*op)->sendGaze(gazeTowards(0, 0, 1)));
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->latestGaze().has_value(); }, 1000, &relay));
  const Datagram gaze = relay.to_robot.back();

  // The same Hello from the operator's own address (the relay) and from an attacker.
  auto attacker = UdpSocket::bind(Endpoint::parse("127.0.0.1:0").value());
  ASSERT_TRUE(attacker);
  const uint64_t replays_before = robot->counters().dropped[DropReason::kReplay];
  ASSERT_TRUE(relay.socket.sendTo(hello, robot->localEndpoint()));
  ASSERT_TRUE(attacker->sendTo(hello, robot->localEndpoint()));
  ASSERT_TRUE(attacker->sendTo(gaze, robot->localEndpoint()));  // from another address
  ASSERT_TRUE(relay.socket.sendTo(gaze, robot->localEndpoint()));  // a replayed gaze
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->counters().dropped.total() >= 4; }));
  EXPECT_EQ(robot->counters().dropped[DropReason::kReplay], replays_before + 3);
  EXPECT_EQ(robot->counters().dropped[DropReason::kNoSession], 1u);
  EXPECT_EQ(robot->counters().sessions_accepted, 1u);
  EXPECT_EQ(robot->counters().refusals, 0u);
  EXPECT_EQ(robot->session()->peer, relay.socket.localEndpoint());

  // The session goes on.
  ASSERT_TRUE((*op)->sendGaze(gazeTowards(1, 0, 1)));
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->latestGaze()->sample.sequence == 2; }, 1000, &relay));
  ASSERT_EQ(robot->send(MessageType::kChunk, chunkPayload(64, 2)), SendResult::kSent);
  relay.pump();
  EXPECT_TRUE(receiveType(**op, MessageType::kChunk));

  // After the session, the old Hello still does not start one.
  (*op)->bye("done");
  ASSERT_TRUE(pollUntil(*robot, [&] { return !robot->hasSession(); }, 1000, &relay));
  ASSERT_TRUE(attacker->sendTo(hello, robot->localEndpoint()));
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->counters().dropped[DropReason::kReplay] == replays_before + 4; }));
  EXPECT_FALSE(robot->hasSession());
}

TEST(Links, GazeNewestWins) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  Relay relay(robot->localEndpoint());
  auto op = connectWhilePolling(*robot, relay.address(), operatorConfig(key, "alice"), &relay);
  ASSERT_TRUE(op) << op.status().toString();
  // Hold the gaze datagrams at the relay, then deliver them out of order.
  const std::size_t first = relay.to_robot.size();
  relay.drop = [](bool to_robot, std::size_t) { return to_robot; };
  for (int i = 1; i <= 4; ++i) {
    GazeSample g = gazeTowards(i, 0, 1);
    g.feedback.last_frame_id = static_cast<uint64_t>(100 + i);
    ASSERT_TRUE((*op)->sendGaze(g));
  }
  const auto end = std::chrono::steady_clock::now() + 1s;
  while (relay.to_robot.size() < first + 4 && std::chrono::steady_clock::now() < end) relay.pump();
  ASSERT_EQ(relay.to_robot.size(), first + 4);
  for (std::size_t k : {2, 0, 1, 3, 1}) ASSERT_TRUE(relay.socket.sendTo(relay.to_robot[first + k], robot->localEndpoint()));
  ASSERT_TRUE(pollUntil(*robot, [&] {
    return robot->counters().gaze_accepted + robot->counters().gaze_stale +
               robot->counters().dropped[DropReason::kReplay] >= 5;
  }));
  EXPECT_EQ(robot->counters().gaze_accepted, 2u);  // 3, then 4
  EXPECT_EQ(robot->counters().gaze_stale, 2u);     // 1 and 2 arrived after 3
  EXPECT_EQ(robot->counters().dropped[DropReason::kReplay], 1u);
  const ReceivedGaze& latest = *robot->latestGaze();
  EXPECT_EQ(latest.sample.sequence, 4u);
  EXPECT_EQ(latest.sample.feedback.last_frame_id, 104u);
  EXPECT_NEAR(latest.sample.gaze_direction.x, 4 / std::sqrt(17.0), 1e-12);
  EXPECT_GT(latest.received_ns, 0);
}

TEST(Links, InvalidGazeFromTheOperatorDroppedAsSemantic) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  auto op = connectWhilePolling(*robot, robot->localEndpoint().toString(), operatorConfig(key, "alice"));
  ASSERT_TRUE(op) << op.status().toString();
  ASSERT_TRUE((*op)->sendGaze(gazeTowards(0, 0, 1)));
  GazeSample bad = gazeTowards(0, 0, 1);
  bad.gaze_direction.x = std::numeric_limits<double>::quiet_NaN();
  ASSERT_TRUE((*op)->sendGaze(bad));
  bad = gazeTowards(0, 0, 1);
  bad.gaze_direction = {0, 0, 2};
  ASSERT_TRUE((*op)->sendGaze(bad));
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->counters().dropped[DropReason::kSemantic] == 2; }));
  ASSERT_TRUE(robot->latestGaze());
  EXPECT_EQ(robot->latestGaze()->sample.sequence, 1u);
  EXPECT_EQ(robot->counters().gaze_accepted, 1u);
}

TEST(Links, BrickAcknowledgementsReachTheRobotAndAnOversizedOneIsNotSent) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  auto op = connectWhilePolling(*robot, robot->localEndpoint().toString(), operatorConfig(key, "alice"));
  ASSERT_TRUE(op) << op.status().toString();
  static BrickAckMsg ack;
  const std::size_t fit = BrickAckMsg::partsThatFit((*op)->mtuBytes() - kDatagramOverhead, 2);
  ASSERT_GT(fit, 40u) << "a 1200-byte MTU takes dozens of parts";
  ack.part_count = fit;
  for (std::size_t i = 0; i < fit; ++i) ack.parts[i] = {{static_cast<int32_t>(i), -1, 2}, 9, static_cast<uint16_t>(i)};
  ack.evicted_count = 2;
  ack.evicted[0] = {4, 5, 6};
  ack.evicted[1] = {-7, 8, -9};
  ASSERT_TRUE((*op)->sendBrickAck(ack));
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->counters().brick_acks == 1; }));
  ASSERT_EQ(robot->brickAcks().size(), fit);
  EXPECT_EQ(robot->brickAcks()[3], ack.parts[3]);
  ASSERT_EQ(robot->brickEvictions().size(), 2u);
  EXPECT_EQ(robot->brickEvictions()[1], (BrickKey{-7, 8, -9}));
  robot->takeBrickAcks();
  EXPECT_TRUE(robot->brickAcks().empty());
  // partsThatFit leaves at most a few parts' room unused...
  MessageEncoder encoder;
  ack.part_count = fit + 3;
  for (std::size_t i = fit; i < fit + 3; ++i) ack.parts[i] = ack.parts[0];
  EXPECT_GT(encoder.encode(ack).size() + kDatagramOverhead, (*op)->mtuBytes());
  // ... and what does not fit is refused at the operator, counted.
  const uint64_t failures = (*op)->counters().send_failures;
  EXPECT_FALSE((*op)->sendBrickAck(ack));
  EXPECT_EQ((*op)->counters().send_failures, failures + 1);
}

TEST(Links, StatusEchoGivesRoundTrip) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  auto op = connectWhilePolling(*robot, robot->localEndpoint().toString(), operatorConfig(key, "alice"));
  ASSERT_TRUE(op) << op.status().toString();
  StatusReport report;
  report.frames_sent = 12;
  ASSERT_EQ(robot->sendStatus(report), SendResult::kSent);
  auto r = receiveType(**op, MessageType::kStatus);
  ASSERT_TRUE(r);
  ASSERT_TRUE((*op)->lastStatus());
  EXPECT_EQ((*op)->lastStatus()->frames_sent, 12u);
  ASSERT_TRUE((*op)->sendGaze(gazeTowards(0, 1, 1)));
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->latestGaze().has_value(); }));
  EXPECT_EQ(robot->latestGaze()->sample.feedback.echo_robot_stamp_ns, (*op)->lastStatus()->robot_stamp_ns);
  EXPECT_GE(robot->lastRttNs(), 0);
  EXPECT_LT(robot->lastRttNs(), 1'000'000'000);
}

TEST(Links, LostDatagramsCountedFromSequenceGaps) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  Relay relay(robot->localEndpoint());
  auto op = connectWhilePolling(*robot, relay.address(), operatorConfig(key, "alice"), &relay);
  ASSERT_TRUE(op) << op.status().toString();
  const std::size_t first = relay.to_client.size();
  relay.drop = [first](bool to_robot, std::size_t i) { return !to_robot && i >= first && (i - first) % 3 == 1; };
  int received = 0;
  for (int i = 0; i < 30; ++i) {
    ASSERT_EQ(robot->send(MessageType::kChunk, chunkPayload(200, static_cast<uint8_t>(i))), SendResult::kSent);
    relay.pump();
    while (auto r = (*op)->receive(5)) received += r->type == MessageType::kChunk;
  }
  EXPECT_EQ(received, 20);
  // The last chunk (index 29) arrived, so every one of the 10 gaps is known.
  EXPECT_EQ((*op)->counters().datagrams_lost, 10u);
  ASSERT_TRUE((*op)->sendGaze(gazeTowards(0, 0, 1)));
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->latestGaze().has_value(); }, 1000, &relay));
  EXPECT_EQ(robot->latestGaze()->sample.feedback.datagrams_lost, 10u);
  EXPECT_GT(robot->latestGaze()->sample.feedback.bytes_received, 20u * 200u);
}

TEST(Links, ReflectedDatagramsAreWrongDirection) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  Relay relay(robot->localEndpoint());
  auto op = connectWhilePolling(*robot, relay.address(), operatorConfig(key, "alice"), &relay);
  ASSERT_TRUE(op) << op.status().toString();
  ASSERT_EQ(robot->send(MessageType::kChunk, chunkPayload(50, 1)), SendResult::kSent);
  ASSERT_TRUE((*op)->sendGaze(gazeTowards(0, 0, 1)));
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->latestGaze().has_value(); }, 1000, &relay));
  relay.pump();
  ASSERT_TRUE(receiveType(**op, MessageType::kChunk));
  const Datagram robot_chunk = relay.to_client.back();
  const Datagram operator_gaze = relay.to_robot.back();
  ASSERT_TRUE(relay.socket.sendTo(robot_chunk, robot->localEndpoint()));  // back to its sender
  ASSERT_TRUE(pollUntil(*robot, [&] { return robot->counters().dropped[DropReason::kWrongDirection] == 1; }));
  auto me = UdpSocket::bind(Endpoint::parse("127.0.0.1:0").value());
  ASSERT_TRUE(me->sendTo(operator_gaze, Endpoint::parse("127.0.0.1:" + std::to_string((*op)->localPort())).value()));
  EXPECT_FALSE((*op)->receive(100));
  EXPECT_EQ((*op)->counters().dropped[DropReason::kWrongDirection], 1u);
}

TEST(Links, SessionEndsOnByeOrTimeoutThenNewOperatorAccepted) {
  const Key key = generateKey();
  auto robot = makeRobot(key, "127.0.0.1:0", 400'000'000);
  ASSERT_TRUE(robot);
  const std::string address = robot->localEndpoint().toString();
  {
    auto alice = connectWhilePolling(*robot, address, operatorConfig(key, "alice"));
    ASSERT_TRUE(alice) << alice.status().toString();
    (*alice)->bye("leaving");
    ASSERT_TRUE(pollUntil(*robot, [&] { return !robot->hasSession(); }));
    EXPECT_EQ(robot->counters().sessions_ended_bye, 1u);
  }
  auto bob = connectWhilePolling(*robot, address, operatorConfig(key, "bob"));
  ASSERT_TRUE(bob) << bob.status().toString();
  ASSERT_TRUE(robot->hasSession());
  EXPECT_EQ(robot->session()->operator_name.view(), "bob");
  // Bob goes silent: after 400 ms the robot ends the session and says Bye.
  ASSERT_TRUE(pollUntil(*robot, [&] { return !robot->hasSession(); }, 1000));
  EXPECT_EQ(robot->counters().sessions_timed_out, 1u);
  EXPECT_TRUE(receiveType(**bob, MessageType::kBye));
  EXPECT_FALSE((*bob)->sessionActive());
  auto carol = connectWhilePolling(*robot, address, operatorConfig(key, "carol"));
  ASSERT_TRUE(carol) << carol.status().toString();
  ASSERT_TRUE(robot->hasSession());
  EXPECT_EQ(robot->session()->operator_name.view(), "carol");
  EXPECT_EQ(robot->counters().sessions_accepted, 3u);
}

// Random bytes, some behind a plausible header, of random length up to beyond the MTU.
Datagram garbage(std::mt19937& rng) {
  // Mostly MTU-sized, some beyond the largest datagram the protocol allows.
  Datagram d(rng() % 10 == 0 ? kMaxMtu - 100 + rng() % 300 : rng() % 1500);
  for (auto& b : d) b = static_cast<uint8_t>(rng());
  if (d.size() >= 4 && rng() % 2 == 0) {
    d[0] = 'F';
    d[1] = 'V';
    d[2] = kProtocolVersion;
    d[3] = static_cast<uint8_t>(1 + rng() % 8);
  }
  return d;
}

TEST(Links, GarbageFloodDoesNotStopGazeOrChunks) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  auto op = connectWhilePolling(*robot, robot->localEndpoint().toString(), operatorConfig(key, "alice"));
  ASSERT_TRUE(op) << op.status().toString();
  auto attacker = UdpSocket::bind(Endpoint::parse("127.0.0.1:0").value());
  ASSERT_TRUE(attacker);
  const Endpoint op_endpoint = Endpoint::parse("127.0.0.1:" + std::to_string((*op)->localPort())).value();
  std::mt19937 rng(11);
  const uint64_t robot_rx_before = robot->counters().datagrams_received;
  const uint64_t op_rx_before = (*op)->counters().datagrams_received;
  // Small batches keep the kernel's receive buffer from overflowing (its drops
  // would not be ours to count).
  constexpr int kBatches = 300;
  constexpr int kPerBatch = 10;
  int chunks = 0;
  for (int b = 0; b < kBatches; ++b) {
    for (int i = 0; i < kPerBatch; ++i) ASSERT_TRUE(attacker->sendTo(garbage(rng), robot->localEndpoint()));
    ASSERT_TRUE((*op)->sendGaze(gazeTowards(b + 1, 0, 1)));
    const uint64_t expect = robot_rx_before + static_cast<uint64_t>((b + 1) * (kPerBatch + 1));
    ASSERT_TRUE(pollUntil(*robot, [&] { return robot->counters().datagrams_received >= expect; })) << b;
    if (b % 3 == 0) {  // the operator takes a third as much garbage
      for (int i = 0; i < kPerBatch; ++i) ASSERT_TRUE(attacker->sendTo(garbage(rng), op_endpoint));
      ASSERT_EQ(robot->send(MessageType::kChunk, chunkPayload(300, static_cast<uint8_t>(b))), SendResult::kSent);
      ASSERT_TRUE(receiveType(**op, MessageType::kChunk)) << b;
      ++chunks;
    }
  }
  EXPECT_EQ(robot->counters().dropped.total(), static_cast<uint64_t>(kBatches * kPerBatch));
  EXPECT_EQ(robot->counters().gaze_accepted, static_cast<uint64_t>(kBatches));
  EXPECT_EQ(robot->latestGaze()->sample.sequence, static_cast<uint64_t>(kBatches));
  EXPECT_TRUE(robot->hasSession());
  EXPECT_EQ((*op)->counters().dropped.total(), static_cast<uint64_t>(chunks * kPerBatch));
  EXPECT_EQ((*op)->counters().datagrams_received - op_rx_before, static_cast<uint64_t>(chunks * (kPerBatch + 1)));
  EXPECT_EQ((*op)->counters().datagrams_lost, 0u);
}

}  // namespace
}  // namespace fovea::net

namespace fovea::net {
namespace {

// A key holder's hand-made Hello: the refusal names the reason and echoes the nonce.
RefuseMsg refusalOf(RobotLink& robot, const Key& key, const HelloMsg& hello) {
  RefuseMsg refuse;
  auto raw = UdpSocket::bind(Endpoint::parse("127.0.0.1:0").value());
  if (!raw) {
    ADD_FAILURE() << raw.status().toString();
    return refuse;
  }
  const DirectionKeys hs = handshakeKeys(key, Role::kOperator);
  SessionChannel channel(hs, randomU64(), 0);
  MessageEncoder encoder;
  std::array<uint8_t, kMaxMtu> out{};
  std::array<uint8_t, kMaxMtu + 1> in{};
  PlainBuffer plain;
  EXPECT_TRUE(raw->sendTo(channel.seal(MessageType::kHello, encoder.encode(hello), out), robot.localEndpoint()));
  const uint64_t refusals = robot.counters().refusals;
  for (int i = 0; i < 200 && robot.counters().refusals == refusals; ++i) robot.poll(5);
  EXPECT_TRUE(raw->waitReadable(500));
  Endpoint from;
  const long n = raw->receive(in, from);
  EXPECT_GT(n, 0);
  if (n <= 0) return refuse;
  const std::span<const uint8_t> d(in.data(), static_cast<std::size_t>(n));
  Header header;
  EXPECT_EQ(parseHeader(d, header), std::nullopt);
  EXPECT_EQ(header.type, MessageType::kRefuse);
  auto payload = openSealed(hs.rx, d, plain);
  EXPECT_TRUE(payload.has_value());
  if (payload) {
    EXPECT_EQ(decode(*payload, refuse), std::nullopt);
  }
  EXPECT_EQ(refuse.client_nonce, hello.client_nonce);
  return refuse;
}

TEST(Links, OtherVersionOrTinyMtuRefusedWithReason) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  HelloMsg hello;
  hello.operator_name.assign("future");
  hello.protocol_version = kProtocolVersion + 1;
  hello.client_nonce = randomNonce128();
  RefuseMsg r = refusalOf(*robot, key, hello);
  EXPECT_EQ(r.reason, RefuseReason::kVersion);
  EXPECT_NE(r.text.view().find("version"), std::string_view::npos) << r.text.view();
  hello.protocol_version = kProtocolVersion;
  hello.mtu_bytes = 100;
  hello.client_nonce = randomNonce128();
  r = refusalOf(*robot, key, hello);
  EXPECT_EQ(r.reason, RefuseReason::kBadRequest);
  EXPECT_NE(r.text.view().find("MTU 100"), std::string_view::npos) << r.text.view();
  EXPECT_FALSE(robot->hasSession());
}

}  // namespace
}  // namespace fovea::net

namespace fovea::net {
namespace {

TEST(Links, OperatorReceiveReturnsOnTimeDuringAFlood) {
  const Key key = generateKey();
  auto robot = makeRobot(key);
  ASSERT_TRUE(robot);
  auto op = connectWhilePolling(*robot, robot->localEndpoint().toString(), operatorConfig(key, "alice"));
  ASSERT_TRUE(op) << op.status().toString();
  const Endpoint op_endpoint = Endpoint::parse("127.0.0.1:" + std::to_string((*op)->localPort())).value();
  std::atomic<bool> stop{false};
  std::thread flood([&] {
    auto attacker = UdpSocket::bind(Endpoint::parse("127.0.0.1:0").value());
    std::array<uint8_t, 64> junk{};
    const auto end = std::chrono::steady_clock::now() + 3s;  // bounded even if the test fails
    while (!stop && std::chrono::steady_clock::now() < end) (void)attacker->sendTo(junk, op_endpoint);
  });
  for (int i = 0; i < 300 && (*op)->counters().datagrams_received < 100; ++i) (void)(*op)->receive(10);
  const auto start = std::chrono::steady_clock::now();
  EXPECT_FALSE((*op)->receive(50));
  const auto elapsed = std::chrono::steady_clock::now() - start;
  stop = true;
  flood.join();
  EXPECT_LT(elapsed, test::scaled(1s));
  EXPECT_GT((*op)->counters().dropped[DropReason::kBadMagic], 100u);
}

}  // namespace
}  // namespace fovea::net
