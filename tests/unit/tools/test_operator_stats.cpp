// fovea-operator's statistics: quantiles against hand-counted ranks, windows, JSON.
#include "tools/operator/operator_stats.h"

#include <gtest/gtest.h>

#include <cmath>

namespace fovea::tools {
namespace {

TEST(Quantile, NearestRank) {
  EXPECT_TRUE(std::isnan(quantile({}, 0.5)));
  EXPECT_EQ(quantile({7}, 0.0), 7);
  EXPECT_EQ(quantile({7}, 1.0), 7);
  // 1..100: p50 is the 50th value, p99 the 99th.
  std::vector<double> v;
  for (int i = 100; i >= 1; --i) v.push_back(i);
  EXPECT_EQ(quantile(v, 0.5), 50);
  EXPECT_EQ(quantile(v, 0.99), 99);
  EXPECT_EQ(quantile(v, 1.0), 100);
  EXPECT_EQ(quantile(v, 0.0), 1);
  EXPECT_EQ(quantile({1, 2, 3, 4}, 0.5), 2);
  EXPECT_EQ(quantile({1, 2, 3, 4}, 0.51), 3);
}

TEST(ClockOffset, RecoversARobotClockAheadOrBehind) {
  // The robot's clock runs 5 s ahead (then 3 s behind) of the operator's; a
  // status stamped at operator time 100 ms arrives 4 ms later (RTT 8 ms).
  for (int64_t offset : {int64_t{5'000'000'000}, int64_t{-3'000'000'000}}) {
    const int64_t sent_local = 100'000'000, rtt = 8'000'000;
    EXPECT_EQ(estimateClockOffsetNs(sent_local + offset, rtt, sent_local + rtt / 2), offset);
  }
  // An asymmetric path (1 ms out, 7 ms back) errs by half the asymmetry.
  EXPECT_EQ(estimateClockOffsetNs(100'000'000, 8'000'000, 100'000'000 + 1'000'000), 3'000'000);
}

TEST(OperatorStats, LiveWindowResetsSummaryKeepsAll) {
  OperatorStats stats;
  for (int i = 0; i < 10; ++i) stats.datagram(1000, i < 5 ? 28 : 48);  // IPv4, then IPv6 headers
  stats.lost(2);
  FrameObservation f;
  f.latency_ms = 12.5;
  f.points_per_region[0] = 100;
  f.points_per_region[2] = 50;
  f.chunks_received = 9;
  f.chunks_expected = 10;
  stats.frame(f);
  stats.frame(f);
  FrameObservation unknown = f;  // a frame whose latency is not known yet
  unknown.latency_ms = NAN;
  stats.frame(unknown);
  const std::string line = liveLine(stats.takeWindow(3.0));
  EXPECT_NE(line.find("fps   1.0"), std::string::npos) << line;
  EXPECT_NE(line.find("0.00 MB/s"), std::string::npos) << line;
  EXPECT_NE(line.find("p50   12.5"), std::string::npos) << line;
  EXPECT_NE(line.find("lost 2"), std::string::npos) << line;
  EXPECT_NE(line.find("r0=100 r2=50"), std::string::npos) << line;
  EXPECT_NE(liveLine(stats.takeWindow(1.0)).find("fps   0.0"), std::string::npos);  // a fresh window

  const std::string json = stats.summaryJson(4.0, "\"name\": \"x\"");
  EXPECT_NE(json.find("\"name\": \"x\","), std::string::npos) << json;
  EXPECT_NE(json.find("\"frames\": 3,"), std::string::npos) << json;
  EXPECT_NE(json.find("\"fps\": 0.75,"), std::string::npos) << json;
  EXPECT_NE(json.find("\"datagrams_lost\": 2,"), std::string::npos) << json;
  EXPECT_NE(json.find("\"wire_bytes\": 10000,"), std::string::npos) << json;
  EXPECT_NE(json.find("\"ip_udp_bytes\": 10380,"), std::string::npos) << json;  // 10000 + 5 x 28 + 5 x 48
  EXPECT_NE(json.find("\"ip_udp_mb_per_s\": 0.002595,"), std::string::npos) << json;
  EXPECT_NE(json.find("\"chunks_expected\": 30,"), std::string::npos) << json;
  EXPECT_NE(json.find("\"p50\": 12.5"), std::string::npos) << json;
  EXPECT_NE(json.find("[100, 0, 50, 0"), std::string::npos) << json;
  // No frames: latency is null, not a number made up.
  EXPECT_NE(OperatorStats{}.summaryJson(1.0, "").find("\"p50\": null"), std::string::npos);
}

}  // namespace
}  // namespace fovea::tools
