// The mock RGB-D camera and the backend table: spec parsing, the Camera
// contract, determinism, the sensor model against hand-computed geometry, and
// the renderer's shortcuts (screen-space culling, incremental balloon updates)
// against a brute-force ray cast.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "hal/camera.h"
#include "hal/camera/mock/mock_camera.h"
#include "hal/camera/mock/scene.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/test_time.h"

namespace fovea::hal::mock {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;

constexpr double kPi = 3.14159265358979323846;

std::unique_ptr<MockCamera> makeCamera(const std::string& args) {
  Result<MockCameraOptions> options = parseMockCameraOptions(args);
  EXPECT_TRUE(options.isOk()) << options.status().toString();
  if (!options.isOk()) return nullptr;
  return std::make_unique<MockCamera>(std::move(options).value());
}

std::unique_ptr<MockCamera> makeStarted(const std::string& args) {
  std::unique_ptr<MockCamera> camera = makeCamera(args);
  if (!camera) return nullptr;
  EXPECT_TRUE(camera->open().isOk());
  EXPECT_TRUE(camera->start().isOk());
  return camera;
}

RgbdFrame makeSlot(const Camera& camera) {
  return RgbdFrame(camera.info().intrinsics.width, camera.info().intrinsics.height);
}

void grab(Camera& camera, RgbdFrame& slot) {
  const Status status = camera.acquire(slot, seconds(1));
  ASSERT_TRUE(status.isOk()) << status.toString();
}

bool sameDepth(const RgbdFrame& a, const RgbdFrame& b) {
  return a.pixelCount() == b.pixelCount() &&
         std::memcmp(a.depth(), b.depth(), a.pixelCount() * sizeof(uint16_t)) == 0;
}

bool sameRgb(const RgbdFrame& a, const RgbdFrame& b) {
  return a.pixelCount() == b.pixelCount() && std::memcmp(a.rgb(), b.rgb(), a.pixelCount() * 3) == 0;
}

std::size_t countDifferentDepth(const RgbdFrame& a, const RgbdFrame& b) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.pixelCount(); ++i) n += a.depth()[i] != b.depth()[i];
  return n;
}

double validFraction(const RgbdFrame& frame) {
  std::size_t valid = 0;
  for (std::size_t i = 0; i < frame.pixelCount(); ++i) valid += frame.depth()[i] != 0;
  return static_cast<double>(valid) / static_cast<double>(frame.pixelCount());
}

// The world direction of pixel (x, y)'s ray, scaled so that its camera z is 1,
// computed in the same order as the renderer.
Eigen::Vector3d pixelRay(const RgbdFrame& frame, int x, int y) {
  const CameraIntrinsics& k = frame.intrinsics;
  const Eigen::Matrix3d& r = frame.T_world_cam.R_world_cam;
  const Eigen::Vector3d row = Eigen::Vector3d(r.col(1)) * ((y - k.cy) / k.fy) + r.col(2);
  return Eigen::Vector3d(r.col(0)) * ((x - k.cx) / k.fx) + row;
}

uint16_t depthUnits(double z_m) { return static_cast<uint16_t>(std::floor(z_m / 0.001 + 0.5)); }

std::string keyframes(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  auto num = [](double v) { return std::to_string(v); };
  return "path=keyframes:0," + num(eye.x()) + "," + num(eye.y()) + "," + num(eye.z()) + "," +
         num(target.x()) + "," + num(target.y()) + "," + num(target.z());
}

// --- The backend table and spec parsing -------------------------------------

void expectInvalid(const std::string& spec, const std::vector<std::string>& mentions) {
  Result<std::unique_ptr<Camera>> camera = createCamera(spec);
  ASSERT_FALSE(camera.isOk()) << spec;
  EXPECT_EQ(camera.status().code(), ErrorCode::kInvalidArgument) << spec;
  for (const std::string& word : mentions) {
    EXPECT_NE(camera.status().message().find(word), std::string::npos)
        << spec << " -> " << camera.status().message() << " should mention " << word;
  }
}

TEST(CameraSpec, UnknownBackendListsTheBackends) { expectInvalid("usb:orbbec", {"usb", "mock"}); }

TEST(CameraSpec, UnknownOrMissingSceneListsTheScenes) {
  expectInvalid("mock:kitchen", {"kitchen", "living-room", "balloon"});
  expectInvalid("mock", {"living-room", "balloon"});
  expectInvalid("mock:", {"living-room", "balloon"});
}

TEST(CameraSpec, UnknownKeyListsTheKeys) {
  expectInvalid("mock:living-room,colour=red",
                {"colour", "seed", "size", "path", "temporal_noise"});
  expectInvalid("mock:living-room,orbit", {"orbit", "key=value"});
}

TEST(CameraSpec, BadValuesNameTheKeyAndTheAcceptedValues) {
  expectInvalid("mock:living-room,size=640x", {"size", "WxH", "640x"});
  expectInvalid("mock:living-room,size=640", {"size", "WxH"});
  expectInvalid("mock:living-room,size=8x8", {"size", "16..4096"});
  expectInvalid("mock:living-room,size=-640x480", {"size"});
  expectInvalid("mock:living-room,seed=-1", {"seed", "unsigned"});
  expectInvalid("mock:living-room,seed=", {"seed"});
  expectInvalid("mock:living-room,fps=0", {"fps"});
  expectInvalid("mock:living-room,fps=fast", {"fps"});
  expectInvalid("mock:living-room,noise=maybe", {"noise", "on|off"});
  expectInvalid("mock:living-room,temporal_noise=1", {"temporal_noise", "on|off"});
  expectInvalid("mock:living-room,realtime=yes", {"realtime", "on|off"});
  expectInvalid("mock:living-room,path=spiral", {"path", "static|pan|orbit|dolly", "keyframes"});
  expectInvalid("mock:living-room,seed=1,seed=2", {"seed", "twice"});
}

TEST(CameraSpec, BadKeyframesSayWhatIsWrong) {
  expectInvalid("mock:living-room,path=keyframes:", {"path", "keyframes"});
  expectInvalid("mock:living-room,path=keyframes:0,1,2,3", {"keyframe 1", "4 numbers"});
  expectInvalid("mock:living-room,path=keyframes:0,1,1,1,2,2,2;1,1,1,1,2,2,x",
                {"keyframe 2", "'x'"});
  expectInvalid("mock:living-room,path=keyframes:0,1,1,1,2,2,2,9", {"keyframe 1", "more than 7"});
  expectInvalid("mock:living-room,path=keyframes:1,1,1,1,2,2,2;0,1,1,1,2,2,2",
                {"keyframe 2", "increase"});
  expectInvalid("mock:living-room,path=keyframes:0,1,1,1,1,1,1", {"keyframe 1", "coincide"});
}

TEST(CameraSpec, ParsesEveryOption) {
  Result<MockCameraOptions> parsed = parseMockCameraOptions(
      "balloon,seed=7,size=320x240,fps=15.5,path=orbit,noise=off,temporal_noise=off,realtime=on");
  ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
  const MockCameraOptions& o = parsed.value();
  EXPECT_EQ(o.scene, "balloon");
  EXPECT_EQ(o.seed, 7u);
  EXPECT_EQ(o.width, 320);
  EXPECT_EQ(o.height, 240);
  EXPECT_DOUBLE_EQ(o.fps, 15.5);
  EXPECT_EQ(o.path.kind, PathKind::kOrbit);
  EXPECT_FALSE(o.noise);
  EXPECT_FALSE(o.temporal_noise);
  EXPECT_TRUE(o.realtime);

  Result<MockCameraOptions> defaults = parseMockCameraOptions("living-room");
  ASSERT_TRUE(defaults.isOk());
  EXPECT_EQ(defaults.value().seed, 1u);
  EXPECT_EQ(defaults.value().width, 640);
  EXPECT_EQ(defaults.value().height, 480);
  EXPECT_DOUBLE_EQ(defaults.value().fps, 30.0);
  EXPECT_EQ(defaults.value().path.kind, PathKind::kStatic);
  EXPECT_TRUE(defaults.value().noise);
  EXPECT_TRUE(defaults.value().temporal_noise);
  EXPECT_FALSE(defaults.value().realtime);

  // Keyframe lists contain commas; the keys after them still parse.
  Result<MockCameraOptions> keys = parseMockCameraOptions(
      "living-room,path=keyframes:0,1,1,1.5,2,2,1;2.5,3,1,1.5,3,4,1;,seed=3");
  ASSERT_TRUE(keys.isOk()) << keys.status().toString();
  ASSERT_EQ(keys.value().path.keyframes.size(), 2u);
  EXPECT_DOUBLE_EQ(keys.value().path.keyframes[1].t_s, 2.5);
  EXPECT_EQ(keys.value().path.keyframes[1].target_m, Eigen::Vector3d(3, 4, 1));
  EXPECT_EQ(keys.value().seed, 3u);
}

TEST(CameraSpec, CreatesAMockCameraWithKinectIntrinsics) {
  Result<std::unique_ptr<Camera>> camera = createCamera("mock:balloon,size=320x240,fps=15");
  ASSERT_TRUE(camera.isOk()) << camera.status().toString();
  const CameraInfo& info = camera.value()->info();
  EXPECT_EQ(info.name, "mock:balloon");
  EXPECT_EQ(info.intrinsics.width, 320);
  EXPECT_EQ(info.intrinsics.height, 240);
  EXPECT_DOUBLE_EQ(info.intrinsics.fx, 262.5);
  EXPECT_DOUBLE_EQ(info.intrinsics.fy, 262.5);
  EXPECT_DOUBLE_EQ(info.intrinsics.cx, 159.5);
  EXPECT_DOUBLE_EQ(info.intrinsics.cy, 119.5);
  EXPECT_DOUBLE_EQ(info.depth_scale_m, 0.001);
  EXPECT_DOUBLE_EQ(info.fps, 15.0);
  // The balloon's mean position, where demos aim the gaze.
  ASSERT_TRUE(info.focus_point_m.has_value());
  EXPECT_TRUE(info.focus_point_m->isApprox(Eigen::Vector3d(0.0, 2.0, 1.15)));
}

TEST(CameraSpec, HelpListsTheMockBackend) {
  const std::string help = cameraSpecHelp();
  for (const char* word :
       {"mock:", "living-room", "balloon", "seed=", "size=", "path=", "temporal_noise"}) {
    EXPECT_NE(help.find(word), std::string::npos) << word;
  }
}

// --- The Camera contract ------------------------------------------------------

TEST(MockCamera, AcquireBeforeStartIsUnavailable) {
  std::unique_ptr<MockCamera> camera = makeCamera("living-room,size=64x48");
  RgbdFrame slot(64, 48);
  EXPECT_EQ(camera->acquire(slot, milliseconds(10)).code(), ErrorCode::kUnavailable);
  EXPECT_EQ(camera->start().code(), ErrorCode::kUnavailable);  // not opened
  ASSERT_TRUE(camera->open().isOk());
  EXPECT_EQ(camera->acquire(slot, milliseconds(10)).code(), ErrorCode::kUnavailable);
  ASSERT_TRUE(camera->start().isOk());
  EXPECT_TRUE(camera->acquire(slot, milliseconds(10)).isOk());
  camera->stop();
  EXPECT_EQ(camera->acquire(slot, milliseconds(10)).code(), ErrorCode::kUnavailable);
  EXPECT_EQ(camera->counters().errors, 3u);
  EXPECT_EQ(camera->counters().frames_delivered, 1u);
}

TEST(MockCamera, SlotTooSmallIsCapacityExceeded) {
  std::unique_ptr<MockCamera> camera = makeStarted("living-room");
  RgbdFrame small(320, 240);
  EXPECT_EQ(camera->acquire(small, seconds(1)).code(), ErrorCode::kCapacityExceeded);
  EXPECT_EQ(camera->counters().errors, 1u);
  RgbdFrame big(800, 600);  // larger is fine: the frame takes its own size
  grab(*camera, big);
  EXPECT_EQ(big.width(), 640);
  EXPECT_EQ(big.height(), 480);
}

TEST(MockCamera, FillsTheSlotsMetadata) {
  std::unique_ptr<MockCamera> camera = makeStarted("living-room,size=160x120");
  RgbdFrame slot = makeSlot(*camera);
  slot.depth_scale_m = 0.5;
  slot.has_rgb = false;
  const int64_t expected_stamps_ns[] = {0, 33333333, 66666667};
  for (uint64_t i = 0; i < 3; ++i) {
    grab(*camera, slot);
    EXPECT_EQ(slot.sequence, i);
    EXPECT_EQ(slot.stamp_ns, expected_stamps_ns[i]);
  }
  EXPECT_EQ(slot.width(), 160);
  EXPECT_EQ(slot.intrinsics.width, 160);
  EXPECT_DOUBLE_EQ(slot.intrinsics.fx, 525.0 * 160 / 640);
  EXPECT_DOUBLE_EQ(slot.depth_scale_m, 0.001);
  EXPECT_TRUE(slot.has_rgb);
  const Pose expected = camera->scene().defaultPose();
  EXPECT_TRUE(slot.T_world_cam.R_world_cam.isApprox(expected.R_world_cam));
  EXPECT_TRUE(slot.T_world_cam.t_world_cam.isApprox(expected.t_world_cam));
  EXPECT_EQ(camera->counters().frames_delivered, 3u);
}

TEST(MockCamera, AcquireDoesNotAllocate) {
  {
    std::unique_ptr<MockCamera> stopped = makeCamera("living-room,size=64x48");
    ASSERT_TRUE(stopped->open().isOk());
    RgbdFrame slot = makeSlot(*stopped);
    test::AllocationScope scope;
    EXPECT_EQ(stopped->acquire(slot, seconds(1)).code(), ErrorCode::kUnavailable);
    EXPECT_EQ(scope.allocations(), 0u);
  }
  // The default size once; the other paths and noise settings at a quarter of
  // its pixels (what is allocated does not depend on the size; the time does).
  for (const char* args :
       {"living-room", "living-room,path=orbit,size=320x240", "balloon,size=320x240",
        "balloon,path=pan,temporal_noise=off,size=320x240", "living-room,noise=off,path=dolly,size=320x240"}) {
    std::unique_ptr<MockCamera> camera = makeStarted(args);
    RgbdFrame slot = makeSlot(*camera);
    RgbdFrame small(32, 32);
    test::AllocationScope scope;
    for (int i = 0; i < 3; ++i) {
      EXPECT_TRUE(camera->acquire(slot, seconds(1)).isOk());
    }
    EXPECT_EQ(camera->acquire(small, seconds(1)).code(), ErrorCode::kCapacityExceeded);
    EXPECT_EQ(scope.allocations(), 0u) << args;
  }
}

// At 2 fps, so that frame 1 is not yet due when the 1 ms acquire asks for it even
// on a slow, loaded emulator (at 20 fps, qemu beside CI's other stages once took
// longer than the 50 ms to frame 1 and got it).
TEST(MockCamera, RealtimePacesToFpsAndTimesOut) {
  std::unique_ptr<MockCamera> camera = makeStarted("living-room,size=64x48,fps=2,realtime=on");
  RgbdFrame slot = makeSlot(*camera);
  const auto start = std::chrono::steady_clock::now();
  grab(*camera, slot);  // frame 0 is due at once
  EXPECT_EQ(camera->acquire(slot, milliseconds(1)).code(), ErrorCode::kUnavailable);
  EXPECT_EQ(camera->counters().timeouts, 1u);
  grab(*camera, slot);  // frame 1 is due 500 ms after start
  EXPECT_GE(std::chrono::steady_clock::now() - start, milliseconds(450));
  EXPECT_EQ(slot.sequence, 1u);
  EXPECT_EQ(slot.stamp_ns, 500'000'000);
}

// --- Determinism ---------------------------------------------------------------

TEST(MockCamera, SameSeedGivesIdenticalFramesAndAnotherSeedDifferentNoise) {
  for (const char* scene : {"living-room", "balloon"}) {
    // 320x240: every pixel's noise is a function of (seed, sequence, pixel), at
    // any size; a quarter of the default's pixels keeps the slow trees quick.
    const std::string args = std::string(scene) + ",seed=5,path=pan,size=320x240";
    std::unique_ptr<MockCamera> a = makeStarted(args);
    std::unique_ptr<MockCamera> b = makeStarted(args);
    std::unique_ptr<MockCamera> c = makeStarted(std::string(scene) + ",seed=6,path=pan,size=320x240");
    RgbdFrame fa = makeSlot(*a), fb = makeSlot(*b), fc = makeSlot(*c);
    for (int i = 0, n = test::repetitions(4, 2); i < n; ++i) {
      grab(*a, fa);
      grab(*b, fb);
      grab(*c, fc);
      EXPECT_TRUE(sameDepth(fa, fb)) << scene << " frame " << i;
      EXPECT_TRUE(sameRgb(fa, fb)) << scene << " frame " << i;
      // Different noise, same geometry and pose.
      EXPECT_GT(countDifferentDepth(fa, fc), fa.pixelCount() / 2) << scene;
      EXPECT_TRUE(fa.T_world_cam.R_world_cam == fc.T_world_cam.R_world_cam);
    }
  }
}

TEST(MockCamera, TemporalNoiseOffGivesIdenticalFramesOfAStaticScene) {
  std::unique_ptr<MockCamera> frozen = makeStarted("living-room,temporal_noise=off");
  std::unique_ptr<MockCamera> live = makeStarted("living-room");
  RgbdFrame f0 = makeSlot(*frozen), f1 = makeSlot(*frozen), l0 = makeSlot(*live),
            l1 = makeSlot(*live);
  grab(*frozen, f0);
  grab(*frozen, f1);
  grab(*live, l0);
  grab(*live, l1);
  EXPECT_TRUE(sameDepth(f0, f1));
  EXPECT_TRUE(sameRgb(f0, f1));
  EXPECT_LT(validFraction(f0), 1.0);  // still noisy, just frozen
  EXPECT_FALSE(sameDepth(l0, l1));
  EXPECT_GT(countDifferentDepth(l0, l1), l0.pixelCount() / 2);
}

// --- Geometry and the sensor model ---------------------------------------------

// Camera 1 m from the south wall (y = 0), looking obliquely at it; depth of
// every pixel that sees bare wall, from the plane equation by hand.
TEST(MockCamera, NoiseOffDepthIsTheRayCastDistanceToAKnownWall) {
  const Eigen::Vector3d eye(2.0, 1.0, 1.5);
  const Eigen::Vector3d target(1.2, 0.0, 1.2);
  std::unique_ptr<MockCamera> camera =
      makeStarted("living-room,noise=off," + keyframes(eye, target));
  RgbdFrame frame = makeSlot(*camera);
  grab(*camera, frame);

  // Look-at by hand: z forward, x = forward x up (right), y = z x x (down).
  const Eigen::Vector3d forward = (target - eye).normalized();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  EXPECT_TRUE(frame.T_world_cam.R_world_cam.col(0).isApprox(right, 1e-12));
  EXPECT_TRUE(frame.T_world_cam.R_world_cam.col(1).isApprox(down, 1e-12));
  EXPECT_TRUE(frame.T_world_cam.R_world_cam.col(2).isApprox(forward, 1e-12));
  EXPECT_EQ(frame.T_world_cam.t_world_cam, eye);

  const double fx = 525.0, cx = 319.5, cy = 239.5;
  int checked = 0, exact = 0;
  for (int y = 0; y < 480; y += 3) {
    for (int x = 0; x < 640; x += 3) {
      const Eigen::Vector3d d_cam((x - cx) / fx, (y - cy) / fx, 1.0);
      const Eigen::Vector3d d = right * d_cam.x() + down * d_cam.y() + forward * d_cam.z();
      if (d.y() >= 0.0) continue;
      const double t = -eye.y() / d.y();  // plane y = 0; t is also the camera z
      const Eigen::Vector3d p = eye + t * d;
      // Bare wall: away from the corners, the floor, the ceiling and the door.
      if (p.x() < 0.2 || p.x() > 4.3 || p.z() < 0.2 || p.z() > 2.5) continue;
      const uint16_t expected = depthUnits(t);
      const uint16_t got = frame.depth()[static_cast<std::size_t>(y) * 640 + x];
      // Off by one only where z sits on a half millimetre and the two ways of
      // computing it differ in the last bit.
      ASSERT_NEAR(got, expected, 1) << "pixel " << x << "," << y;
      ++checked;
      exact += got == expected;
    }
  }
  EXPECT_GT(checked, 20000);
  EXPECT_GE(exact, checked - checked / 1000);
}

// The renderer culls groups in screen space and re-renders only the balloon's
// rectangle; the result must equal a plain ray cast through Scene::intersect.
TEST(MockCamera, NoiseOffFramesEqualABruteForceRayCast) {
  for (const char* args :
       {"living-room,noise=off,size=320x240,path=orbit,fps=2", "balloon,noise=off,size=320x240",
        "balloon,noise=off,size=320x240,path=dolly,fps=4",
        // Outside the room, looking in through the south wall's outer face.
        "living-room,noise=off,size=160x120,path=keyframes:0,3,-2,1.5,3,2,1",
        // Straight down from under the ceiling (look-at falls back to +y up).
        "living-room,noise=off,size=160x120,path=keyframes:0,2.8,2.6,2.6,2.8,2.6,0",
        // Inside the bookshelf's bounds, between two shelves.
        "living-room,noise=off,size=160x120,path=keyframes:0,0.2,1.8,0.75,3,2,0.7",
        // The movers: a box walking across the orbit, a box carried with the camera.
        "walker,noise=off,size=160x120,path=orbit,fps=2", "carried,noise=off,size=160x120,path=orbit,fps=2"}) {
    std::unique_ptr<MockCamera> camera = makeStarted(args);
    RgbdFrame frame = makeSlot(*camera);
    for (int i = 0; i < 6; ++i) {
      grab(*camera, frame);
      const double time_s = static_cast<double>(frame.sequence) / camera->options().fps;
      std::size_t mismatches = 0;
      for (int y = 0; y < frame.height(); ++y) {
        for (int x = 0; x < frame.width(); ++x) {
          Hit hit;
          bool found =
              camera->scene().intersect(frame.T_world_cam.t_world_cam, pixelRay(frame, x, y),
                                        time_s, SceneLayer::kAll, 1e300, hit);
          found |= camera->scene().intersectCarried(frame.T_world_cam, pixelRay(frame, x, y),
                                                    found ? hit.t : 1e300, hit);
          const uint16_t expected = found && hit.t >= 0.4 && hit.t <= 8.0 ? depthUnits(hit.t) : 0;
          mismatches += frame.depth()[static_cast<std::size_t>(y) * frame.width() + x] != expected;
        }
      }
      EXPECT_EQ(mismatches, 0u) << args << " frame " << i;
    }
  }
}

// A static scene on a moving path is rendered row by row into the frame
// (MockCameraOptions::stream_rows): every frame is the whole image's bit for
// bit, noise and dropout bands included, at an odd width (pairs of pixels that
// share a draw straddle rows) and an even one, with and without noise, and
// with a garbage frame between.
TEST(MockCamera, RowByRowFramesAreTheWholeImagesBitForBit) {
  for (const char* args : {"living-room,size=161x121,path=orbit,fps=4", "living-room,size=160x120,path=pan,fps=4",
                           "living-room,size=161x121,path=dolly,fps=4,noise=off",
                           "living-room,size=160x120,path=orbit,fps=4,temporal_noise=off,fault=garbage@2"}) {
    SCOPED_TRACE(args);
    Result<MockCameraOptions> options = parseMockCameraOptions(args);
    ASSERT_TRUE(options.isOk()) << options.status().toString();
    MockCameraOptions whole_options = options.value();
    whole_options.stream_rows = false;
    MockCamera rows(options.value()), whole(whole_options);
    for (MockCamera* camera : {&rows, &whole}) {
      ASSERT_TRUE(camera->open().isOk());
      ASSERT_TRUE(camera->start().isOk());
    }
    RgbdFrame a = makeSlot(rows), b = makeSlot(whole);
    for (int i = 0; i < 5; ++i) {
      grab(rows, a);
      grab(whole, b);
      EXPECT_TRUE(sameDepth(a, b)) << "frame " << i;
      EXPECT_EQ(std::memcmp(a.rgb(), b.rgb(), 3 * a.pixelCount()), 0) << "frame " << i;
      EXPECT_GT(std::count_if(a.depth(), a.depth() + a.pixelCount(), [](uint16_t d) { return d != 0; }),
                static_cast<std::ptrdiff_t>(a.pixelCount() / 4));
    }
  }
}

TEST(MockCamera, ValidPixelFractionIsSane) {
  for (const char* args : {"living-room", "balloon", "living-room,path=orbit"}) {
    std::unique_ptr<MockCamera> camera = makeStarted(args);
    RgbdFrame frame = makeSlot(*camera);
    grab(*camera, frame);
    const double valid = validFraction(frame);
    EXPECT_GT(valid, 0.60) << args;
    EXPECT_LT(valid, 0.995) << args;
  }
}

// Camera 0.4 m under the ceiling looking east along the room, tilted up 25
// degrees: the ceiling is seen from 0.5 m at 40 degrees incidence out to 5.4 m
// at 86 degrees.
TEST(MockCamera, PixelsGoMissingAtGrazingIncidence) {
  const Eigen::Vector3d eye(0.3, 2.25, 2.3);
  const Eigen::Vector3d target = eye + Eigen::Vector3d(1.0, 0.0, std::tan(25.0 * kPi / 180.0));
  std::unique_ptr<MockCamera> camera = makeStarted("living-room," + keyframes(eye, target));
  RgbdFrame frame = makeSlot(*camera);
  int grazing = 0, grazing_missing = 0, steep = 0, steep_missing = 0;
  for (int i = 0; i < 3; ++i) {
    grab(*camera, frame);
    for (int y = 0; y < 480; ++y) {
      for (int x = 0; x < 640; ++x) {
        const Eigen::Vector3d d = pixelRay(frame, x, y);
        if (d.z() <= 0.0) continue;
        const double t = (2.7 - eye.z()) / d.z();
        const Eigen::Vector3d p = eye + t * d;
        if (p.x() > 5.7 || p.y() < 0.3 || p.y() > 4.2 || t > 7.5) continue;
        const double incidence_deg = std::acos(d.z() / d.norm()) * 180.0 / kPi;
        const bool missing = frame.depth()[static_cast<std::size_t>(y) * 640 + x] == 0;
        if (incidence_deg > 82.0) {
          ++grazing;
          grazing_missing += missing;
        } else if (incidence_deg < 70.0) {
          ++steep;
          steep_missing += missing;
        }
      }
    }
  }
  ASSERT_GT(grazing, 1000);
  ASSERT_GT(steep, 1000);
  EXPECT_GT(static_cast<double>(grazing_missing) / grazing, 0.6);
  EXPECT_LT(static_cast<double>(steep_missing) / steep, 0.02);
}

// Background pixels next to an occluding edge (from the ideal depth) are lost.
TEST(MockCamera, PixelsGoMissingNextToDepthDiscontinuities) {
  std::unique_ptr<MockCamera> ideal = makeStarted("living-room,noise=off");
  std::unique_ptr<MockCamera> noisy = makeStarted("living-room");
  RgbdFrame clean = makeSlot(*ideal), frame = makeSlot(*noisy);
  grab(*ideal, clean);
  grab(*noisy, frame);
  int band = 0, band_missing = 0;
  for (int y = 1; y < 479; ++y) {
    for (int x = 1; x < 639; ++x) {
      const int z = clean.depth()[y * 640 + x];
      if (z == 0) continue;
      bool next_to_occluder = false;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int zq = clean.depth()[(y + dy) * 640 + x + dx];
          next_to_occluder |= zq > 0 && z - zq > 300;
        }
      }
      if (!next_to_occluder) continue;
      ++band;
      band_missing += frame.depth()[y * 640 + x] == 0;
    }
  }
  EXPECT_GT(band, 300);
  EXPECT_EQ(band_missing, band);
}

// Axial noise on a wall seen head-on at 1 m and 3 m: Nguyen et al. give
// sigma = 1.9 mm and 14.0 mm; a linear growth would give a ratio of 3.
TEST(MockCamera, DepthNoiseGrowsWithTheSquareOfDepth) {
  auto measure = [](double distance_m) {
    const Eigen::Vector3d eye(2.0, distance_m, 1.5);
    const std::string path = keyframes(eye, Eigen::Vector3d(2.0, 0.0, 1.5));
    std::unique_ptr<MockCamera> ideal = makeStarted("living-room,noise=off," + path);
    std::unique_ptr<MockCamera> noisy = makeStarted("living-room,seed=11," + path);
    RgbdFrame clean = makeSlot(*ideal), frame = makeSlot(*noisy);
    double sum = 0.0, sum2 = 0.0;
    int n = 0;
    // 8 frames natively, 2 in the slow trees: 7 400 pixels still measure sigma to about 1 %.
    for (int i = 0; i < test::repetitions(8, 2); ++i) {
      grab(*ideal, clean);
      grab(*noisy, frame);
      for (int y = 240 - 30; y <= 240 + 30; ++y) {
        for (int x = 320 - 30; x <= 320 + 30; ++x) {
          const std::size_t p = static_cast<std::size_t>(y) * 640 + x;
          if (frame.depth()[p] == 0 || clean.depth()[p] == 0) continue;
          const double r = static_cast<double>(frame.depth()[p]) - clean.depth()[p];
          sum += r;
          sum2 += r * r;
          ++n;
        }
      }
    }
    const double mean = sum / n;
    EXPECT_NEAR(clean.depth()[240 * 640 + 320], distance_m * 1000.0, 2.0);
    EXPECT_NEAR(mean, 0.0, 0.1 * std::sqrt(sum2 / n) + 0.2);
    return std::sqrt(sum2 / n - mean * mean) * 0.001;
  };
  const double sigma_1m = measure(1.0);
  const double sigma_3m = measure(3.0);
  EXPECT_NEAR(sigma_1m, 0.0012 + 0.0019 * 0.36, 0.0004);
  EXPECT_NEAR(sigma_3m, 0.0012 + 0.0019 * 6.76, 0.0015);
  EXPECT_GT(sigma_3m / sigma_1m, 5.5);
  EXPECT_LT(sigma_3m / sigma_1m, 10.0);
}

TEST(MockCamera, TheBalloonMoves) {
  std::unique_ptr<MockCamera> camera = makeStarted("balloon,noise=off");
  RgbdFrame first = makeSlot(*camera), later = makeSlot(*camera);
  grab(*camera, first);
  for (int i = 0; i < 4; ++i) grab(*camera, later);  // t = 0.133 s
  // The balloon (its front about 1.7 m away) is in view and has moved.
  auto balloonPixels = [](const RgbdFrame& f) {
    int n = 0;
    for (std::size_t i = 0; i < f.pixelCount(); ++i)
      n += f.depth()[i] > 1000 && f.depth()[i] < 2600;
    return n;
  };
  EXPECT_GT(balloonPixels(first), 5000);
  EXPECT_GT(balloonPixels(later), 5000);
  EXPECT_GT(countDifferentDepth(first, later), 1000u);
  EXPECT_TRUE(first.T_world_cam.R_world_cam == later.T_world_cam.R_world_cam);  // camera static
}

// --- Paths and scenes -------------------------------------------------------------

TEST(MockCamera, KeyframePathInterpolatesEyeAndTarget) {
  std::unique_ptr<MockCamera> camera = makeStarted(
      "living-room,size=64x48,fps=10,noise=off,"
      "path=keyframes:0,1,1,1.5,1,4,1.5;2,5,1,1.5,5,4,1.5");
  RgbdFrame frame = makeSlot(*camera);
  for (int i = 0; i <= 30; ++i) {
    grab(*camera, frame);
    const Eigen::Vector3d& t = frame.T_world_cam.t_world_cam;
    const Eigen::Matrix3d& r = frame.T_world_cam.R_world_cam;
    const double expected_x = 1.0 + 2.0 * std::clamp(i / 10.0, 0.0, 2.0);  // clamped after 2 s
    EXPECT_NEAR(t.x(), expected_x, 1e-9) << "frame " << i;
    EXPECT_NEAR(t.y(), 1.0, 1e-9);
    EXPECT_NEAR(t.z(), 1.5, 1e-9);
    // Looking along +y (north), image x east, image y down.
    EXPECT_TRUE(r.col(2).isApprox(Eigen::Vector3d::UnitY(), 1e-9));
    EXPECT_TRUE(r.col(0).isApprox(Eigen::Vector3d::UnitX(), 1e-9));
    EXPECT_TRUE(r.col(1).isApprox(-Eigen::Vector3d::UnitZ(), 1e-9));
  }
  // Mid-segment, a turning target: eye (3, 1, 1.5), target halfway.
  CameraPath path;
  path.kind = PathKind::kKeyframes;
  path.keyframes = {{0.0, {0, 0, 1}, {0, 1, 1}}, {1.0, {2, 0, 1}, {4, 1, 1}}};
  const Pose mid = cameraPoseAt(path, SceneInfo(), 0.5);
  EXPECT_TRUE(mid.t_world_cam.isApprox(Eigen::Vector3d(1, 0, 1)));
  EXPECT_TRUE(mid.R_world_cam.col(2).isApprox(Eigen::Vector3d(1, 1, 0).normalized()));
}

TEST(MockCamera, BuiltInPathsKeepTheirShape) {
  Result<Scene> room = Scene::create("living-room");
  ASSERT_TRUE(room.isOk());
  const SceneInfo& info = room.value().info();
  CameraPath path;
  for (double t = 0.0; t < 30.0; t += 0.7) {
    path.kind = PathKind::kOrbit;
    const Pose orbit = cameraPoseAt(path, info, t);
    const Eigen::Vector3d to_focus = info.focus_point_m - orbit.t_world_cam;
    EXPECT_NEAR(std::hypot(to_focus.x(), to_focus.y()), info.orbit_radius_m, 1e-9);
    EXPECT_NEAR(orbit.t_world_cam.z(), info.orbit_height_m, 1e-9);
    EXPECT_TRUE(orbit.R_world_cam.col(2).isApprox(to_focus.normalized(), 1e-9));
    path.kind = PathKind::kPan;
    EXPECT_EQ(cameraPoseAt(path, info, t).t_world_cam, info.default_eye_m);
    path.kind = PathKind::kDolly;
    const Pose dolly = cameraPoseAt(path, info, t);
    EXPECT_LE((dolly.t_world_cam - info.default_eye_m).norm(), info.dolly_distance_m + 1e-9);
    EXPECT_TRUE(dolly.R_world_cam.isApprox(room.value().defaultPose().R_world_cam, 1e-9));
  }
}

TEST(MockScene, FocusPointsAreTheRoomCentreAndTheBalloonsMeanPosition) {
  Result<Scene> room = Scene::create("living-room");
  ASSERT_TRUE(room.isOk());
  EXPECT_TRUE(room.value().info().focus_point_m.isApprox(Eigen::Vector3d(3.0, 2.25, 1.35)));
  EXPECT_FALSE(room.value().isDynamic());

  Result<Scene> balloon = Scene::create("balloon");
  ASSERT_TRUE(balloon.isOk());
  ASSERT_TRUE(balloon.value().isDynamic());
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  const int samples = 800;
  for (int i = 0; i < samples; ++i) {
    Eigen::Vector3d lo, hi;
    ASSERT_TRUE(balloon.value().dynamicBounds(8.0 * i / samples, lo, hi));
    EXPECT_NEAR(hi.x() - lo.x(), 0.6, 1e-12);  // radius 0.3 m
    sum += 0.5 * (lo + hi);
  }
  EXPECT_TRUE((sum / samples).isApprox(balloon.value().info().focus_point_m, 1e-9));

  EXPECT_EQ(Scene::create("kitchen").status().code(), ErrorCode::kInvalidArgument);

  // balloon-leaves: the same balloon until 2 s, then gone (the wall behind it is seen).
  Result<Scene> leaves = Scene::create("balloon-leaves");
  ASSERT_TRUE(leaves.isOk());
  EXPECT_EQ(leaves.value().info().name, "balloon-leaves");
  const Eigen::Vector3d eye = leaves.value().info().default_eye_m;
  auto hitAt = [&](double time_s) {
    Eigen::Vector3d lo, hi;
    const Eigen::Vector3d centre = leaves.value().dynamicBounds(time_s, lo, hi) ? Eigen::Vector3d(0.5 * (lo + hi))
                                                                               : Eigen::Vector3d(0.0, 2.0, 1.15);
    Hit hit;
    EXPECT_TRUE(leaves.value().intersect(eye, centre - eye, time_s, SceneLayer::kAll, 1e9, hit));
    return hit.shape;
  };
  Eigen::Vector3d lo, hi;
  EXPECT_TRUE(leaves.value().dynamicBounds(1.9, lo, hi));
  EXPECT_FALSE(leaves.value().dynamicBounds(2.0, lo, hi));
  ASSERT_NE(hitAt(1.9), nullptr);
  EXPECT_EQ(hitAt(1.9)->kind, ShapeKind::kSphere);
  ASSERT_NE(hitAt(2.5), nullptr);
  EXPECT_EQ(hitAt(2.5)->kind, ShapeKind::kPlane);  // the wall where the balloon was
}

// The pixels where the noiseless view of `scene` differs from the living room's
// by more than a centimetre (the same path and time): where its movers are seen.
std::vector<bool> moverPixels(const RgbdFrame& scene, const RgbdFrame& room) {
  std::vector<bool> mover(scene.pixelCount());
  for (std::size_t i = 0; i < scene.pixelCount(); ++i) {
    mover[i] = std::abs(static_cast<int>(scene.depth()[i]) - static_cast<int>(room.depth()[i])) > 10;
  }
  return mover;
}

double share(const std::vector<bool>& mask) {
  return static_cast<double>(std::count(mask.begin(), mask.end(), true)) / static_cast<double>(mask.size());
}

// Issue 42's large mover: a person-sized box walking 1.3 m either way of the
// room's middle in 8 s, from its west end; over a third of the orbit's view
// as it crosses the middle at 2 s; walker-leaves is gone from 3 s on.
TEST(MockScene, TheWalkerCrossesTheOrbitsViewOverAThirdOfItAndLeaves) {
  Result<Scene> walker = Scene::create("walker");
  ASSERT_TRUE(walker.isOk());
  EXPECT_TRUE(walker.value().isDynamic());
  Eigen::Vector3d lo, hi;
  const std::pair<double, double> centre_x_at[] = {{0.0, 1.7}, {2.0, 3.0}, {4.0, 4.3}, {6.0, 3.0}, {8.0, 1.7}};
  for (const auto& [time_s, x_m] : centre_x_at) {
    ASSERT_TRUE(walker.value().dynamicBounds(time_s, lo, hi));
    EXPECT_NEAR(0.5 * (lo.x() + hi.x()), x_m, 1e-9) << time_s;
    EXPECT_NEAR(hi.z() - lo.z(), 1.75, 1e-12);
  }
  std::unique_ptr<MockCamera> camera = makeStarted("walker,noise=off,size=160x120,path=orbit,fps=0.5");
  std::unique_ptr<MockCamera> room = makeStarted("living-room,noise=off,size=160x120,path=orbit,fps=0.5");
  RgbdFrame frame = makeSlot(*camera), room_frame = makeSlot(*room);
  grab(*camera, frame), grab(*room, room_frame);  // t = 0: at the west end, out of view
  const double at_start = share(moverPixels(frame, room_frame));
  grab(*camera, frame), grab(*room, room_frame);  // t = 2 s: crossing the middle
  const double crossing = share(moverPixels(frame, room_frame));
  EXPECT_GE(crossing, 0.30) << "a third of the view";
  EXPECT_LT(crossing, 0.60);
  EXPECT_LT(at_start, crossing);

  Result<Scene> leaves = Scene::create("walker-leaves");
  ASSERT_TRUE(leaves.isOk());
  EXPECT_EQ(leaves.value().info().name, "walker-leaves");
  EXPECT_TRUE(leaves.value().dynamicBounds(2.9, lo, hi));
  EXPECT_FALSE(leaves.value().dynamicBounds(3.0, lo, hi));
}

// A moving shape's texture moves with it: the same point of the walker at two
// times, reached by rays shifted by its motion, is the same point of its own
// frame (and so the same texel).
TEST(MockScene, AMovingBoxCarriesItsTexture) {
  Result<Scene> walker = Scene::create("walker");
  ASSERT_TRUE(walker.isOk());
  const Scene& scene = walker.value();
  Eigen::Vector3d lo0, hi0, lo1, hi1;
  ASSERT_TRUE(scene.dynamicBounds(1.0, lo0, hi0));
  ASSERT_TRUE(scene.dynamicBounds(1.5, lo1, hi1));
  const Eigen::Vector3d shift = lo1 - lo0;
  ASSERT_GT(shift.norm(), 0.1);
  const Eigen::Vector3d origin(lo0.x() + 0.2, 1.0, 1.2);  // south of the box, looking north at it
  const Eigen::Vector3d dir(0.0, 1.0, 0.05);
  Hit first, second;
  ASSERT_TRUE(scene.intersect(origin, dir, 1.0, SceneLayer::kDynamic, 1e9, first));
  ASSERT_TRUE(scene.intersect(origin + shift, dir, 1.5, SceneLayer::kDynamic, 1e9, second));
  EXPECT_NEAR(first.t, second.t, 1e-9);
  EXPECT_EQ(first.face_axis, 1);
  EXPECT_TRUE(first.local_m.isApprox(second.local_m, 1e-12));
  EXPECT_FALSE(first.local_m.isApprox(origin + first.t * dir, 1e-3)) << "local, not world, coordinates";
}

// Issue 42's carried mover: the block is seen in the same pixels at the same
// depth in every frame while the camera orbits, over about 28 % of the view.
TEST(MockScene, TheCarriedBlockStaysPutInTheViewWhileTheCameraOrbits) {
  std::unique_ptr<MockCamera> camera = makeStarted("carried,noise=off,size=160x120,path=orbit,fps=1");
  std::unique_ptr<MockCamera> room = makeStarted("living-room,noise=off,size=160x120,path=orbit,fps=1");
  RgbdFrame frame = makeSlot(*camera), room_frame = makeSlot(*room), first = makeSlot(*camera);
  grab(*camera, first), grab(*room, room_frame);
  const std::vector<bool> first_mask = moverPixels(first, room_frame);
  EXPECT_GT(share(first_mask), 0.24);
  EXPECT_LT(share(first_mask), 0.32);
  for (int i = 1; i < 3; ++i) {
    grab(*camera, frame), grab(*room, room_frame);
    EXPECT_FALSE(frame.T_world_cam.t_world_cam.isApprox(first.T_world_cam.t_world_cam, 1e-3)) << "the camera moves";
    const std::vector<bool> mask = moverPixels(frame, room_frame);
    std::size_t moved = 0;
    for (std::size_t p = 0; p < mask.size(); ++p) {
      moved += mask[p] != first_mask[p] || (mask[p] && frame.depth()[p] != first.depth()[p]);
    }
    EXPECT_EQ(moved, 0u) << "frame " << i;
  }
}

}  // namespace
}  // namespace fovea::hal::mock
