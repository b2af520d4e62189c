// A realistic foveated frame for the codec tests: the mock living room through
// back-projection and the Foveator (as tests/integration/test_mock_pipeline.cpp).
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "hal/camera.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "tests/support/test_time.h"

namespace fovea::test {

struct MockFoveatedFrame {
  pipeline::FoveatedCloud cloud;
  std::vector<double> voxel_size_m;  // per region
  uint64_t capture_ns = 0;
};

// Frame `index` of `spec`, foveated with `preset` for a gaze towards the scene centre.
inline MockFoveatedFrame mockFoveatedFrame(const std::string& spec = "mock:living-room",
                                           pipeline::Preset preset = pipeline::Preset::kF1, int frames = 1) {
  std::unique_ptr<hal::Camera> camera = hal::createCamera(spec).value();
  EXPECT_TRUE(camera->open().isOk());
  EXPECT_TRUE(camera->start().isOk());
  const hal::CameraIntrinsics& k = camera->info().intrinsics;
  const std::size_t pixels = static_cast<std::size_t>(k.width) * k.height;
  hal::RgbdFrame frame(k.width, k.height);
  pipeline::PointCloud cloud(pixels);
  MockFoveatedFrame out;
  out.cloud = pipeline::FoveatedCloud(pixels);
  pipeline::FoveationConfig config;
  config.acuity.preset = preset;
  pipeline::Foveator foveator = pipeline::Foveator::create({pixels, pixels}, config).value();
  pipeline::FoveationStats stats;
  for (int f = 0; f < frames; ++f) {
    EXPECT_TRUE(camera->acquire(frame, test::scaled(std::chrono::seconds(1))).isOk());
    pipeline::BackprojectCounts counts;
    EXPECT_TRUE(pipeline::backprojectRef(frame, pipeline::DepthRange{}, cloud, counts).isOk());
    pipeline::Gaze gaze;
    gaze.origin_m = frame.T_world_cam.t_world_cam;
    gaze.direction = *camera->info().focus_point_m - gaze.origin_m;
    EXPECT_TRUE(foveator.foveate(cloud, gaze, out.cloud, stats).isOk());
  }
  for (int r = 0; r < stats.region_count; ++r) out.voxel_size_m.push_back(stats.regions[static_cast<std::size_t>(r)].voxel_size_m);
  out.capture_ns = 123456789;
  return out;
}

}  // namespace fovea::test
