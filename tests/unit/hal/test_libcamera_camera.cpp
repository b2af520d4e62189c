// The libcamera backend: spec parsing and pixel conversion without a camera;
// the real libcamera 0.0.3 with no camera (this host) for discovery and the
// errors; and frames from the vimc virtual camera where a kernel has it.
#include "hal/camera/libcamera/libcamera_camera.h"

#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "hal/camera.h"
#include "tests/support/alloc_counter.h"

namespace fovea::hal::libcam {
namespace {

using std::chrono::milliseconds;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

bool libcameraSeesCameras() {
  Result<std::vector<DeviceListing>> listed = discoverLibcameraCameras();
  return listed.isOk() && !listed->empty();
}

CameraCalibration exampleCalibration(int colour_width, int colour_height) {
  CameraCalibration c;
  c.source = "test calibration";
  c.colour = StreamCalibration{{colour_width, colour_height, 600.0, 600.0, colour_width / 2.0, colour_height / 2.0},
                               {}};
  Pose t;
  t.t_world_cam = Eigen::Vector3d(0.025, 0, 0);
  c.T_colour_depth = t;
  return c;
}

// ---------------------------------------------------------------- no camera

TEST(LibcameraOptions, SpecWithEveryKeyAndADepthSpecWithCommas) {
  Result<LibcameraCameraOptions> o =
      parseLibcameraCameraOptions("1,size=1280x720,format=XRGB8888,buffers=6,depth=v4l2:serial=123,colour=none");
  ASSERT_TRUE(o.isOk()) << o.status().toString();
  EXPECT_EQ(o->camera, "1");
  EXPECT_EQ(o->width, 1280);
  EXPECT_EQ(o->height, 720);
  EXPECT_EQ(o->format, "XRGB8888");
  EXPECT_EQ(o->buffers, 6);
  EXPECT_EQ(o->depth_spec, "v4l2:serial=123,colour=none");  // the rest of the spec is the depth camera's
  Result<LibcameraCameraOptions> id =
      parseLibcameraCameraOptions("/base/soc/i2c0mux/i2c@1/imx219@10,depth=openni2:Dummy");
  ASSERT_TRUE(id.isOk()) << id.status().toString();
  EXPECT_EQ(id->camera, "/base/soc/i2c0mux/i2c@1/imx219@10");
  EXPECT_EQ(id->buffers, 4);
  EXPECT_EQ(id->format, "");
}

TEST(LibcameraOptions, BadSpecsSayWhatIsWrong) {
  const struct {
    const char* args;
    const char* says;
  } cases[] = {
      {"0", "depth=SPEC is required"},
      {"0,size=1280x720", "depth=SPEC is required"},
      {"depth=v4l2:/dev/video0", "name the colour camera first"},
      {"", "expected libcamera:N|ID"},
      {"0,size=big,depth=mock:living-room", "size: expected WxH"},
      {"0,format=YUYV,depth=mock:living-room", "use the v4l2 backend"},
      {"0,format=MJPEG,depth=mock:living-room", "BGR888, RGB888"},
      {"0,buffers=1,depth=mock:living-room", "buffers: expected 2..32"},
      {"0,exposure=3,depth=mock:living-room", "unknown option 'exposure'"},
      {"0,depth=libcamera:1,depth=x", "another backend"},
  };
  for (const auto& c : cases) {
    Result<LibcameraCameraOptions> parsed = parseLibcameraCameraOptions(c.args);
    ASSERT_FALSE(parsed.isOk()) << c.args;
    EXPECT_EQ(parsed.status().code(), ErrorCode::kInvalidArgument) << c.args;
    EXPECT_TRUE(contains(parsed.status().message(), c.says)) << c.args << ": " << parsed.status().message();
  }
  // The depth camera's spec is checked when the camera is made.
  Result<std::unique_ptr<Camera>> bad = createCamera("libcamera:0,depth=mock:living-room,fps=-1");
  ASSERT_FALSE(bad.isOk());
  EXPECT_TRUE(contains(bad.status().message(), "depth=mock:living-room,fps=-1")) << bad.status().message();
  Result<std::unique_ptr<Camera>> unknown = createCamera("libcamera:0,depth=kinect:1");
  ASSERT_FALSE(unknown.isOk());
  EXPECT_TRUE(contains(unknown.status().message(), "unknown backend 'kinect'")) << unknown.status().message();
}

TEST(LibcameraFormats, PackedRgbIntoRgb8) {
  // One 2x2 image per format, with 2 bytes of row padding; pixel i has R = 10 + i, G = 20 + i, B = 30 + i.
  const struct {
    const char* name;
    int bpp;
  } formats[] = {{"BGR888", 3}, {"RGB888", 3}, {"XBGR8888", 4}, {"XRGB8888", 4}};
  for (const auto& f : formats) {
    const std::optional<PackedRgbLayout> layout = packedRgbLayout(f.name);
    ASSERT_TRUE(layout.has_value()) << f.name;
    ASSERT_EQ(layout->bytes_per_pixel, f.bpp);
    const std::size_t stride = 2 * f.bpp + 2;
    std::vector<uint8_t> src(stride * 2, 0xEE);
    const bool memory_rgb = std::string(f.name).find("BGR") != std::string::npos;  // DRM names: BGR888 is R,G,B
    for (int i = 0; i < 4; ++i) {
      uint8_t* p = src.data() + stride * (i / 2) + f.bpp * (i % 2);
      p[0] = static_cast<uint8_t>(memory_rgb ? 10 + i : 30 + i);
      p[1] = static_cast<uint8_t>(20 + i);
      p[2] = static_cast<uint8_t>(memory_rgb ? 30 + i : 10 + i);
      if (f.bpp == 4) p[3] = 0x55;
    }
    std::vector<uint8_t> rgb(12, 0);
    ASSERT_TRUE(packedRgbToRgb8(*layout, src.data(), src.size(), stride, 2, 2, rgb.data())) << f.name;
    for (int i = 0; i < 4; ++i) {
      EXPECT_EQ(rgb[3 * i + 0], 10 + i) << f.name << " pixel " << i;
      EXPECT_EQ(rgb[3 * i + 1], 20 + i) << f.name << " pixel " << i;
      EXPECT_EQ(rgb[3 * i + 2], 30 + i) << f.name << " pixel " << i;
    }
    // A frame one byte short, or a stride shorter than a row: refused, nothing written.
    std::vector<uint8_t> untouched(12, 7);
    const std::size_t needed = stride + 2 * f.bpp;
    EXPECT_FALSE(packedRgbToRgb8(*layout, src.data(), needed - 1, stride, 2, 2, untouched.data())) << f.name;
    EXPECT_FALSE(packedRgbToRgb8(*layout, src.data(), src.size(), 2 * f.bpp - 1, 2, 2, untouched.data()));
    EXPECT_EQ(untouched, std::vector<uint8_t>(12, 7));
    EXPECT_TRUE(packedRgbToRgb8(*layout, src.data(), needed, stride, 2, 2, rgb.data())) << f.name;
  }
  EXPECT_FALSE(packedRgbLayout("YUYV").has_value());
  EXPECT_FALSE(packedRgbLayout("NV12").has_value());
}

// ------------------------------------------ the real libcamera, no camera

TEST(LibcameraHost, DiscoveryRunsWithZeroCameras) {
  Result<std::vector<DeviceListing>> listed = discoverLibcameraCameras();
  ASSERT_TRUE(listed.isOk()) << listed.status().toString();
  if (!listed->empty()) GTEST_SKIP() << "libcamera sees a camera here (" << listed->front().detail << ")";
  EXPECT_TRUE(listed->empty());
  // Twice: the camera manager is stopped and made again.
  EXPECT_TRUE(discoverLibcameraCameras().isOk());
}

TEST(LibcameraHost, NoCameraSaysWhatToCheck) {
  if (libcameraSeesCameras()) GTEST_SKIP() << "libcamera sees a camera here";
  ColourStream stream;
  LibcameraCameraOptions options;
  options.camera = "0";
  options.depth_spec = "mock:living-room";
  const Status s = stream.open(options);
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.code(), ErrorCode::kNotFound);
  EXPECT_TRUE(contains(s.message(), "libcamera: no camera found")) << s.message();
  EXPECT_TRUE(contains(s.message(), "cam --list")) << s.message();
  EXPECT_FALSE(stream.start().isOk());
}

TEST(LibcameraHost, OpenWithoutCalibrationSaysWhatToGive) {
  Result<std::unique_ptr<Camera>> camera = createCamera("libcamera:0,depth=mock:living-room,size=160x120");
  ASSERT_TRUE(camera.isOk()) << camera.status().toString();
  const Status s = camera.value()->open();
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.code(), ErrorCode::kInvalidArgument);
  EXPECT_TRUE(contains(s.message(), "T_colour_depth")) << s.message();
  EXPECT_FALSE(camera.value()->start().isOk());
}

TEST(LibcameraHost, WithCalibrationTheDepthCameraOpensAndTheMissingColourCameraIsNamed) {
  if (libcameraSeesCameras()) GTEST_SKIP() << "libcamera sees a camera here";
  Result<std::unique_ptr<Camera>> camera = createCamera("libcamera:0,depth=mock:living-room,size=160x120");
  ASSERT_TRUE(camera.isOk());
  ASSERT_TRUE(camera.value()->setCalibration(exampleCalibration(640, 480)).isOk());
  const Status s = camera.value()->open();
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.code(), ErrorCode::kNotFound);
  EXPECT_TRUE(contains(s.message(), "no camera found")) << s.message();
  // Open again: still a clear error, no crash, nothing leaked into a second manager.
  EXPECT_EQ(camera.value()->open().code(), ErrorCode::kNotFound);
}

// ------------------------------------------- acquire() with a fake colour source

// Passes a mock depth camera through and notes its last stamp, so that the fake
// colour source below can deliver "the colour frame taken with it".
class StampNotingCamera final : public Camera {
 public:
  StampNotingCamera(std::unique_ptr<Camera> inner, int64_t* last_stamp_ns)
      : inner_(std::move(inner)), last_stamp_ns_(last_stamp_ns) {}
  Status open() override { return inner_->open(); }
  Status start() override { return inner_->start(); }
  Status acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) override {
    const Status s = inner_->acquire(slot, timeout);
    if (s) *last_stamp_ns_ = slot.stamp_ns;
    return s;
  }
  void stop() override { inner_->stop(); }
  const CameraInfo& info() const override { return inner_->info(); }
  CameraCounters counters() const override { return inner_->counters(); }

 private:
  std::unique_ptr<Camera> inner_;
  int64_t* last_stamp_ns_;
};

// Colour frames k = 0, 1, ... stamped k / fps (the mock depth camera's stamps),
// each available once the depth frame of that stamp has been taken; BGR888
// (R, G, B in memory) of one colour: R = 10 + k % 200, G = 100, B = 200.
class FakeColour final : public ColourSource {
 public:
  FakeColour(int width, int height, double fps, const int64_t* depth_stamp_ns, bool deliver)
      : width_(width), height_(height), period_ns_(1e9 / fps), depth_stamp_ns_(depth_stamp_ns), deliver_(deliver),
        image_(static_cast<std::size_t>(width) * height * 3) {}
  Status open(const LibcameraCameraOptions&) override { return Status::ok(); }
  Status start() override {
    next_ = 0;
    return Status::ok();
  }
  Status next(ColourFrame& frame, std::chrono::nanoseconds) override {
    const auto stamp = static_cast<int64_t>(std::llround(static_cast<double>(next_) * period_ns_));
    if (!deliver_ || *depth_stamp_ns_ < 0 || stamp > *depth_stamp_ns_) return Status(ErrorCode::kUnavailable, "t");
    for (std::size_t p = 0; p < image_.size(); p += 3) {
      image_[p] = static_cast<uint8_t>(10 + next_ % 200);
      image_[p + 1] = 100;
      image_[p + 2] = 200;
    }
    frame.data = image_.data();
    frame.bytes = image_.size();
    frame.stride = static_cast<std::size_t>(width_) * 3;
    frame.stamp_ns = stamp;
    frame.token = next_++;
    ++outstanding_;
    return Status::ok();
  }
  void release(const ColourFrame&) override { --outstanding_; }
  void stop() override {}
  void close() override {}
  const std::string& id() const override { return id_; }
  const std::string& model() const override { return id_; }
  int width() const override { return width_; }
  int height() const override { return height_; }
  const PackedRgbLayout& layout() const override { return layout_; }
  uint64_t failedFrames() const override { return 0; }
  std::size_t mappedBytes() const override { return image_.size(); }
  int outstanding() const { return outstanding_; }

 private:
  int width_, height_;
  double period_ns_;
  const int64_t* depth_stamp_ns_;
  bool deliver_;
  std::vector<uint8_t> image_;
  uint64_t next_ = 0;
  int outstanding_ = 0;
  std::string id_ = "fake";
  PackedRgbLayout layout_ = *packedRgbLayout("BGR888");
};

struct FakeRig {
  int64_t depth_stamp_ns = -1;
  FakeColour* colour = nullptr;
  std::unique_ptr<LibcameraCamera> camera;
};

FakeRig makeFakeRig(bool deliver_colour) {
  FakeRig rig;
  Result<std::unique_ptr<Camera>> mock = createCamera("mock:living-room,size=160x120,noise=off");
  EXPECT_TRUE(mock.isOk());
  auto depth = std::make_unique<StampNotingCamera>(std::move(mock).value(), &rig.depth_stamp_ns);
  auto colour = std::make_unique<FakeColour>(160, 120, 30.0, &rig.depth_stamp_ns, deliver_colour);
  rig.colour = colour.get();
  LibcameraCameraOptions options;
  options.camera = "0";
  options.depth_spec = "mock:living-room,size=160x120,noise=off";
  rig.camera = std::make_unique<LibcameraCamera>(options, std::move(depth), std::move(colour));
  return rig;
}

TEST(LibcameraAcquire, ColourIsPairedByStampAndRegisteredWithoutAllocating) {
  FakeRig rig = makeFakeRig(true);
  // The colour camera sees what the depth camera sees (same intrinsics, no offset).
  CameraCalibration calibration;
  calibration.source = "identity";
  calibration.colour = StreamCalibration{{160, 120, 525.0 * 160 / 640, 525.0 * 160 / 640, 79.5, 59.5}, {}};
  calibration.T_colour_depth = Pose();
  ASSERT_TRUE(rig.camera->setCalibration(calibration).isOk());
  const Status opened = rig.camera->open();
  ASSERT_TRUE(opened.isOk()) << opened.toString();
  EXPECT_EQ(rig.camera->info().name, "libcamera:0");
  EXPECT_EQ(rig.camera->info().intrinsics.width, 160);  // the depth camera's
  ASSERT_TRUE(rig.camera->start().isOk());
  RgbdFrame slot(160, 120);
  ASSERT_TRUE(rig.camera->acquire(slot, milliseconds(1000)).isOk());  // warm-up
  test::AllocationScope scope;
  for (int i = 1; i <= 30; ++i) {
    const Status s = rig.camera->acquire(slot, milliseconds(1000));
    ASSERT_TRUE(s.isOk()) << s.toString();
    ASSERT_TRUE(slot.has_rgb) << "frame " << i;
    // Every pixel with depth shows colour frame i (same stamp): R = 10 + i, G = 100, B = 200.
    std::size_t coloured = 0, with_depth = 0;
    for (std::size_t p = 0; p < slot.pixelCount(); ++p) {
      if (slot.depth()[p] == 0) continue;
      ++with_depth;
      const uint8_t* rgb = slot.rgb() + 3 * p;
      coloured += rgb[0] == 10 + i && rgb[1] == 100 && rgb[2] == 200;
    }
    ASSERT_GT(with_depth, 1000u);
    EXPECT_EQ(coloured, with_depth) << "frame " << i;
  }
  EXPECT_EQ(scope.allocations(), 0u);
  EXPECT_EQ(rig.camera->pairingCounts().paired, 31u);
  EXPECT_EQ(rig.camera->pairingCounts().depth_unmatched, 0u);
  EXPECT_EQ(rig.colour->outstanding(), 0);  // every colour frame given back
  EXPECT_EQ(rig.camera->counters().frames_delivered, 31u);
  rig.camera->stop();
}

TEST(LibcameraAcquire, NoColourFrameGivesDepthWithoutColourCounted) {
  FakeRig rig = makeFakeRig(false);
  CameraCalibration calibration;
  calibration.source = "identity";
  calibration.colour = StreamCalibration{{160, 120, 131.25, 131.25, 79.5, 59.5}, {}};
  calibration.T_colour_depth = Pose();
  ASSERT_TRUE(rig.camera->setCalibration(calibration).isOk());
  ASSERT_TRUE(rig.camera->open().isOk());
  ASSERT_TRUE(rig.camera->start().isOk());
  RgbdFrame slot(160, 120);
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(rig.camera->acquire(slot, milliseconds(1000)).isOk());
    EXPECT_FALSE(slot.has_rgb);
  }
  EXPECT_EQ(rig.camera->pairingCounts().depth_unmatched, 3u);
  EXPECT_EQ(rig.camera->pairingCounts().paired, 0u);
}

TEST(LibcameraAcquire, ColourCalibrationOfAnotherSizeIsRefused) {
  FakeRig rig = makeFakeRig(true);
  ASSERT_TRUE(rig.camera->setCalibration(exampleCalibration(640, 480)).isOk());
  const Status s = rig.camera->open();
  ASSERT_FALSE(s.isOk());
  EXPECT_TRUE(contains(s.message(), "is for 640x480")) << s.message();
  EXPECT_TRUE(contains(s.message(), "streams 160x120")) << s.message();
}

// ------------------------------------------------------------------- vimc

// The vimc virtual camera, where a kernel has the driver. Debian 12's arm64
// kernel (the VM's) is built without it (CONFIG_VIDEO_VIMC is not set), so on
// this project's machines this skips; docs/cameras-libcamera.md says more.
TEST(LibcameraVimc, ColourStreamCapturesFrames) {
  Result<std::vector<DeviceListing>> listed = discoverLibcameraCameras();
  ASSERT_TRUE(listed.isOk()) << listed.status().toString();
  std::string vimc_spec;
  for (const DeviceListing& d : listed.value()) {
    if (contains(d.detail, "platform/vimc")) vimc_spec = d.spec;
  }
  if (vimc_spec.empty()) {
    GTEST_SKIP() << "no vimc camera: libcamera 0.0.3 (Debian 12) has the vimc pipeline handler, but Debian 12's "
                    "kernels are built with CONFIG_VIDEO_VIMC not set (checked in linux-image-6.1.0-*-arm64's "
                    "config), so neither this host nor the arm64 VM can load vimc; the handler also needs "
                    "ipa_vimc.so from libcamera-ipa";
  }
  LibcameraCameraOptions options;
  options.camera = vimc_spec.substr(std::string("libcamera:").size(), vimc_spec.find(',') - 10);
  options.depth_spec = "mock:living-room";
  options.width = 640;
  options.height = 480;
  ColourStream stream;
  ASSERT_TRUE(stream.open(options).isOk());
  ASSERT_TRUE(stream.start().isOk());
  std::vector<uint8_t> rgb(static_cast<std::size_t>(stream.width()) * stream.height() * 3);
  int64_t previous = 0;
  for (int i = 0; i < 10; ++i) {
    ColourStream::Frame frame;
    const Status s = stream.next(frame, milliseconds(3000));
    ASSERT_TRUE(s.isOk()) << s.toString();
    EXPECT_TRUE(packedRgbToRgb8(stream.layout(), frame.data, frame.bytes, frame.stride, stream.width(),
                                stream.height(), rgb.data()));
    EXPECT_GT(frame.stamp_ns, previous);
    previous = frame.stamp_ns;
    stream.release(frame);
  }
  stream.stop();
  EXPECT_EQ(stream.failedFrames(), 0u);
}

}  // namespace
}  // namespace fovea::hal::libcam
