// The V4L2 camera's spec: every selector form, every option, and the errors
// for each malformed one (they name the option and what it accepts).
#include <gtest/gtest.h>

#include <linux/videodev2.h>

#include <string>

#include "hal/camera/v4l2/v4l2_options.h"

namespace fovea::hal::v4l2 {
namespace {

using Kind = NodeSelector::Kind;

V4l2CameraOptions parseOk(const std::string& args) {
  Result<V4l2CameraOptions> r = parseV4l2CameraOptions(args);
  EXPECT_TRUE(r.isOk()) << args << ": " << r.status().message();
  return r.isOk() ? r.value() : V4l2CameraOptions{};
}

std::string parseError(const std::string& args) {
  Result<V4l2CameraOptions> r = parseV4l2CameraOptions(args);
  EXPECT_FALSE(r.isOk()) << args << " parsed";
  if (r.isOk()) return "";
  EXPECT_EQ(r.status().code(), ErrorCode::kInvalidArgument);
  return r.status().message();
}

TEST(V4l2Options, DepthNodeByPathWithDefaults) {
  const V4l2CameraOptions o = parseOk("/dev/video2");
  EXPECT_EQ(o.depth.kind, Kind::kPath);
  EXPECT_EQ(o.depth.value, "/dev/video2");
  EXPECT_EQ(o.colour.kind, Kind::kNone);
  EXPECT_EQ(o.width, 0);
  EXPECT_EQ(o.fps, 0);
  EXPECT_EQ(o.depth_format, 0u);
  EXPECT_DOUBLE_EQ(o.depth_scale_m, 0.001);
  EXPECT_FALSE(o.depth_scale_given);
  EXPECT_EQ(o.buffers, 4);
  EXPECT_EQ(o.pair_tolerance_ns, 0);
  EXPECT_TRUE(o.calib_path.empty());
}

TEST(V4l2Options, DepthNodeBySerialAndByBus) {
  const V4l2CameraOptions s = parseOk("serial=f0233333");
  EXPECT_EQ(s.depth.kind, Kind::kSerial);
  EXPECT_EQ(s.depth.value, "f0233333");
  // bus_info contains ':' and '.'; only ',' separates options.
  const V4l2CameraOptions b = parseOk("bus=usb-0000:01:00.0-1,fps=15");
  EXPECT_EQ(b.depth.kind, Kind::kBus);
  EXPECT_EQ(b.depth.value, "usb-0000:01:00.0-1");
  EXPECT_EQ(b.fps, 15);
  EXPECT_EQ(parseOk("bus=platform:vivid-000").depth.value, "platform:vivid-000");
  EXPECT_EQ(selectorText(b.depth), "bus=usb-0000:01:00.0-1");
  EXPECT_EQ(selectorText(s.depth), "serial=f0233333");
}

TEST(V4l2Options, ColourNodeForms) {
  EXPECT_EQ(parseOk("/dev/video0,colour=none").colour.kind, Kind::kNone);
  EXPECT_EQ(parseOk("/dev/video0,colour=auto").colour.kind, Kind::kAuto);
  const V4l2CameraOptions p = parseOk("/dev/video0,colour=/dev/video4");
  EXPECT_EQ(p.colour.kind, Kind::kPath);
  EXPECT_EQ(p.colour.value, "/dev/video4");
  const V4l2CameraOptions s = parseOk("serial=1,colour=serial=2");
  EXPECT_EQ(s.colour.kind, Kind::kSerial);
  EXPECT_EQ(s.colour.value, "2");
  const V4l2CameraOptions b = parseOk("bus=a,color=bus=platform:vivid-001");
  EXPECT_EQ(b.colour.kind, Kind::kBus);
  EXPECT_EQ(b.colour.value, "platform:vivid-001");
}

TEST(V4l2Options, EveryModeOption) {
  const V4l2CameraOptions o = parseOk(
      "/dev/video0,colour=auto,size=848x480,fps=60,format=Y16,colour_size=1280x720,colour_format=MJPG,"
      "depth_scale=0.0001,calib=/etc/fovea/d435.yaml,buffers=8,pair_tolerance_ms=12.5,hfov_deg=87,"
      "colour_hfov_deg=69,extrinsics=identity");
  EXPECT_EQ(o.width, 848);
  EXPECT_EQ(o.height, 480);
  EXPECT_EQ(o.fps, 60);
  EXPECT_EQ(o.depth_format, V4L2_PIX_FMT_Y16);
  EXPECT_EQ(o.colour_width, 1280);
  EXPECT_EQ(o.colour_height, 720);
  EXPECT_EQ(o.colour_format, V4L2_PIX_FMT_MJPEG);
  EXPECT_DOUBLE_EQ(o.depth_scale_m, 0.0001);
  EXPECT_TRUE(o.depth_scale_given);
  EXPECT_EQ(o.calib_path, "/etc/fovea/d435.yaml");
  EXPECT_EQ(o.buffers, 8);
  EXPECT_EQ(o.pair_tolerance_ns, 12'500'000);
  EXPECT_DOUBLE_EQ(o.hfov_deg, 87.0);
  EXPECT_DOUBLE_EQ(o.colour_hfov_deg, 69.0);
  EXPECT_TRUE(o.extrinsics_identity);
  EXPECT_EQ(parseOk("/dev/video0,format=Z16").depth_format, V4L2_PIX_FMT_Z16);
  EXPECT_EQ(parseOk("/dev/video0,colour=auto,colour_format=YUYV").colour_format, V4L2_PIX_FMT_YUYV);
  EXPECT_EQ(parseOk("/dev/video0,colour=auto,colour_format=UYVY").colour_format, V4L2_PIX_FMT_UYVY);
  EXPECT_EQ(parseOk("/dev/video0,colour=auto,colour_format=RGB3").colour_format, V4L2_PIX_FMT_RGB24);
  EXPECT_EQ(parseOk("/dev/video0,colour=auto,colour_format=BGR3").colour_format, V4L2_PIX_FMT_BGR24);
}

TEST(V4l2Options, BadSelectorsSayTheForms) {
  EXPECT_NE(parseError("").find("v4l2:/dev/videoN|serial=SERIAL|bus=BUS_INFO|auto"), std::string::npos);
  EXPECT_NE(parseError("video0").find("expected /dev/videoN, serial=SERIAL, bus=BUS_INFO or auto"), std::string::npos);
  EXPECT_NE(parseError("serial=").find("names nothing"), std::string::npos);
  EXPECT_NE(parseError("bus=").find("names nothing"), std::string::npos);
  // none is colour-only; auto picks the first depth node.
  EXPECT_NE(parseError("none").find("depth node"), std::string::npos);
  EXPECT_EQ(parseOk("auto,colour=auto").depth.kind, Kind::kAuto);
  EXPECT_NE(parseError("/dev/video0,colour=video4").find("auto or none"), std::string::npos);
}

TEST(V4l2Options, BadOptionsNameTheOption) {
  EXPECT_NE(parseError("/dev/video0,size=640").find("size: expected WxH"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,size=0x480").find("size: expected WxH"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,size=640x480x3").find("size:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,colour=auto,colour_size=axb").find("colour_size:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,fps=0").find("fps: expected an integer in 1..1000"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,fps=29.97").find("fps:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,format=YUYV").find("format: expected Z16|Y16"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,colour=auto,colour_format=Z16").find("YUYV|UYVY|MJPG|RGB3|BGR3"),
            std::string::npos);
  EXPECT_NE(parseError("/dev/video0,depth_scale=0").find("depth_scale:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,depth_scale=nan").find("depth_scale:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,depth_scale=2").find("depth_scale:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,calib=").find("calib:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,buffers=1").find("buffers: expected an integer in 2..32"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,buffers=33").find("buffers:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,pair_tolerance_ms=-1").find("pair_tolerance_ms:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,hfov_deg=200").find("hfov_deg: expected a horizontal field of view"),
            std::string::npos);
  EXPECT_NE(parseError("/dev/video0,colour=auto,extrinsics=guess").find("extrinsics:"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,zoom=2").find("unknown option 'zoom'"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,fast").find("not key=value"), std::string::npos);
}

TEST(V4l2Options, ColourOptionsNeedAColourNode) {
  EXPECT_NE(parseError("/dev/video0,colour_size=1280x720").find("need a colour node"), std::string::npos);
  EXPECT_NE(parseError("/dev/video0,extrinsics=identity").find("need a colour node"), std::string::npos);
}

TEST(V4l2Options, FourccText) {
  EXPECT_EQ(fourccText(V4L2_PIX_FMT_Z16), "Z16");
  EXPECT_EQ(fourccText(V4L2_PIX_FMT_YUYV), "YUYV");
  EXPECT_EQ(fourccText(0x01020304u), "????");
}

}  // namespace
}  // namespace fovea::hal::v4l2
