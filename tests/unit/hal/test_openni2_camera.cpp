// The OpenNI2 backend: spec parsing, mode choice, intrinsics and clock mapping
// without a device, and the real backend end to end against OpenNI2's
// synthetic Dummy device (libDummyDevice.so, which Debian's libopenni2-0 ships).
#include "hal/camera/openni2/openni2_camera.h"

#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "hal/camera.h"
#include "tests/support/alloc_counter.h"

namespace fovea::hal::openni2 {
namespace {

using std::chrono::milliseconds;

constexpr int kDepth1Mm = 100;    // openni::PIXEL_FORMAT_DEPTH_1_MM
constexpr int kDepth100Um = 101;  // openni::PIXEL_FORMAT_DEPTH_100_UM
constexpr int kRgb888 = 200;      // openni::PIXEL_FORMAT_RGB888

// Asserts a Status is ok, printing it when it is not.
#define ASSERT_OK(expr)                         \
  do {                                          \
    const Status status_ = (expr);              \
    ASSERT_TRUE(status_.isOk()) << status_.toString(); \
  } while (0)

// Cross builds tested through qemu-user: OpenNI2's runtime hangs there in its
// first initialize (seen with the arm64 build under qemu-aarch64 7.2, not
// investigated further); these tests run natively and on arm64 hardware.
#ifdef FOVEA_TESTS_IN_QEMU_USER
#define SKIP_UNDER_QEMU_USER() GTEST_SKIP() << "OpenNI2's runtime hangs under qemu-user: runs natively only"
#else
#define SKIP_UNDER_QEMU_USER() (void)0
#endif

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

std::unique_ptr<Camera> makeCamera(const std::string& args) {
  Result<std::unique_ptr<Camera>> camera = OpenNI2Camera::create(args);
  EXPECT_TRUE(camera.isOk()) << camera.status().toString();
  return camera.isOk() ? std::move(camera).value() : nullptr;
}

OpenNI2Camera& asOpenNI2(Camera& camera) { return static_cast<OpenNI2Camera&>(camera); }

// ---------------------------------------------------------------- no device

TEST(OpenNI2Options, DefaultsAndEveryKey) {
  Result<OpenNI2CameraOptions> none = parseOpenNI2CameraOptions("");
  ASSERT_TRUE(none.isOk()) << none.status().toString();
  EXPECT_EQ(none->uri, "");
  EXPECT_EQ(none->width, 0);
  EXPECT_TRUE(none->colour);
  EXPECT_TRUE(none->registration);
  EXPECT_TRUE(none->sync);

  Result<OpenNI2CameraOptions> all =
      parseOpenNI2CameraOptions("1d27/0601@1/5,size=640x480,fps=30,colour=off,registration=off,sync=off");
  ASSERT_TRUE(all.isOk()) << all.status().toString();
  EXPECT_EQ(all->uri, "1d27/0601@1/5");
  EXPECT_EQ(all->width, 640);
  EXPECT_EQ(all->height, 480);
  EXPECT_EQ(all->fps, 30);
  EXPECT_FALSE(all->colour);
  EXPECT_FALSE(all->registration);
  EXPECT_FALSE(all->sync);

  // Options without a URI: the first device.
  Result<OpenNI2CameraOptions> first = parseOpenNI2CameraOptions("size=320x240");
  ASSERT_TRUE(first.isOk());
  EXPECT_EQ(first->uri, "");
  EXPECT_EQ(first->width, 320);
}

TEST(OpenNI2Options, BadSpecsSayWhatIsWrong) {
  const struct {
    const char* args;
    const char* says;
  } cases[] = {
      {"Dummy,size=640", "size: expected WxH"},
      {"Dummy,size=0x480", "size: expected WxH"},
      {"Dummy,size=99999x480", "size: expected WxH"},
      {"Dummy,fps=fast", "fps: expected a positive integer"},
      {"Dummy,fps=-3", "fps: expected a positive integer"},
      {"Dummy,colour=maybe", "colour: expected on|off"},
      {"Dummy,registration=1", "registration: expected on|off"},
      {"Dummy,exposure=3", "unknown option 'exposure'"},
      {"Dummy,,fps=30", "empty option"},
      {"Dummy,640x480", "is not key=value"},
  };
  for (const auto& c : cases) {
    Result<OpenNI2CameraOptions> parsed = parseOpenNI2CameraOptions(c.args);
    ASSERT_FALSE(parsed.isOk()) << c.args;
    EXPECT_EQ(parsed.status().code(), ErrorCode::kInvalidArgument) << c.args;
    EXPECT_TRUE(contains(parsed.status().message(), c.says)) << c.args << ": " << parsed.status().message();
  }
  // Through the backend table too.
  Result<std::unique_ptr<Camera>> bad = createCamera("openni2:Dummy,fps=0");
  ASSERT_FALSE(bad.isOk());
  EXPECT_TRUE(contains(bad.status().message(), "fps")) << bad.status().message();
}

TEST(OpenNI2Modes, ChoosesTheRequestedOrPreferredModeInTheBestFormat) {
  const std::vector<VideoModeDesc> modes = {
      {320, 240, 30, kDepth100Um}, {320, 240, 30, kDepth1Mm}, {640, 480, 30, kDepth1Mm},
      {640, 480, 60, kDepth1Mm},   {640, 480, 30, kRgb888},
  };
  const std::vector<int> depth_formats = {kDepth1Mm, kDepth100Um};
  // Requested size and rate.
  Result<int> m = chooseVideoMode(modes, depth_formats, 640, 480, 60, {}, "depth");
  ASSERT_TRUE(m.isOk());
  EXPECT_EQ(m.value(), 3);
  // Requested size, any rate; 1 mm preferred over 100 um.
  m = chooseVideoMode(modes, depth_formats, 320, 240, 0, {}, "depth");
  ASSERT_TRUE(m.isOk());
  EXPECT_EQ(m.value(), 1);
  // No size: the device's current (preferred) mode.
  m = chooseVideoMode(modes, depth_formats, 0, 0, 0, {640, 480, 30, kDepth1Mm}, "depth");
  ASSERT_TRUE(m.isOk());
  EXPECT_EQ(m.value(), 2);
  // No size and a preferred mode in a format we cannot use: the first usable.
  m = chooseVideoMode(modes, depth_formats, 0, 0, 0, {1280, 1024, 30, kRgb888}, "depth");
  ASSERT_TRUE(m.isOk());
  EXPECT_EQ(m.value(), 1);
  // Colour: only RGB888 qualifies.
  m = chooseVideoMode(modes, {kRgb888}, 640, 480, 30, {}, "colour");
  ASSERT_TRUE(m.isOk());
  EXPECT_EQ(m.value(), 4);
}

TEST(OpenNI2Modes, NoMatchListsEveryMode) {
  const std::vector<VideoModeDesc> modes = {{320, 240, 30, kDepth1Mm}, {640, 480, 30, kRgb888}};
  Result<int> m = chooseVideoMode(modes, {kDepth1Mm, kDepth100Um}, 1280, 720, 30, {}, "depth");
  ASSERT_FALSE(m.isOk());
  EXPECT_EQ(m.status().code(), ErrorCode::kInvalidArgument);
  const std::string& text = m.status().message();
  EXPECT_TRUE(contains(text, "depth sensor has no mode 1280x720 @ 30 fps")) << text;
  EXPECT_TRUE(contains(text, "320x240 @ 30 fps DEPTH_1_MM")) << text;
  EXPECT_TRUE(contains(text, "640x480 @ 30 fps RGB888")) << text;
  Result<int> none = chooseVideoMode({}, {kRgb888}, 0, 0, 0, {}, "colour");
  ASSERT_FALSE(none.isOk());
  EXPECT_TRUE(contains(none.status().message(), "none")) << none.status().message();
}

TEST(OpenNI2Intrinsics, FromFieldOfView) {
  // A 90 degree horizontal field of view over 640 pixels: fx = 320 exactly.
  const CameraIntrinsics k = intrinsicsFromFov(640, 480, M_PI / 2, 2 * std::atan(0.75));
  EXPECT_NEAR(k.fx, 320.0, 1e-9);
  EXPECT_NEAR(k.fy, 320.0, 1e-9);  // tan(vfov / 2) = 0.75 = 240 / 320
  EXPECT_DOUBLE_EQ(k.cx, 320.0);
  EXPECT_DOUBLE_EQ(k.cy, 240.0);
  EXPECT_EQ(k.width, 640);
  EXPECT_EQ(k.height, 480);
  // The Carmine's nominal 58 degrees at 640 pixels: about 577 (its datasheet's focal length).
  EXPECT_NEAR(intrinsicsFromFov(640, 480, 58.0 * M_PI / 180, 45.0 * M_PI / 180).fx, 577.3, 0.1);
  // A pixel at the image edge back-projects along the edge of the field of view.
  const double hfov = 1.0;
  const CameraIntrinsics e = intrinsicsFromFov(320, 240, hfov, 0.8);
  EXPECT_NEAR(std::atan((320 - e.cx) / e.fx), hfov / 2, 1e-12);
}

TEST(OpenNI2Uri, OniRecordingsAreRecognised) {
  EXPECT_TRUE(isOniRecordingUri("/data/session.oni"));
  EXPECT_TRUE(isOniRecordingUri("CAPTURE.ONI"));
  EXPECT_FALSE(isOniRecordingUri("Dummy"));
  EXPECT_FALSE(isOniRecordingUri("1d27/0601@1/5"));
  EXPECT_FALSE(isOniRecordingUri("oni"));
  EXPECT_FALSE(isOniRecordingUri("x.onix"));
}

TEST(OpenNI2Clock, DeviceStampsMoveOntoTheHostClock) {
  DeviceClockMapper clock;
  // First frame: device 33 ms, received at host 5 s: offset 5 s - 33 ms.
  EXPECT_EQ(clock.toHostNs(33'000, 5'000'000'000), 5'000'000'000);
  // Later frames follow the device's clock, not the (jittery) receive time.
  EXPECT_EQ(clock.toHostNs(66'000, 5'040'000'000), 5'033'000'000);
  EXPECT_EQ(clock.toHostNs(99'000, 5'060'000'000), 5'066'000'000);
  EXPECT_EQ(clock.reanchors(), 0u);
  // The device clock steps back (device reset): anchored again.
  EXPECT_EQ(clock.toHostNs(10'000, 9'000'000'000), 9'000'000'000);
  EXPECT_EQ(clock.reanchors(), 1u);
  // A restart anchors anew without counting a step.
  clock.reset();
  EXPECT_EQ(clock.toHostNs(500'000, 12'000'000'000), 12'000'000'000);
  EXPECT_EQ(clock.reanchors(), 1u);
  // A stamp beyond int64 nanoseconds saturates instead of overflowing.
  clock.reset();
  EXPECT_EQ(clock.toHostNs(UINT64_MAX, 0), 0);  // saturated, then anchored: no overflow
  EXPECT_EQ(clock.toHostNs(UINT64_MAX, 1), 0);
}

TEST(OpenNI2Camera, OniRecordingIsRefusedWithAReason) {
  for (const char* uri : {"/tmp/no-such-recording.oni", "session.ONI"}) {
    std::unique_ptr<Camera> camera = makeCamera(uri);
    ASSERT_NE(camera, nullptr);
    const Status s = camera->open();
    ASSERT_FALSE(s.isOk()) << uri;
    EXPECT_EQ(s.code(), ErrorCode::kInvalidArgument);
    EXPECT_TRUE(contains(s.message(), ".oni recording")) << s.message();
    EXPECT_TRUE(contains(s.message(), "without frames")) << s.message();
    EXPECT_TRUE(contains(s.message(), "tum:PATH")) << s.message();
    EXPECT_FALSE(camera->start().isOk());
  }
}

// ------------------------------------------------------- OpenNI2's runtime

TEST(OpenNI2Camera, FirstDeviceWhenNoneIsPluggedInSaysWhatToDo) {
  SKIP_UNDER_QEMU_USER();
  Result<std::vector<DeviceListing>> listed = discoverOpenNI2Cameras();
  ASSERT_TRUE(listed.isOk()) << listed.status().toString();
  if (!listed->empty()) GTEST_SKIP() << "an OpenNI2 device is plugged in (" << listed->front().spec << ")";
  std::unique_ptr<Camera> camera = makeCamera("");
  ASSERT_NE(camera, nullptr);
  const Status s = camera->open();
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.code(), ErrorCode::kNotFound);
  EXPECT_TRUE(contains(s.message(), "no OpenNI2 device found")) << s.message();
  EXPECT_TRUE(contains(s.message(), "lsusb")) << s.message();
  EXPECT_TRUE(contains(s.message(), "2bc5")) << s.message();
  EXPECT_TRUE(contains(s.message(), "udev rules")) << s.message();
  EXPECT_FALSE(camera->start().isOk());
}

TEST(OpenNI2Camera, UnknownUriIsNotFound) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> camera = makeCamera("2bc5/0401@9/99");
  ASSERT_NE(camera, nullptr);
  const Status s = camera->open();
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.code(), ErrorCode::kNotFound);
  EXPECT_TRUE(contains(s.message(), "cannot open device '2bc5/0401@9/99'")) << s.message();
  EXPECT_TRUE(contains(s.message(), "udev")) << s.message();
}

TEST(OpenNI2Dummy, OpensWithItsModesModelAndNominalIntrinsics) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> camera = makeCamera("Dummy");
  ASSERT_NE(camera, nullptr);
  ASSERT_OK(camera->open());
  OpenNI2Camera& cam = asOpenNI2(*camera);
  const CameraInfo& info = camera->info();
  EXPECT_EQ(info.name, "openni2:Dummy");
  EXPECT_EQ(info.model, "Table Tennis");  // the Dummy driver's vendor string; it has no name
  EXPECT_EQ(info.serial, "");
  EXPECT_EQ(cam.depthMode().width, 320);
  EXPECT_EQ(cam.depthMode().height, 240);
  EXPECT_EQ(cam.depthMode().pixel_format, kDepth1Mm);
  EXPECT_EQ(cam.colourMode().pixel_format, kRgb888);
  EXPECT_DOUBLE_EQ(info.depth_scale_m, 0.001);
  EXPECT_DOUBLE_EQ(info.fps, 30.0);
  EXPECT_TRUE(cam.colourEnabled());
  EXPECT_FALSE(cam.hardwareRegistration());  // the Dummy does not offer it
  // It reports a zero field of view: the nominal one, said in a note.
  const CameraIntrinsics expected = intrinsicsFromFov(320, 240, 58.0 * M_PI / 180, 45.0 * M_PI / 180);
  EXPECT_DOUBLE_EQ(info.intrinsics.fx, expected.fx);
  EXPECT_DOUBLE_EQ(info.intrinsics.fy, expected.fy);
  EXPECT_DOUBLE_EQ(info.intrinsics.cx, 160.0);
  EXPECT_EQ(info.intrinsics.width, 320);
  ASSERT_EQ(cam.notes().size(), 2u);
  EXPECT_TRUE(contains(cam.notes()[0], "nominal 58 x 45 degrees")) << cam.notes()[0];
  EXPECT_TRUE(contains(cam.notes()[1], "delivered unregistered")) << cam.notes()[1];
}

TEST(OpenNI2Dummy, WrongSizeListsTheModes) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> camera = makeCamera("Dummy,size=640x480");
  ASSERT_NE(camera, nullptr);
  const Status s = camera->open();
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.code(), ErrorCode::kInvalidArgument);
  EXPECT_TRUE(contains(s.message(), "no mode 640x480")) << s.message();
  EXPECT_TRUE(contains(s.message(), "320x240 @ 30 fps DEPTH_1_MM")) << s.message();
  // The right size is fine.
  std::unique_ptr<Camera> ok = makeCamera("Dummy,size=320x240,fps=30");
  ASSERT_OK(ok->open());
}

// The Dummy's colour thread can fall whole frames behind its depth on a loaded
// machine, for good (see hal/camera/openni2/openni2_camera.cpp): acquire() then
// says "out of step", and a restart, as hal::CaptureRetry does, aligns the
// streams again. Up to kMaxRealigns such restarts per test; anything else fails.
constexpr int kMaxRealigns = 10;
Status acquireRealigning(Camera& camera, RgbdFrame& slot, int& restarts) {
  Status s = camera.acquire(slot, milliseconds(2000));
  while (!s.isOk() && s.message() == "out of step" && restarts < kMaxRealigns) {
    ++restarts;
    camera.stop();
    if (Status started = camera.start(); !started.isOk()) return started;
    s = camera.acquire(slot, milliseconds(2000));
  }
  return s;
}

TEST(OpenNI2Dummy, DeliversAHundredPairedFramesWithoutAllocatingItself) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> camera = makeCamera("Dummy");
  ASSERT_NE(camera, nullptr);
  ASSERT_OK(camera->open());
  OpenNI2Camera& cam = asOpenNI2(*camera);
  RgbdFrame slot(640, 480);
  ASSERT_OK(camera->start());
  // A few frames first: OpenNI2 grows its frame pool as the streams start.
  for (int i = 0; i < 5; ++i) ASSERT_OK(camera->acquire(slot, milliseconds(2000)));

  const uint64_t released_before = cam.framesReleased();
  const uint64_t thread_before = test::threadAllocationCount();
  int64_t previous_stamp = slot.stamp_ns;
  uint64_t previous_sequence = slot.sequence;
  std::size_t with_depth = 0;
  int restarts = 0;
  {
    test::AllocationScope scope;
    for (int i = 0; i < 100; ++i) {
      const Status s = acquireRealigning(*camera, slot, restarts);
      ASSERT_TRUE(s.isOk()) << s.toString() << " at frame " << i << "; paired " << cam.pairingCounts().paired
                            << ", depth unmatched " << cam.pairingCounts().depth_unmatched << ", colour dropped "
                            << cam.pairingCounts().colour_dropped << ", released " << cam.framesReleased();
      if (restarts == 0) {
        ASSERT_GT(slot.stamp_ns, previous_stamp);
      }
      ASSERT_EQ(slot.sequence, previous_sequence + 1);
      previous_stamp = slot.stamp_ns;
      previous_sequence = slot.sequence;
      for (std::size_t p = 0; p < slot.pixelCount(); ++p) with_depth += slot.depth()[p] != 0;
    }
  }
  const uint64_t ours = test::threadAllocationCount() - thread_before;
  const uint64_t released = cam.framesReleased() - released_before;
  // libOpenNI2 allocates one 24-byte list node when a frame goes back to its
  // pool (oniFrameRelease); nothing else on this thread may allocate.
  if (restarts == 0) {
    EXPECT_LE(ours, released) << "acquire() allocated beyond libOpenNI2's one node per released frame";
  }
  EXPECT_GE(released, 200u - 3);  // a depth and a colour frame per delivered frame (3 depth frames may wait)
  std::printf("[ measured ] 100 frames: %llu allocations on the acquiring thread, %llu OpenNI2 frames released\n",
              static_cast<unsigned long long>(ours), static_cast<unsigned long long>(released));

  EXPECT_EQ(slot.width(), 320);
  EXPECT_EQ(slot.height(), 240);
  EXPECT_TRUE(slot.has_rgb);
  EXPECT_GT(with_depth, 100u * 300);  // the Dummy draws a few hundred pixels of depth each frame
  EXPECT_DOUBLE_EQ(slot.intrinsics.fx, camera->info().intrinsics.fx);
  EXPECT_DOUBLE_EQ(slot.depth_scale_m, 0.001);
  const CameraCounters c = camera->counters();
  EXPECT_EQ(c.frames_delivered, 105u);
  EXPECT_EQ(c.bad_frames, 0u);
  EXPECT_EQ(c.errors, static_cast<uint64_t>(restarts));  // each "out of step" counts
  EXPECT_EQ(c.disconnects, 0u);
  // Every delivered frame is a pair. The Dummy's colour thread runs slower
  // than its depth thread (each sleeps 33 ms after building its frame), so
  // some depth frames find no colour frame and are dropped, counted.
  EXPECT_EQ(cam.pairingCounts().paired, 105u);
  std::printf("[ measured ] depth frames without colour (dropped): %llu\n",
              static_cast<unsigned long long>(cam.pairingCounts().depth_unmatched));
  camera->stop();
}

TEST(OpenNI2Dummy, StampsAreOnTheMonotonicClock) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> camera = makeCamera("Dummy");
  ASSERT_OK(camera->open());
  ASSERT_OK(camera->start());
  RgbdFrame slot(320, 240);
  ASSERT_OK(camera->acquire(slot, milliseconds(2000)));
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  const int64_t now_ns = static_cast<int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec;
  EXPECT_LE(slot.stamp_ns, now_ns);
  EXPECT_GT(slot.stamp_ns, now_ns - 60'000'000'000);  // not the device's clock, which starts near 0
  const int64_t first = slot.stamp_ns;
  ASSERT_OK(camera->acquire(slot, milliseconds(2000)));
  EXPECT_EQ(slot.stamp_ns - first, 33'000'000);  // the Dummy's device stamps step 33 000 us
}

TEST(OpenNI2Dummy, ColourOffGivesDepthOnly) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> camera = makeCamera("Dummy,colour=off");
  ASSERT_OK(camera->open());
  EXPECT_FALSE(asOpenNI2(*camera).colourEnabled());
  ASSERT_OK(camera->start());
  RgbdFrame slot(320, 240);
  for (int i = 0; i < 5; ++i) ASSERT_OK(camera->acquire(slot, milliseconds(2000)));
  EXPECT_FALSE(slot.has_rgb);
  EXPECT_EQ(camera->counters().frames_delivered, 5u);
}

TEST(OpenNI2Dummy, StopStartAndReopenCycles) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> camera = makeCamera("Dummy");
  RgbdFrame slot(320, 240);
  for (int cycle = 0; cycle < 3; ++cycle) {
    ASSERT_OK(camera->open());
    for (int run = 0; run < 2; ++run) {
      SCOPED_TRACE("cycle " + std::to_string(cycle) + " run " + std::to_string(run));
      ASSERT_OK(camera->start());
      int restarts = 0;
      for (int i = 0; i < 3; ++i) ASSERT_OK(acquireRealigning(*camera, slot, restarts));
      camera->stop();
      const Status stopped = camera->acquire(slot, milliseconds(10));
      EXPECT_EQ(stopped.code(), ErrorCode::kUnavailable);
    }
  }
  EXPECT_EQ(camera->counters().frames_delivered, 18u);
  // Destroyed while streaming: stops, closes and lets the runtime go, no crash.
  // (Realigning here too: CI's asan-tests saw "out of step" on this acquire.)
  ASSERT_OK(camera->start());
  int restarts = 0;
  ASSERT_OK(acquireRealigning(*camera, slot, restarts));
  camera.reset();
  // The runtime comes back for the next camera.
  std::unique_ptr<Camera> again = makeCamera("Dummy");
  ASSERT_OK(again->open());
  ASSERT_OK(again->start());
  ASSERT_OK(acquireRealigning(*again, slot, restarts));
}

TEST(OpenNI2Dummy, SlotTooSmallAndNotStarted) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> camera = makeCamera("Dummy");
  ASSERT_OK(camera->open());
  RgbdFrame slot(320, 240);
  EXPECT_EQ(camera->acquire(slot, milliseconds(10)).code(), ErrorCode::kUnavailable);
  ASSERT_OK(camera->start());
  RgbdFrame small(160, 120);
  EXPECT_EQ(camera->acquire(small, milliseconds(10)).code(), ErrorCode::kCapacityExceeded);
  EXPECT_EQ(camera->counters().errors, 2u);
}

TEST(OpenNI2Dummy, CalibrationOverridesTheIntrinsics) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> camera = makeCamera("Dummy");
  CameraCalibration calibration;
  calibration.source = "dummy.yaml";
  calibration.depth = StreamCalibration{{320, 240, 290.0, 291.0, 159.5, 119.5}, {}};
  calibration.depth_scale_m = 0.00125;
  ASSERT_OK(camera->setCalibration(calibration));
  ASSERT_OK(camera->open());
  EXPECT_DOUBLE_EQ(camera->info().intrinsics.fx, 290.0);
  EXPECT_DOUBLE_EQ(camera->info().intrinsics.cy, 119.5);
  EXPECT_DOUBLE_EQ(camera->info().depth_scale_m, 0.00125);
  // Calibrated: no note about the nominal field of view.
  for (const std::string& note : asOpenNI2(*camera).notes()) EXPECT_FALSE(contains(note, "nominal")) << note;

  // A calibration of another size is refused at open(), naming both.
  calibration.depth->intrinsics.width = 640;
  calibration.depth->intrinsics.height = 480;
  ASSERT_OK(camera->setCalibration(calibration));
  const Status s = camera->open();
  ASSERT_FALSE(s.isOk());
  EXPECT_TRUE(contains(s.message(), "dummy.yaml is for 640x480")) << s.message();
  EXPECT_TRUE(contains(s.message(), "320x240")) << s.message();

  // Colour calibration and extrinsics: not used by this backend, so refused.
  CameraCalibration colour;
  colour.source = "stereo.yaml";
  colour.T_colour_depth = Pose();
  const Status refused = camera->setCalibration(colour);
  EXPECT_EQ(refused.code(), ErrorCode::kInvalidArgument);
  EXPECT_TRUE(contains(refused.message(), "stereo.yaml")) << refused.message();
}

TEST(OpenNI2Dummy, TwoCamerasAndDiscoveryShareTheRuntime) {
  SKIP_UNDER_QEMU_USER();
  std::unique_ptr<Camera> a = makeCamera("Dummy");
  std::unique_ptr<Camera> b = makeCamera("Dummy,colour=off");
  ASSERT_OK(a->open());
  ASSERT_OK(b->open());
  ASSERT_OK(a->start());
  RgbdFrame slot(320, 240);
  ASSERT_OK(a->acquire(slot, milliseconds(2000)));
  // Discovery holds and lets go of the runtime while the cameras run; the
  // Dummy (enumerated now that it is open) is not listed as a camera.
  Result<std::vector<DeviceListing>> listed = discoverOpenNI2Cameras();
  ASSERT_TRUE(listed.isOk()) << listed.status().toString();
  for (const DeviceListing& d : listed.value()) EXPECT_NE(d.spec, "openni2:Dummy");
  b.reset();
  ASSERT_OK(a->acquire(slot, milliseconds(2000)));
  a->stop();
}

TEST(OpenNI2Dummy, ThroughTheBackendTable) {
  SKIP_UNDER_QEMU_USER();
  Result<std::unique_ptr<Camera>> camera = createCamera("openni2:Dummy");
  ASSERT_TRUE(camera.isOk()) << camera.status().toString();
  ASSERT_OK(camera.value()->open());
  EXPECT_TRUE(contains(cameraSpecHelp(), "openni2:[URI]"));
  bool listed = false;
  for (const CameraDiscovery& d : discoverCameras()) {
    if (d.backend == "openni2") listed = d.devices.isOk();
  }
  EXPECT_TRUE(listed);
}

}  // namespace
}  // namespace fovea::hal::openni2
