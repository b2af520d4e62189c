// io/foxglove: each encoder's bytes decoded back with libprotobuf's generated
// classes, field by field; the embedded schemas parse as FileDescriptorSets
// naming their message; steady-state encoding allocates nothing.
#include <cmath>
#include <cstring>

#include <google/protobuf/descriptor.pb.h>
#include <gtest/gtest.h>

#include "foxglove/FrameTransform.pb.h"
#include "foxglove/Log.pb.h"
#include "foxglove/PointCloud.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "io/foxglove/foxglove.h"
#include "tests/support/alloc_counter.h"

namespace fovea::foxglove {
namespace {

template <typename M>
M parse(std::span<const uint8_t> bytes) {
  M m;
  EXPECT_TRUE(m.ParseFromArray(bytes.data(), static_cast<int>(bytes.size())));
  return m;
}

pipeline::PointCloud sampleCloud(std::size_t n) {
  pipeline::PointCloud c(n);
  c.origin_m = {1000.5, -2.25, 3.0};
  for (std::size_t i = 0; i < n; ++i) {
    const float f = static_cast<float>(i);
    EXPECT_TRUE(c.push(0.1f * f, -0.2f * f, 1.5f + f, pipeline::packRgb(static_cast<uint8_t>(i), 0x80, 0xfe)));
  }
  return c;
}

TEST(FoxgloveSchemas, AreFileDescriptorSetsWithTheirMessage) {
  for (const Schema& s : {pointCloudSchema(), frameTransformSchema(), logSchema(), sceneUpdateSchema()}) {
    SCOPED_TRACE(std::string(s.name));
    EXPECT_EQ(s.encoding, "protobuf");
    ASSERT_FALSE(s.data.empty());
    google::protobuf::FileDescriptorSet set;
    ASSERT_TRUE(set.ParseFromArray(s.data.data(), static_cast<int>(s.data.size())));
    bool found = false;
    bool timestamp = false;
    for (const auto& file : set.file()) {
      timestamp |= file.name() == "google/protobuf/timestamp.proto";
      for (const auto& m : file.message_type()) found |= file.package() + "." + m.name() == s.name;
    }
    EXPECT_TRUE(found);
    EXPECT_TRUE(timestamp);  // imports included
  }
  EXPECT_TRUE(schemaData("foxglove.Nothing").empty());
}

TEST(FoxglovePointCloud, DecodesFieldByField) {
  const pipeline::PointCloud cloud = sampleCloud(100);
  PointCloudEncoder enc;
  const auto m = parse<::foxglove::PointCloud>(enc.encode(cloud, "world", 1'700'000'000'123'456'789));
  EXPECT_EQ(m.timestamp().seconds(), 1'700'000'000);
  EXPECT_EQ(m.timestamp().nanos(), 123'456'789);
  EXPECT_EQ(m.frame_id(), "world");
  EXPECT_EQ(m.pose().position().x(), 1000.5);
  EXPECT_EQ(m.pose().position().y(), -2.25);
  EXPECT_EQ(m.pose().orientation().w(), 1.0);
  EXPECT_EQ(m.point_stride(), 16u);
  ASSERT_EQ(m.fields_size(), 4);
  EXPECT_EQ(m.fields(0).name(), "x");
  EXPECT_EQ(m.fields(2).name(), "z");
  EXPECT_EQ(m.fields(2).offset(), 8u);
  EXPECT_EQ(m.fields(0).type(), ::foxglove::PackedElementField::FLOAT32);
  EXPECT_EQ(m.fields(3).name(), "rgba");
  EXPECT_EQ(m.fields(3).type(), ::foxglove::PackedElementField::UINT32);
  ASSERT_EQ(m.data().size(), 100u * 16u);
  for (std::size_t i = 0; i < 100; ++i) {
    float x, y, z;
    uint32_t rgba;
    std::memcpy(&x, m.data().data() + i * 16, 4);
    std::memcpy(&y, m.data().data() + i * 16 + 4, 4);
    std::memcpy(&z, m.data().data() + i * 16 + 8, 4);
    std::memcpy(&rgba, m.data().data() + i * 16 + 12, 4);  // little-endian hosts (x86-64, aarch64)
    ASSERT_EQ(x, cloud.x()[i]);
    ASSERT_EQ(y, cloud.y()[i]);
    ASSERT_EQ(z, cloud.z()[i]);
    ASSERT_EQ(rgba, 0xff000000u | (static_cast<uint32_t>(i) << 16) | 0x80feu) << i;  // 0xAARRGGBB
  }
  // A smaller cloud after a larger one: no stale points.
  const auto small = parse<::foxglove::PointCloud>(enc.encode(sampleCloud(3), "map", -1));
  EXPECT_EQ(small.data().size(), 48u);
  EXPECT_EQ(small.frame_id(), "map");
  EXPECT_EQ(small.timestamp().seconds(), -1);
  EXPECT_EQ(small.timestamp().nanos(), 999'999'999);
}

TEST(FoxgloveFrameTransform, DecodesFieldByField) {
  FrameTransformEncoder enc;
  const auto m = parse<::foxglove::FrameTransform>(enc.encode("world", "head", {1, 2, 3}, {0.5, 0.5, -0.5, 0.5}, 42));
  EXPECT_EQ(m.parent_frame_id(), "world");
  EXPECT_EQ(m.child_frame_id(), "head");
  EXPECT_EQ(m.translation().x(), 1);
  EXPECT_EQ(m.translation().z(), 3);
  EXPECT_EQ(m.rotation().w(), 0.5);
  EXPECT_EQ(m.rotation().y(), -0.5);
  EXPECT_EQ(m.timestamp().nanos(), 42);
}

TEST(FoxgloveLog, DecodesFieldByField) {
  LogEncoder enc;
  const auto m = parse<::foxglove::Log>(enc.encode(LogLevel::kWarning, "robot gone", "fovea-operator", 5'000'000'001));
  EXPECT_EQ(m.level(), ::foxglove::Log::WARNING);
  EXPECT_EQ(m.message(), "robot gone");
  EXPECT_EQ(m.name(), "fovea-operator");
  EXPECT_EQ(m.timestamp().seconds(), 5);
  EXPECT_EQ(m.timestamp().nanos(), 1);
}

TEST(FoxgloveGazeRay, ArrowFromTheEyeAlongTheGaze) {
  GazeRayEncoder enc;
  struct Case {
    std::array<double, 3> d;
  };
  for (const Case c : {Case{{0, 0, 2}}, Case{{1, 0, 0}}, Case{{-1, 0, 0}}, Case{{0.3, -0.4, 0.5}}}) {
    const auto m = parse<::foxglove::SceneUpdate>(enc.encode("world", {0.1, 0.2, 0.3}, c.d, 2.0, 7));
    ASSERT_EQ(m.entities_size(), 1);
    const auto& e = m.entities(0);
    EXPECT_EQ(e.id(), "gaze");
    EXPECT_EQ(e.frame_id(), "world");
    ASSERT_EQ(e.arrows_size(), 1);
    const auto& a = e.arrows(0);
    EXPECT_EQ(a.pose().position().y(), 0.2);
    EXPECT_NEAR(a.shaft_length() + a.head_length(), 2.0, 1e-12);
    // The pose's +x, rotated, is the normalised direction.
    const auto& q = a.pose().orientation();
    const double w = q.w(), x = q.x(), y = q.y(), z = q.z();
    const double rx = 1 - 2 * (y * y + z * z), ry = 2 * (x * y + w * z), rz = 2 * (x * z - w * y);
    const double n = std::sqrt(c.d[0] * c.d[0] + c.d[1] * c.d[1] + c.d[2] * c.d[2]);
    EXPECT_NEAR(rx, c.d[0] / n, 1e-9);
    EXPECT_NEAR(ry, c.d[1] / n, 1e-9);
    EXPECT_NEAR(rz, c.d[2] / n, 1e-9);
  }
}

TEST(FoxgloveEncoders, SteadyStateAllocatesNothing) {
  const pipeline::PointCloud big = sampleCloud(50'000);
  const pipeline::PointCloud small = sampleCloud(10'000);
  PointCloudEncoder cloud;
  FrameTransformEncoder tf;
  LogEncoder log;
  GazeRayEncoder gaze;
  const std::string_view line = "12.0 fps | 1.20 MB/s | latency p50 3.1 ms p99 5.2 ms | lost 0 | points 1 2 3 4";
  auto round = [&](int64_t t) {
    std::size_t bytes = cloud.encode(big, "world", t).size();
    bytes += cloud.encode(small, "world", t).size();
    bytes += tf.encode("world", "head", {1, 2, 3}, {1, 0, 0, 0}, t).size();
    bytes += log.encode(LogLevel::kInfo, line, "fovea-operator", t).size();
    bytes += gaze.encode("world", {0, 0, 0}, {0, 0, 1}, 2.0, t).size();
    return bytes;
  };
  const std::size_t warm = round(1'000'000'000);
  test::AllocationScope scope;
  std::size_t bytes = 0;
  for (int i = 1; i <= 20; ++i) bytes += round(1'000'000'000LL * i);
  EXPECT_EQ(scope.allocations(), 0u);
  EXPECT_EQ(bytes, 20 * warm);
}

}  // namespace
}  // namespace fovea::foxglove
