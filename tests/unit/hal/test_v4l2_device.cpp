// The V4L2 backend without a device: sysfs identity read from a fake tree
// (a RealSense-like USB device with a depth and a metadata node), the node
// listing, discovery with no nodes (an empty list, not an error), nodes that
// are not V4L2 devices, and open() of a missing node or of a serial nobody has,
// with the messages a user sees.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "hal/camera.h"
#include "hal/camera/v4l2/sysfs.h"
#include "hal/camera/v4l2/v4l2_camera.h"
#include "hal/camera/v4l2/v4l2_node.h"

namespace fovea::hal::v4l2 {
namespace {

namespace fs = std::filesystem;

void write(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text << "\n";
}

class V4l2FakeTree : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("fovea-v4l2-" + std::to_string(::getpid()) + "-" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    sys_ = root_ / "sys";
    dev_ = root_ / "dev";
    fs::create_directories(dev_);
    // /sys/devices/pci0000:00/0000:00:14.0/usb2/2-1 is the USB device,
    // 2-1:1.0 its depth interface with video0 (index 0) and video1 (metadata).
    const fs::path usb = sys_ / "devices/pci0000:00/0000:00:14.0/usb2/2-1";
    write(usb / "idVendor", "8086");
    write(usb / "idProduct", "0b07");
    write(usb / "serial", "f0233333");
    write(usb / "manufacturer", "Intel(R) RealSense(TM) Depth Camera 435");
    write(usb / "product", "Intel(R) RealSense(TM) Depth Camera 435");
    write(usb / "busnum", "2");
    write(usb / "devnum", "3");
    const fs::path intf = usb / "2-1:1.0";
    for (int i = 0; i < 2; ++i) {
      const fs::path node = intf / "video4linux" / ("video" + std::to_string(i));
      write(node / "name", "Intel(R) RealSense(TM) Depth Ca");
      write(node / "index", std::to_string(i));
      fs::create_directory_symlink(intf, node / "device");
      fs::create_directories(sys_ / "class/video4linux");
      fs::create_directory_symlink(node, sys_ / "class/video4linux" / ("video" + std::to_string(i)));
    }
    // A platform node (vivid) without a USB device above it.
    const fs::path vivid = sys_ / "devices/platform/vivid.0/video4linux/video7";
    write(vivid / "name", "vivid-000-vid-cap");
    fs::create_directory_symlink(sys_ / "devices/platform/vivid.0", vivid / "device");
    fs::create_directory_symlink(vivid, sys_ / "class/video4linux/video7");
  }
  void TearDown() override { fs::remove_all(root_); }

  fs::path root_, sys_, dev_;
};

TEST_F(V4l2FakeTree, UsbIdentityFromTheDeviceAboveTheInterface) {
  const VideoNodeSysfs node = readVideoNodeSysfs(sys_.string(), "video0");
  EXPECT_EQ(node.node, "video0");
  EXPECT_EQ(node.card, "Intel(R) RealSense(TM) Depth Ca");
  EXPECT_EQ(node.index, 0);
  EXPECT_EQ(node.usb.vendor_id, "8086");
  EXPECT_EQ(node.usb.product_id, "0b07");
  EXPECT_EQ(node.usb.serial, "f0233333");
  EXPECT_EQ(node.usb.port, "2-1");
  EXPECT_EQ(node.usb.busnum, "2");
  EXPECT_EQ(node.usb.devnum, "3");
  EXPECT_EQ(node.usb.product, "Intel(R) RealSense(TM) Depth Camera 435");
  EXPECT_NE(node.usb.device_path.find("usb2/2-1"), std::string::npos);
  EXPECT_EQ(readVideoNodeSysfs(sys_.string(), "video1").index, 1);
  EXPECT_EQ(readVideoNodeSysfs(sys_.string(), "video1").usb.serial, "f0233333");
}

TEST_F(V4l2FakeTree, PlatformNodeHasNoUsbIdentity) {
  const VideoNodeSysfs node = readVideoNodeSysfs(sys_.string(), "video7");
  EXPECT_EQ(node.card, "vivid-000-vid-cap");
  EXPECT_EQ(node.index, -1);
  EXPECT_TRUE(node.usb.device_path.empty());
  EXPECT_TRUE(node.usb.serial.empty());
}

TEST_F(V4l2FakeTree, MissingNodeReadsEmpty) {
  const VideoNodeSysfs node = readVideoNodeSysfs(sys_.string(), "video3");
  EXPECT_TRUE(node.card.empty());
  EXPECT_TRUE(node.usb.vendor_id.empty());
  EXPECT_TRUE(readVideoNodeSysfs((root_ / "nowhere").string(), "video0").card.empty());
}

TEST_F(V4l2FakeTree, NodesListedByNumber) {
  for (const char* name : {"video10", "video2", "video0", "vbi0", "video", "videoX", "media0"}) write(dev_ / name, "");
  const std::vector<std::string> nodes = listVideoNodes(dev_.string());
  ASSERT_EQ(nodes.size(), 3u);
  EXPECT_EQ(nodes[0], "video0");
  EXPECT_EQ(nodes[1], "video2");
  EXPECT_EQ(nodes[2], "video10");
  EXPECT_TRUE(listVideoNodes((root_ / "no-dev").string()).empty());
}

TEST_F(V4l2FakeTree, DiscoveryWithoutNodesIsAnEmptyList) {
  Result<std::vector<DeviceListing>> found = discoverV4l2CamerasIn({dev_.string(), sys_.string()});
  ASSERT_TRUE(found.isOk()) << found.status().message();
  EXPECT_TRUE(found->empty());
}

TEST_F(V4l2FakeTree, NodesThatAreNotV4l2DevicesAreNotListed) {
  write(dev_ / "video0", "not a device");
  Result<std::vector<DeviceListing>> found = discoverV4l2CamerasIn({dev_.string(), sys_.string()});
  ASSERT_TRUE(found.isOk()) << found.status().message();
  EXPECT_TRUE(found->empty());
  V4l2Node node(V4l2Node::Io::kRaw);
  const Status s = node.open((dev_ / "video0").string());
  EXPECT_EQ(s.code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(s.message().find("is not a V4L2 device"), std::string::npos) << s.message();
  EXPECT_FALSE(node.isOpen());
}

// 0: the error names the video group and the udev rule; 1: listed anyway; 2: another message.
int discoverDenied(const fs::path& dev, const fs::path& sys) {
  Result<std::vector<DeviceListing>> found = discoverV4l2CamerasIn({dev.string(), sys.string()});
  if (found.isOk()) return 1;
  const std::string& m = found.status().message();
  return m.find("video group") != std::string::npos && m.find("udev rule") != std::string::npos ? 0 : 2;
}

TEST_F(V4l2FakeTree, PermissionDeniedNamesTheVideoGroup) {
  write(dev_ / "video0", "");
  fs::permissions(dev_ / "video0", fs::perms::none);
  if (::geteuid() != 0) {
    EXPECT_EQ(discoverDenied(dev_, sys_), 0);
    return;
  }
  // Root opens anything: the check runs in a child as nobody.
  fs::permissions(root_, fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec |
                             fs::perms::others_read | fs::perms::others_exec);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    if (::setgid(65534) != 0 || ::setuid(65534) != 0) ::_exit(3);
    ::_exit(discoverDenied(dev_, sys_));
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "1: listed without an error, 2: another message, 3: could not become nobody";
}

TEST_F(V4l2FakeTree, SerialNobodyHasIsNotFound) {
  V4l2CameraOptions options;
  options.depth = {NodeSelector::Kind::kSerial, "f0233333"};
  V4l2Camera camera(options, {dev_.string(), sys_.string()});
  const Status s = camera.open();
  EXPECT_EQ(s.code(), ErrorCode::kNotFound);
  EXPECT_NE(s.message().find("no depth node with serial=f0233333"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("plugged in"), std::string::npos);
}

TEST(V4l2Errors, OpenErrorsSayWhatToDo) {
  EXPECT_EQ(nodeOpenError("/dev/video0", ENOENT).code(), ErrorCode::kNotFound);
  EXPECT_NE(nodeOpenError("/dev/video0", ENOENT).message().find("plugged in"), std::string::npos);
  const Status denied = nodeOpenError("/dev/video0", EACCES);
  EXPECT_NE(denied.message().find("video group"), std::string::npos);
  EXPECT_NE(denied.message().find("udev rule"), std::string::npos);
  const Status busy = nodeOpenError("/dev/video0", EBUSY);
  EXPECT_NE(busy.message().find("busy: another program is streaming from it"), std::string::npos);
  EXPECT_NE(busy.message().find("fuser -v /dev/video0"), std::string::npos);
}

TEST(V4l2Camera, MissingNodeGivesAClearError) {
  Result<std::unique_ptr<Camera>> camera = createCamera("v4l2:/dev/video-fovea-missing,hfov_deg=60");
  ASSERT_TRUE(camera.isOk()) << camera.status().message();
  EXPECT_EQ((*camera)->info().name, "v4l2:/dev/video-fovea-missing");
  const Status s = (*camera)->open();
  EXPECT_EQ(s.code(), ErrorCode::kNotFound);
  EXPECT_NE(s.message().find("/dev/video-fovea-missing does not exist: is the camera plugged in?"), std::string::npos)
      << s.message();
  // Never opened: start and acquire fail cleanly, stop is harmless.
  EXPECT_EQ((*camera)->start().code(), ErrorCode::kUnavailable);
  RgbdFrame slot(640, 480);
  EXPECT_EQ((*camera)->acquire(slot, std::chrono::milliseconds(1)).code(), ErrorCode::kUnavailable);
  (*camera)->stop();
  (*camera)->stop();
  EXPECT_EQ((*camera)->counters().errors, 1u);
}

TEST(V4l2Camera, BadSpecIsRefusedAtCreate) {
  Result<std::unique_ptr<Camera>> camera = createCamera("v4l2:/dev/video0,size=big");
  ASSERT_FALSE(camera.isOk());
  EXPECT_NE(camera.status().message().find("size: expected WxH"), std::string::npos);
}

TEST(V4l2Camera, DiscoveryOnThisHost) {
  if (!listVideoNodes("/dev").empty()) GTEST_SKIP() << "this host has /dev/video* nodes; the empty case runs elsewhere";
  Result<std::vector<DeviceListing>> found = discoverV4l2Cameras();
  ASSERT_TRUE(found.isOk()) << found.status().message();
  EXPECT_TRUE(found->empty());
}

TEST(V4l2Camera, HfovIntrinsics) {
  const CameraIntrinsics k = intrinsicsFromHfov(640, 480, 90.0);
  EXPECT_EQ(k.width, 640);
  EXPECT_EQ(k.height, 480);
  EXPECT_NEAR(k.fx, 320.0, 1e-9);  // tan(45 deg) = 1
  EXPECT_NEAR(k.fy, 320.0, 1e-9);
  EXPECT_NEAR(k.cx, 319.5, 1e-12);
  EXPECT_NEAR(k.cy, 239.5, 1e-12);
}

TEST(V4l2Camera, ResetOfACameraNeverOpenedSaysWhy) {
  V4l2CameraOptions options;
  options.depth = {NodeSelector::Kind::kPath, "/dev/video-fovea-missing"};
  V4l2Camera camera(options);
  const Status s = camera.resetDevice();
  EXPECT_EQ(s.code(), ErrorCode::kUnavailable);
  EXPECT_FALSE(s.message().empty());
}

TEST(V4l2Camera, SetCalibrationIsAccepted) {
  V4l2CameraOptions options;
  options.depth = {NodeSelector::Kind::kPath, "/dev/video-fovea-missing"};
  V4l2Camera camera(options);
  CameraCalibration calibration;
  calibration.depth = StreamCalibration{{640, 480, 600, 600, 320, 240}, {}};
  calibration.source = "test";
  EXPECT_TRUE(camera.setCalibration(calibration).isOk());
  calibration.depth->intrinsics.fx = 0;
  const Status bad = camera.setCalibration(calibration);
  EXPECT_EQ(bad.code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(bad.message().find("from test"), std::string::npos) << bad.message();
}

}  // namespace
}  // namespace fovea::hal::v4l2
