// Back-projection against points worked out by hand.
#include <cmath>

#include <gtest/gtest.h>

#include "pipeline/backproject.h"

namespace fovea::pipeline {
namespace {

hal::RgbdFrame smallFrame() {
  hal::RgbdFrame frame(4, 3);
  frame.intrinsics = {4, 3, 2.0, 4.0, 1.5, 1.0};
  frame.depth_scale_m = 0.001;
  for (int i = 0; i < 12; ++i) {
    frame.depth()[i] = 1000;
    frame.rgb()[3 * i] = static_cast<uint8_t>(10 * i);
    frame.rgb()[3 * i + 1] = 7;
    frame.rgb()[3 * i + 2] = 200;
  }
  return frame;
}

TEST(Backproject, IdentityPoseGivesThePinholeRay) {
  hal::RgbdFrame frame = smallFrame();
  frame.depth()[1 * 4 + 3] = 2500;  // pixel (u=3, v=1) at 2.5 m
  PointCloud cloud(12);
  BackprojectCounts counts;
  ASSERT_TRUE(backprojectRef(frame, DepthRange{}, cloud, counts).isOk());
  ASSERT_EQ(cloud.size(), 12u);
  // Pixel (3, 1): x = (3 - 1.5) / 2 * 2.5 = 1.875, y = (1 - 1) / 4 * 2.5 = 0.
  EXPECT_FLOAT_EQ(cloud.x()[7], 1.875f);
  EXPECT_FLOAT_EQ(cloud.y()[7], 0.0f);
  EXPECT_FLOAT_EQ(cloud.z()[7], 2.5f);
  // Pixel (0, 0) at 1 m: x = -0.75, y = -0.25.
  EXPECT_FLOAT_EQ(cloud.x()[0], -0.75f);
  EXPECT_FLOAT_EQ(cloud.y()[0], -0.25f);
  EXPECT_EQ(cloud.rgb()[7], packRgb(70, 7, 200));
  EXPECT_EQ(counts.valid, 12u);
}

TEST(Backproject, PoseRotatesAndTheOriginCarriesTheTranslation) {
  hal::RgbdFrame frame = smallFrame();
  // Camera 10 km from the map origin, looking along world +x (z_cam -> x_world,
  // x_cam -> -y_world, y_cam -> -z_world).
  frame.T_world_cam.R_world_cam << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  frame.T_world_cam.t_world_cam = Eigen::Vector3d(10000.25, -5000.5, 12.0);
  PointCloud cloud(12);
  BackprojectCounts counts;
  ASSERT_TRUE(backprojectRef(frame, DepthRange{}, cloud, counts).isOk());
  EXPECT_EQ(cloud.origin_m, frame.T_world_cam.t_world_cam);
  // Pixel (0, 0): p_cam = (-0.75, -0.25, 1) -> p_world - origin = (1, 0.75, 0.25).
  EXPECT_FLOAT_EQ(cloud.x()[0], 1.0f);
  EXPECT_FLOAT_EQ(cloud.y()[0], 0.75f);
  EXPECT_FLOAT_EQ(cloud.z()[0], 0.25f);
  const Eigen::Vector3d w = cloud.world(0);
  EXPECT_DOUBLE_EQ(w.x(), 10001.25);
  EXPECT_DOUBLE_EQ(w.y(), -4999.75);
}

TEST(Backproject, SkipsZeroAndOutOfRangeDepth) {
  hal::RgbdFrame frame = smallFrame();
  frame.depth()[0] = 0;
  frame.depth()[1] = 99;     // 0.099 m < 0.1
  frame.depth()[2] = 100;    // exactly min: kept
  frame.depth()[3] = 10000;  // exactly max: kept
  frame.depth()[4] = 10001;  // beyond
  PointCloud cloud(12);
  BackprojectCounts counts;
  ASSERT_TRUE(backprojectRef(frame, DepthRange{0.1, 10.0}, cloud, counts).isOk());
  EXPECT_EQ(counts.no_depth, 1u);
  EXPECT_EQ(counts.out_of_range, 2u);
  EXPECT_EQ(counts.valid, 9u);
  EXPECT_FLOAT_EQ(cloud.z()[0], 0.1f);
  EXPECT_FLOAT_EQ(cloud.z()[1], 10.0f);
}

TEST(Backproject, TumDepthScale) {
  hal::RgbdFrame frame = smallFrame();
  frame.depth_scale_m = 1.0 / 5000.0;
  frame.depth()[0] = 10000;  // 2 m
  PointCloud cloud(12);
  BackprojectCounts counts;
  ASSERT_TRUE(backprojectRef(frame, DepthRange{}, cloud, counts).isOk());
  EXPECT_FLOAT_EQ(cloud.z()[0], 2.0f);
  EXPECT_FLOAT_EQ(cloud.z()[1], 0.2f);
}

TEST(Backproject, AllDepthInvalidGivesAnEmptyCloud) {
  hal::RgbdFrame frame = smallFrame();
  for (int i = 0; i < 12; ++i) frame.depth()[i] = 0;
  PointCloud cloud(12);
  BackprojectCounts counts;
  ASSERT_TRUE(backprojectRef(frame, DepthRange{}, cloud, counts).isOk());
  EXPECT_TRUE(cloud.empty());
  EXPECT_EQ(counts.no_depth, 12u);
}

TEST(Backproject, CapacityTooSmallIsAnErrorAndLeavesNothingHalfWritten) {
  hal::RgbdFrame frame = smallFrame();
  PointCloud cloud(5);
  BackprojectCounts counts;
  Status s = backprojectRef(frame, DepthRange{}, cloud, counts);
  EXPECT_EQ(s.code(), ErrorCode::kCapacityExceeded);
  EXPECT_TRUE(cloud.empty());
}

TEST(Backproject, RejectsUnusableFrames) {
  auto expectRejected = [](hal::RgbdFrame frame, const char* what) {
    PointCloud cloud(12);
    BackprojectCounts counts;
    Status s = backprojectRef(frame, DepthRange{}, cloud, counts);
    EXPECT_EQ(s.code(), ErrorCode::kInvalidInput) << what;
    EXPECT_TRUE(cloud.empty()) << what;
  };
  hal::RgbdFrame f = smallFrame();
  f.T_world_cam.t_world_cam.x() = NAN;
  expectRejected(f, "NaN translation");
  f = smallFrame();
  f.T_world_cam.R_world_cam(1, 1) = INFINITY;
  expectRejected(f, "Inf rotation");
  f = smallFrame();
  f.T_world_cam.R_world_cam(0, 0) = 2.0;
  expectRejected(f, "not a rotation");
  f = smallFrame();
  f.T_world_cam.R_world_cam(0, 0) = -1.0;
  expectRejected(f, "a reflection");
  f = smallFrame();
  f.intrinsics.fx = 0.0;
  expectRejected(f, "zero focal length");
  f = smallFrame();
  f.intrinsics.cy = NAN;
  expectRejected(f, "NaN principal point");
  f = smallFrame();
  f.depth_scale_m = NAN;
  expectRejected(f, "NaN depth scale");
  f = smallFrame();
  f.intrinsics.width = 8;
  expectRejected(f, "intrinsics for another size");
}

TEST(Backproject, RejectsBadDepthRange) {
  hal::RgbdFrame frame = smallFrame();
  PointCloud cloud(12);
  BackprojectCounts counts;
  EXPECT_EQ(backprojectRef(frame, DepthRange{2.0, 1.0}, cloud, counts).code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(backprojectRef(frame, DepthRange{NAN, 1.0}, cloud, counts).code(), ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace fovea::pipeline

namespace fovea::pipeline {
namespace {

TEST(Backproject, RawDepthRangeBracketsTheMetricRange) {
  RawDepthRange r = rawDepthRange(DepthRange{0.1, 10.0}, 0.001);
  EXPECT_EQ(r.min, 100);
  EXPECT_EQ(r.max, 10000);
  r = rawDepthRange(DepthRange{0.4, 8.0}, 1.0 / 5000.0);  // TUM units
  EXPECT_EQ(r.min, 2000);
  EXPECT_EQ(r.max, 40000);
  // Whatever the rounding of min/scale, the bounds are the tightest raw values in range.
  for (double scale : {0.001, 1.0 / 5000.0, 0.00025, 0.0123}) {
    for (double lo : {0.0, 0.1, 0.33, 0.7}) {
      const RawDepthRange b = rawDepthRange(DepthRange{lo, 7.77}, scale);
      EXPECT_GE(static_cast<double>(b.min) * scale, lo);
      if (b.min > 1) {
        EXPECT_LT(static_cast<double>(b.min - 1) * scale, lo);
      }
      EXPECT_LE(static_cast<double>(b.max) * scale, 7.77);
      if (b.max < 65535) {
        EXPECT_GT(static_cast<double>(b.max + 1) * scale, 7.77);
      }
    }
  }
  // A range beyond what uint16 depth can express: empty.
  r = rawDepthRange(DepthRange{70.0, 80.0}, 0.001);
  EXPECT_LT(r.max, r.min);
}

}  // namespace
}  // namespace fovea::pipeline
