// The streamer's reading of the operator's gaze (what the foveation stage gets):
// the eye from the gaze sample, and the head's forward axis from the HMD
// orientation (its z axis turned into the world, docs/protocol.md), which
// ACUITY's view cull uses. An operator over loopback sends the samples.
#include "core/clock.h"
#include "firmware/streamer.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <thread>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "net/operator_link.h"
#include "tests/support/test_time.h"

namespace fovea::firmware {
namespace {

using namespace std::chrono_literals;

TEST(Streamer, OperatorGazeCarriesTheEyeAndTheHeadsForwardAxis) {
  StreamConfig config;
  config.link.listen = "127.0.0.1:0";
  config.link.insecure = true;
  Result<std::unique_ptr<Streamer>> created = Streamer::create(config, 1000);
  ASSERT_TRUE(created) << created.status().message();
  Streamer& streamer = *created.value();
  OperatorGaze gaze;
  EXPECT_FALSE(streamer.operatorGaze(gaze));  // nobody there
  EXPECT_FALSE(gaze.valid);

  // The robot answers the hello while the operator connects.
  std::atomic<bool> stop{false};
  std::thread robot([&] {
    while (!stop.load()) streamer.idleUntil(monotonicNs() + 2'000'000);
  });
  net::OperatorLinkConfig op_config;
  op_config.insecure = true;
  op_config.connect_timeout_ms = static_cast<int>(test::scaled(3000ms).count());
  Result<std::unique_ptr<net::OperatorLink>> op =
      net::OperatorLink::connect(streamer.localEndpoint().toString(), op_config);
  stop.store(true);
  robot.join();
  ASSERT_TRUE(op) << op.status().message();

  // Heads turned: 90 degrees about y (forward = +x), 30 degrees about x, and a
  // quaternion 2e-4 off unit length (within the protocol's tolerance).
  const Eigen::Quaterniond heads[] = {Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY())),
                                      Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 6, Eigen::Vector3d::UnitX())),
                                      Eigen::Quaterniond(1.0002, 0.0, 0.0, 0.0)};
  uint64_t sequence = 0;
  for (const Eigen::Quaterniond& head : heads) {
    net::GazeSample s;
    s.sequence = ++sequence;
    s.operator_stamp_ns = 1'000'000 * static_cast<int64_t>(sequence);
    s.gaze_origin_m = {3.0, 0.35, 1.55};
    s.gaze_direction = {0.0, 0.6, 0.8};
    s.hmd_position_m = {3.0, 0.35, 1.6};
    s.hmd_orientation = {head.w(), head.x(), head.y(), head.z()};
    ASSERT_TRUE((*op)->sendGaze(s));
    ASSERT_TRUE(test::waitUntil(
        [&] {
          streamer.poll();
          return streamer.operatorGaze(gaze) && gaze.stamp_ns == s.operator_stamp_ns;
        },
        3000ms));
    const Eigen::Vector3d expected = head.normalized() * Eigen::Vector3d::UnitZ();
    EXPECT_TRUE(gaze.valid);
    EXPECT_TRUE(gaze.gaze.view_known);
    EXPECT_LT((gaze.gaze.view_forward - expected).norm(), 1e-12) << gaze.gaze.view_forward.transpose();
    EXPECT_NEAR(gaze.gaze.view_forward.norm(), 1.0, 1e-12);
    EXPECT_EQ(gaze.gaze.origin_m, Eigen::Vector3d(3.0, 0.35, 1.55));
    EXPECT_EQ(gaze.gaze.direction, Eigen::Vector3d(0.0, 0.6, 0.8));
    EXPECT_GT(gaze.received_ns, 0);
  }
  EXPECT_NEAR(gaze.gaze.view_forward.z(), 1.0, 1e-12);  // the last head looks along +z

  // A station that does not know where the eye is (confidence 0): no operator gaze.
  net::GazeSample blind;
  blind.sequence = ++sequence;
  blind.operator_stamp_ns = 99'000'000;
  blind.confidence = 0.0f;
  ASSERT_TRUE((*op)->sendGaze(blind));
  EXPECT_TRUE(test::waitUntil(
      [&] {
        streamer.poll();
        return !streamer.operatorGaze(gaze);
      },
      3000ms));
  EXPECT_FALSE(gaze.valid);
}

// The token bucket's burst: by default (burst_ms 0) one frame period of the
// session's budget, so a frame that fits the budget over a period leaves at
// once; burst_ms > 0 sets it in milliseconds. Both as a budget times a time,
// read from the scheduler (nothing timed).
TEST(Streamer, BurstIsOneFramePeriodOfTheBudgetByDefault) {
  for (const double burst_ms : {0.0, 5.0}) {
    StreamConfig config;
    config.link.listen = "127.0.0.1:0";
    config.link.insecure = true;
    config.burst_ms = burst_ms;
    Result<std::unique_ptr<Streamer>> created = Streamer::create(config, 1000);
    ASSERT_TRUE(created) << created.status().message();
    Streamer& streamer = *created.value();
    std::atomic<bool> stop{false};
    std::thread robot([&] {
      while (!stop.load()) streamer.idleUntil(monotonicNs() + 2'000'000);
    });
    net::OperatorLinkConfig op_config;
    op_config.insecure = true;
    op_config.connect_timeout_ms = static_cast<int>(test::scaled(3000ms).count());
    op_config.budget_bytes_per_s = 12'500'000;
    Result<std::unique_ptr<net::OperatorLink>> op =
        net::OperatorLink::connect(streamer.localEndpoint().toString(), op_config);
    stop.store(true);
    robot.join();
    ASSERT_TRUE(op) << op.status().message();
    pipeline::FoveatedCloud cloud{16};
    for (int i = 0; i < 4; ++i) ASSERT_TRUE(cloud.points.push(0.1f * static_cast<float>(i), 0.0f, 1.0f, 0x808080));
    std::fill_n(cloud.region.begin(), 4, uint8_t{0});
    std::fill_n(cloud.weight.begin(), 4, 1u);
    pipeline::FoveationStats stats;
    stats.region_count = 1;
    const int64_t now = monotonicNs();
    Result<FrameSendReport> sent = streamer.sendFrame(cloud, stats, 1, now, now + 30'000'000, 40'000'000);
    ASSERT_TRUE(sent) << sent.status().message();
    ASSERT_TRUE(sent->had_session);
    const double budget = static_cast<double>(streamer.sessionBudgetBytesPerS());
    EXPECT_EQ(budget, 12'500'000.0);
    EXPECT_DOUBLE_EQ(streamer.burstBytes(), budget * (burst_ms > 0 ? burst_ms * 1e-3 : 0.040)) << burst_ms;
  }
}

}  // namespace
}  // namespace fovea::firmware
