// The last fused frame's explained view (pipeline/map/explained_view.h): the
// fused frame judged against its own view leaves exactly what the map's
// appendUnexplained() leaves; a later frame it was not fused from is thinned
// as a brute-force reprojection written here (in double) thins it; and the
// hard cases: no view, a frame larger than the view's size, points behind the
// view's camera or not finite, and a map 10 km from the world origin.
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "core/depth_noise.h"
#include "pipeline/backproject.h"
#include "pipeline/map/explained_view.h"
#include "pipeline/map/surfel_map.h"
#include "tests/support/cameras.h"
#include "tests/support/test_time.h"

namespace fovea::pipeline::map {
namespace {

constexpr int kW = 320, kH = 240;

// The mock living room on its orbit, fused frame by frame, the view captured
// after each as the mapper does (mapper.cpp).
struct Fused {
  std::unique_ptr<hal::Camera> camera = test::startedCamera("mock:living-room,size=320x240,path=orbit");
  SurfelMap map = SurfelMap::create(config()).value();
  ExplainedView view = ExplainedView::create(kW, kH, config().depth_tolerance_sigmas).value();
  hal::RgbdFrame frame{kW, kH};

  static SurfelMapConfig config() {
    SurfelMapConfig c;
    c.max_width = kW;
    c.max_height = kH;
    c.max_surfels = 1 << 19;
    c.max_bricks = 4096;
    return c;
  }
  // The camera's next frame, not fused.
  void next() {
    ASSERT_TRUE(camera->acquire(frame, test::scaled(std::chrono::seconds(1))).isOk());
  }
  void fuseNext() {
    next();
    FuseStats stats;
    ASSERT_EQ(map.fuse(frame, stats), FuseOutcome::kFused);
    view.capture(frame, map.explainedPixels());
  }
};

// The frame back-projected whole, in the map's depth range.
PointCloud whole(const hal::RgbdFrame& frame) {
  PointCloud cloud(static_cast<std::size_t>(kW) * kH);
  BackprojectCounts counts;
  EXPECT_TRUE(backprojectRef(frame, Fused::config().depth, cloud, counts).isOk());
  return cloud;
}

// Fusion is the slow part (half a minute under the sanitizers and qemu), so
// the suite fuses once: 14 frames, the last of them kept as `fused`, then the
// camera's next three frames, not fused, as `later`. The tests only read it.
class ExplainedViewTest : public ::testing::Test {
 protected:
  static constexpr int kFusedFrames = 14;
  static constexpr int kLaterFrames = 3;

  static void SetUpTestSuite() {
    fused_ = new Fused;
    ASSERT_TRUE(fused_->camera);
    for (int i = 0; i < kFusedFrames; ++i) ASSERT_NO_FATAL_FAILURE(fused_->fuseNext());
    fused_frame_ = new hal::RgbdFrame(fused_->frame);
    later_ = new std::vector<hal::RgbdFrame>;
    for (int i = 0; i < kLaterFrames; ++i) {
      ASSERT_NO_FATAL_FAILURE(fused_->next());  // the camera moved on: not fused
      later_->push_back(fused_->frame);
    }
  }
  static void TearDownTestSuite() {
    delete later_;
    delete fused_frame_;
    delete fused_;
    later_ = nullptr;
    fused_frame_ = nullptr;
    fused_ = nullptr;
  }
  void SetUp() override {
    ASSERT_TRUE(fused_ != nullptr && later_ != nullptr && later_->size() == kLaterFrames) << "the suite's fusion failed";
  }

  static const SurfelMap& map() { return fused_->map; }
  static const ExplainedView& view() { return fused_->view; }
  static const hal::RgbdFrame& fusedFrame() { return *fused_frame_; }
  static const std::vector<hal::RgbdFrame>& later() { return *later_; }

 private:
  static Fused* fused_;
  static hal::RgbdFrame* fused_frame_;
  static std::vector<hal::RgbdFrame>* later_;
};

Fused* ExplainedViewTest::fused_ = nullptr;
hal::RgbdFrame* ExplainedViewTest::fused_frame_ = nullptr;
std::vector<hal::RgbdFrame>* ExplainedViewTest::later_ = nullptr;

TEST_F(ExplainedViewTest, TheFusedFrameJudgedAgainstItsOwnViewLeavesWhatTheMapLeaves) {
  PointCloud unexplained(static_cast<std::size_t>(kW) * kH);
  unexplained.origin_m = fusedFrame().T_world_cam.t_world_cam;
  const std::size_t left = map().appendUnexplained(fusedFrame(), unexplained);
  PointCloud cloud = whole(fusedFrame());
  const std::size_t valid = cloud.size();
  const std::size_t removed = view().removeExplained(cloud);
  EXPECT_GT(removed, valid / 2) << "after 14 frames the settled map explains most of the view";
  ASSERT_EQ(cloud.size(), left);
  ASSERT_EQ(removed + left, valid);
  // The same pixels in the same (row) order: the same points, up to float rounding.
  for (std::size_t i = 0; i < left; ++i) {
    ASSERT_NEAR(cloud.x()[i], unexplained.x()[i], 1e-5) << i;
    ASSERT_NEAR(cloud.y()[i], unexplained.y()[i], 1e-5) << i;
    ASSERT_NEAR(cloud.z()[i], unexplained.z()[i], 1e-5) << i;
    ASSERT_EQ(cloud.rgb()[i], unexplained.rgb()[i]) << i;
  }
}

// The reference: each point into the view's camera in double, the nearest
// pixel, explained there and within sqrt(2) times the association's tolerance
// of its measured depth.
std::vector<bool> explainedByBruteForce(const PointCloud& cloud, const hal::RgbdFrame& view_frame,
                                        const SurfelMap& map) {
  const hal::CameraIntrinsics& k = view_frame.intrinsics;
  const hal::Pose& pose = view_frame.T_world_cam;
  const double tolerance = std::sqrt(2.0) * map.config().depth_tolerance_sigmas;
  std::vector<bool> explained(cloud.size(), false);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d q = pose.R_world_cam.transpose() * (cloud.world(i) - pose.t_world_cam);
    if (q.z() <= 0.0) continue;
    const double u = k.fx * q.x() / q.z() + k.cx, v = k.fy * q.y() / q.z() + k.cy;
    const long iu = std::lround(u), iv = std::lround(v);
    if (iu < 0 || iv < 0 || iu >= view_frame.width() || iv >= view_frame.height()) continue;
    const std::size_t p = static_cast<std::size_t>(iv) * view_frame.width() + static_cast<std::size_t>(iu);
    const double seen = map.measuredDepth()[p];
    explained[i] = map.explainedPixels()[p] && seen > 0.0 && std::abs(q.z() - seen) <= tolerance * depthSigma(seen);
  }
  return explained;
}

TEST_F(ExplainedViewTest, ALaterFrameIsThinnedAsABruteForceReprojectionThinsIt) {
  for (int later = 1; later <= kLaterFrames; ++later) {
    const PointCloud all = whole(this->later()[static_cast<std::size_t>(later - 1)]);
    const std::vector<bool> expected = explainedByBruteForce(all, fusedFrame(), map());
    PointCloud cloud = all;
    const std::size_t removed = view().removeExplained(cloud);
    // Walk both: the kept points are the reference's unexplained ones, in order;
    // a point the float and the double arithmetic round to different pixels or
    // sides of the tolerance may differ (at most 0.2 % of them).
    std::size_t j = 0, differ = 0, expected_removed = 0;
    for (std::size_t i = 0; i < all.size(); ++i) {
      expected_removed += expected[i] ? 1 : 0;
      const bool kept = j < cloud.size() && cloud.x()[j] == all.x()[i] && cloud.y()[j] == all.y()[i] &&
                        cloud.z()[j] == all.z()[i];
      if (kept) ++j;
      if (kept == expected[i]) ++differ;
    }
    EXPECT_EQ(j, cloud.size()) << "every kept point is one of the frame's, in order";
    EXPECT_LE(differ, all.size() / 500) << "frame +" << later;
    EXPECT_GT(expected_removed, all.size() / 3) << "frame +" << later << ": the map explains much of a nearby view";
    EXPECT_LT(expected_removed, all.size()) << "frame +" << later << ": the moved view sees something new";
    EXPECT_EQ(removed + cloud.size(), all.size());
  }
}

// Records what visitUnexplained() offers, as a cloud.
struct CloudSink final : LivePointSink {
  PointCloud cloud{static_cast<std::size_t>(kW) * kH};
  bool take(int, int, const Eigen::Vector3f& p, uint32_t rgb) override { return cloud.push(p.x(), p.y(), p.z(), rgb); }
};

TEST_F(ExplainedViewTest, VisitingAFramesPixelsOffersWhatRemovingFromItsWholeCloudKeeps) {
  const ExplainedView none = ExplainedView::create(kW, kH, Fused::config().depth_tolerance_sigmas).value();
  for (const ExplainedView* judge : {&view(), &none}) {
    for (const hal::RgbdFrame& frame : later()) {
      PointCloud kept = whole(frame);
      const std::size_t valid = kept.size();
      const std::size_t removed = judge->removeExplained(kept);
      CloudSink offered;
      ExplainedView::VisitCounts counts;
      judge->visitUnexplained(frame, PixelBackprojection(frame, Fused::config().depth), offered, counts);
      EXPECT_EQ(counts.valid, valid);
      EXPECT_EQ(counts.explained, removed);
      ASSERT_EQ(offered.cloud.size(), kept.size());
      for (std::size_t i = 0; i < kept.size(); ++i) {  // the same bits, in the same order
        ASSERT_EQ(offered.cloud.x()[i], kept.x()[i]) << i;
        ASSERT_EQ(offered.cloud.y()[i], kept.y()[i]) << i;
        ASSERT_EQ(offered.cloud.z()[i], kept.z()[i]) << i;
        ASSERT_EQ(offered.cloud.rgb()[i], kept.rgb()[i]) << i;
      }
    }
  }
  // A sink that says stop is offered no more.
  struct StopAtThree final : LivePointSink {
    int taken = 0;
    bool take(int, int, const Eigen::Vector3f&, uint32_t) override { return ++taken < 3; }
  } stop;
  ExplainedView::VisitCounts counts;
  none.visitUnexplained(later()[0], PixelBackprojection(later()[0], Fused::config().depth), stop, counts);
  EXPECT_EQ(stop.taken, 3);
}

TEST_F(ExplainedViewTest, HardCases) {
  // No view yet: nothing is explained.
  ExplainedView none = ExplainedView::create(kW, kH, Fused::config().depth_tolerance_sigmas).value();
  PointCloud cloud = whole(later()[0]);
  const std::size_t valid = cloud.size();
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(none.removeExplained(cloud), 0u);
  EXPECT_EQ(cloud.size(), valid);
  PointCloud at_origin = whole(fusedFrame());
  const std::size_t whole_at_origin = at_origin.size();
  const std::size_t removed_at_origin = view().removeExplained(at_origin);
  const std::size_t kept_at_origin = at_origin.size();
  ASSERT_EQ(kept_at_origin + removed_at_origin, whole_at_origin);
  ASSERT_GT(kept_at_origin, 0u);
  ASSERT_GT(removed_at_origin, 0u);
  // 10 km away: the view and the cloud moved together judge alike.
  const Eigen::Vector3d far(1e4, -1e4, 1e4);
  ExplainedView far_view = ExplainedView::create(kW, kH, Fused::config().depth_tolerance_sigmas).value();
  hal::RgbdFrame far_frame = fusedFrame();
  far_frame.T_world_cam.t_world_cam += far;
  far_view.capture(far_frame, map().explainedPixels());
  PointCloud far_cloud = whole(fusedFrame());
  far_cloud.origin_m += far;
  EXPECT_EQ(far_view.removeExplained(far_cloud), removed_at_origin);
  EXPECT_EQ(far_cloud.size(), kept_at_origin);
  // Points behind the camera, at it, and not finite are never explained.
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  PointCloud odd(4);
  odd.origin_m = fusedFrame().T_world_cam.t_world_cam;
  const Eigen::Vector3f behind = (fusedFrame().T_world_cam.R_world_cam * Eigen::Vector3d(0, 0, -2)).cast<float>();
  ASSERT_TRUE(odd.push(behind.x(), behind.y(), behind.z(), 0));
  ASSERT_TRUE(odd.push(0, 0, 0, 0));
  ASSERT_TRUE(odd.push(nan, 0, 1, 0));
  ASSERT_TRUE(odd.push(inf, inf, inf, 0));
  EXPECT_EQ(view().removeExplained(odd), 0u);
  EXPECT_EQ(odd.size(), 4u);
  // A frame larger than the view was made for empties it.
  ExplainedView emptied = view();
  hal::RgbdFrame large(2 * kW, kH);
  ASSERT_TRUE(large.setSize(2 * kW, kH));
  std::vector<uint8_t> explained(large.pixelCount(), 1);
  std::fill(large.depth(), large.depth() + large.pixelCount(), uint16_t{1000});
  emptied.capture(large, explained.data());
  EXPECT_TRUE(emptied.empty());
  PointCloud again = whole(fusedFrame());
  EXPECT_EQ(emptied.removeExplained(again), 0u);
}

// The nearest pixel without libm's lround: the same index for every float
// above -0.5, the halves and the floats beside them included.
TEST(ViewJudge, TheNearestPixelIsLroundsAboveMinusAHalf) {
  std::vector<float> values = {-0.49999997f, -0.25f, -0.0f, 0.0f, 0.49999997f, 0.5f, 0.50000006f, 1.5f,
                               2.5f, 638.5f, 639.49997f, 16777215.0f};
  for (int k = 0; k < 2000; ++k) {
    const float half = static_cast<float>(k) + 0.5f;
    values.push_back(half);
    values.push_back(std::nextafter(half, 0.0f));
    values.push_back(std::nextafter(half, 1e9f));
  }
  for (float c : values) {
    ASSERT_EQ(nearestPixel(c), static_cast<std::size_t>(std::lround(c))) << c;
  }
}

TEST(ExplainedView, RefusesABadSizeOrTolerance) {
  EXPECT_FALSE(ExplainedView::create(0, kH, 3.0).isOk());
  EXPECT_FALSE(ExplainedView::create(kW, -1, 3.0).isOk());
  EXPECT_FALSE(ExplainedView::create(kW, kH, 0.0).isOk());
  EXPECT_FALSE(ExplainedView::create(kW, kH, std::numeric_limits<double>::quiet_NaN()).isOk());
  EXPECT_TRUE(ExplainedView::create(kW, kH, 3.0).isOk());
}

}  // namespace
}  // namespace fovea::pipeline::map
