// Once a session runs, datagrams in and out allocate nothing: gaze, chunks,
// status, and garbage that is dropped (docs/protocol.md).
#include <gtest/gtest.h>

#include <array>
#include <future>
#include <random>

#include "net/operator_link.h"
#include "net/robot_link.h"
#include "tests/support/alloc_counter.h"

namespace fovea::net {
namespace {

TEST(LinksZeroAlloc, SessionTrafficAllocatesNothing) {
  const Key key = generateKey();
  RobotLinkConfig robot_config;
  robot_config.listen = "127.0.0.1:0";
  robot_config.key = key;
  auto robot_result = RobotLink::create(robot_config);
  ASSERT_TRUE(robot_result) << robot_result.status().toString();
  RobotLink& robot = *robot_result.value();
  OperatorLinkConfig op_config;
  op_config.key = key;
  op_config.first_retry_ms = 20;
  const std::string address = robot.localEndpoint().toString();
  auto pending = std::async(std::launch::async, [&] { return OperatorLink::connect(address, op_config); });
  while (pending.wait_for(std::chrono::milliseconds(0)) != std::future_status::ready) robot.poll(1);
  auto op_result = pending.get();
  ASSERT_TRUE(op_result) << op_result.status().toString();
  OperatorLink& op = *op_result.value();
  auto attacker = UdpSocket::bind(Endpoint::parse("127.0.0.1:0").value());
  ASSERT_TRUE(attacker);
  const Endpoint robot_endpoint = robot.localEndpoint();

  std::array<uint8_t, 1000> chunk{};
  std::array<uint8_t, 700> junk{};
  std::mt19937 rng(5);
  GazeSample gaze;
  StatusReport status;
  int delivered = 0;
  uint64_t allocations = 0;
  auto round = [&] {
    for (auto& b : junk) b = static_cast<uint8_t>(rng());
    const uint64_t target = robot.counters().datagrams_received + 2;
    (void)attacker->sendTo(junk, robot_endpoint);
    (void)op.sendGaze(gaze);
    for (int i = 0; i < 200 && robot.counters().datagrams_received < target; ++i) robot.poll(5);
    (void)robot.send(MessageType::kChunk, chunk);
    (void)robot.sendStatus(status);
    for (int k = 0; k < 2; ++k) delivered += op.receive(100).has_value();
  };
  round();  // warm-up: the encoders' buffers are allocated on first use
  {
    test::AllocationScope scope;
    for (int i = 0; i < 50; ++i) round();
    allocations = scope.allocations();
  }
  EXPECT_EQ(allocations, 0u);
  EXPECT_EQ(delivered, 2 * 51);
  EXPECT_EQ(robot.counters().gaze_accepted, 51u);
  EXPECT_EQ(robot.counters().dropped.total(), 51u);
}

}  // namespace
}  // namespace fovea::net
