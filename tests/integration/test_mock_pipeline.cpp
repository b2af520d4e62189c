// Camera -> back-projection -> foveation on the mock scenes: the output is a
// function of the scene and the gaze only.
#include <chrono>
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "hal/camera.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "tests/support/test_time.h"

namespace fovea {
namespace {

// Owns a camera and the buffers of one pipeline, all sized at construction.
class MockPipeline {
 public:
  MockPipeline(const std::string& spec, pipeline::Preset preset)
      : camera_(hal::createCamera(spec).value()), frame_(640, 480), cloud_(640 * 480), out_(640 * 480) {
    pipeline::FoveationConfig config;
    config.acuity.preset = preset;
    foveator_ = std::make_unique<pipeline::Foveator>(pipeline::Foveator::create({640 * 480, 640 * 480}, config).value());
    EXPECT_TRUE(camera_->open().isOk());
    EXPECT_TRUE(camera_->start().isOk());
  }

  // The next frame, foveated for a gaze from the camera towards the scene centre.
  const pipeline::FoveatedCloud& next() {
    EXPECT_TRUE(camera_->acquire(frame_, test::scaled(std::chrono::seconds(1))).isOk());
    pipeline::BackprojectCounts counts;
    EXPECT_TRUE(pipeline::backprojectRef(frame_, pipeline::DepthRange{}, cloud_, counts).isOk());
    pipeline::Gaze gaze;
    gaze.origin_m = frame_.T_world_cam.t_world_cam;
    gaze.direction = *camera_->info().focus_point_m - gaze.origin_m;
    EXPECT_TRUE(foveator_->foveate(cloud_, gaze, out_, stats_).isOk());
    return out_;
  }
  const pipeline::FoveationStats& stats() const { return stats_; }

 private:
  std::unique_ptr<hal::Camera> camera_;
  hal::RgbdFrame frame_;
  pipeline::PointCloud cloud_;
  pipeline::FoveatedCloud out_;
  std::unique_ptr<pipeline::Foveator> foveator_;
  pipeline::FoveationStats stats_;
};

// Bit-identical clouds (world positions, colours, regions, weights).
void expectIdentical(const pipeline::FoveatedCloud& a, const pipeline::FoveatedCloud& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a.points.world(i), b.points.world(i)) << "point " << i;
    ASSERT_EQ(a.points.rgb()[i], b.points.rgb()[i]) << "point " << i;
    ASSERT_EQ(a.region[i], b.region[i]) << "point " << i;
    ASSERT_EQ(a.weight[i], b.weight[i]) << "point " << i;
  }
}

TEST(MockPipeline, TwoFramesOfAStaticSceneGiveTheSameOutput) {
  MockPipeline p("mock:living-room,temporal_noise=off", pipeline::Preset::kF1);
  const pipeline::FoveatedCloud first = p.next();
  EXPECT_GT(first.size(), 10000u);
  for (int i = 0; i < 3; ++i) expectIdentical(first, p.next());
}

TEST(MockPipeline, TwoRunsGiveTheSameOutput) {
  // 320x240 where a mock frame's ray cast costs 20 times as much: determinism
  // does not depend on the size.
  const std::string size = test::timeScale() > 1.0 ? ",size=320x240" : "";
  for (const char* scene : {"mock:living-room", "mock:balloon", "mock:living-room,path=orbit"}) {
    const std::string spec = scene + size;
    MockPipeline a(spec, pipeline::Preset::kF3);
    MockPipeline b(spec, pipeline::Preset::kF3);
    for (int i = 0, n = test::repetitions(3, 2); i < n; ++i) {
      SCOPED_TRACE(spec + " frame " + std::to_string(i));
      expectIdentical(a.next(), b.next());
    }
  }
}

TEST(MockPipeline, DifferentSeedsGiveDifferentNoiseAndSimilarCounts) {
  MockPipeline a("mock:living-room,seed=1", pipeline::Preset::kF1);
  MockPipeline b("mock:living-room,seed=2", pipeline::Preset::kF1);
  const std::size_t na = a.next().size();
  const std::size_t nb = b.next().size();
  EXPECT_NE(na, nb);  // noise differs, so the occupied voxels differ a little
  EXPECT_NEAR(static_cast<double>(na), static_cast<double>(nb), 0.05 * static_cast<double>(na));
}

// The paper's presets reduce the living room as intended: the fovea untouched,
// fewer points with fewer regions, FREF everything.
TEST(MockPipeline, PresetsOrderTheOutputSize) {
  std::size_t out[4];
  const pipeline::Preset presets[] = {pipeline::Preset::kF1, pipeline::Preset::kF2, pipeline::Preset::kF3,
                                      pipeline::Preset::kFRef};
  uint32_t valid = 0;
  for (int i = 0; i < 4; ++i) {
    MockPipeline p("mock:living-room", presets[i]);
    out[i] = p.next().size();
    EXPECT_EQ(p.stats().regions[0].points_in, p.stats().regions[0].points_out);
    valid = p.stats().points_in;
  }
  EXPECT_LT(out[0], out[1]);  // F1 samples the near periphery at the far-peripheral size; F2 does not
  EXPECT_LT(out[1], out[2]);
  EXPECT_EQ(out[3], valid);   // FREF keeps every valid point
  EXPECT_LT(out[2], valid / 3);
}

}  // namespace
}  // namespace fovea
