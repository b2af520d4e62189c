// Which node a V4L2 spec picks, on made-up node lists: two RealSense-like USB
// cameras (depth, infrared and colour nodes each), found by path, serial,
// bus_info and USB port; colour=auto finds the sibling colour node; after a
// re-plug renumbers the nodes, a camera named by path is found again by what
// its first open saw, never confused with the camera that now holds its old
// path.
#include <gtest/gtest.h>

#include <linux/videodev2.h>

#include <string>
#include <vector>

#include "hal/camera/v4l2/node_selection.h"

namespace fovea::hal::v4l2 {
namespace {

using Kind = NodeSelector::Kind;

NodeInfo node(int n, const std::string& serial, const std::string& port, std::vector<uint32_t> formats) {
  NodeInfo info;
  info.path = "/dev/video" + std::to_string(n);
  info.caps.driver = "uvcvideo";
  info.caps.bus_info = "usb-0000:00:14.0-" + port;
  info.sysfs.usb.serial = serial;
  info.sysfs.usb.port = port;
  info.sysfs.usb.device_path = "/sys/devices/pci0000:00/0000:00:14.0/usb2/" + port;
  info.formats = std::move(formats);
  info.depth = offersDepth(info.formats);
  info.colour = offersColour(info.formats);
  return info;
}

// Camera A (serial AAA, port 2-1) at video0 (depth Z16), video2 (infrared,
// Y16 among others), video4 (colour YUYV); camera B (BBB, port 2-2) from video6.
std::vector<NodeInfo> twoCameras(int first_a, int first_b) {
  return {
      node(first_a, "AAA", "2-1", {V4L2_PIX_FMT_Z16}),
      node(first_a + 2, "AAA", "2-1", {V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_Y16}),
      node(first_a + 4, "AAA", "2-1", {V4L2_PIX_FMT_YUYV}),
      node(first_b, "BBB", "2-2", {V4L2_PIX_FMT_Z16}),
      node(first_b + 2, "BBB", "2-2", {V4L2_PIX_FMT_MJPEG, V4L2_PIX_FMT_YUYV}),
  };
}

std::string depthPath(const std::vector<NodeInfo>& nodes, const NodeSelector& sel, const SeenNode& seen = {}) {
  const int i = pickDepthNode(nodes, sel, seen);
  return i < 0 ? "none" : nodes[static_cast<std::size_t>(i)].path;
}

std::string colourPath(const std::vector<NodeInfo>& nodes, const NodeSelector& sel, const std::string& depth,
                       const SeenNode& seen = {}) {
  const int i = pickColourNode(nodes, sel, depth, seen);
  return i < 0 ? "none" : nodes[static_cast<std::size_t>(i)].path;
}

TEST(V4l2NodeSelection, DepthBySerialBusAndPort) {
  const std::vector<NodeInfo> nodes = twoCameras(0, 6);
  EXPECT_EQ(depthPath(nodes, {Kind::kSerial, "BBB"}), "/dev/video6");
  EXPECT_EQ(depthPath(nodes, {Kind::kSerial, "AAA"}), "/dev/video0");
  EXPECT_EQ(depthPath(nodes, {Kind::kBus, "usb-0000:00:14.0-2-2"}), "/dev/video6");
  EXPECT_EQ(depthPath(nodes, {Kind::kBus, "2-1"}), "/dev/video0");
  EXPECT_EQ(depthPath(nodes, {Kind::kPath, "/dev/video2"}), "/dev/video2");  // the infrared node, asked for
  EXPECT_EQ(depthPath(nodes, {Kind::kPath, "/dev/video4"}), "none");         // colour only
  EXPECT_EQ(depthPath(nodes, {Kind::kSerial, "CCC"}), "none");
  EXPECT_EQ(depthPath({}, {Kind::kSerial, "AAA"}), "none");
}

// auto (a board profile that cannot know the serial): the first node offering
// Z16, not an earlier Y16 infrared node; Y16 when no node has Z16; after a
// re-plug, the camera the first open took, even when another now comes first.
TEST(V4l2NodeSelection, DepthAutoTakesTheFirstDepthNodeAndKeepsItsDevice) {
  std::vector<NodeInfo> nodes = twoCameras(0, 6);
  std::swap(nodes[0], nodes[1]);  // camera A's infrared node (Y16) before its depth node
  EXPECT_EQ(depthPath(nodes, {Kind::kAuto, ""}), "/dev/video0");
  const std::vector<NodeInfo> y16_only = {node(3, "CCC", "1-1", {V4L2_PIX_FMT_YUYV}),
                                          node(5, "CCC", "1-1", {V4L2_PIX_FMT_Y16})};
  EXPECT_EQ(depthPath(y16_only, {Kind::kAuto, ""}), "/dev/video5");
  EXPECT_EQ(depthPath({node(1, "CCC", "1-1", {V4L2_PIX_FMT_YUYV})}, {Kind::kAuto, ""}), "none");
  SeenNode seen_b;
  seen_b.serial = "BBB";
  seen_b.format = V4L2_PIX_FMT_Z16;
  EXPECT_EQ(depthPath(twoCameras(1, 7), {Kind::kAuto, ""}, seen_b), "/dev/video7");
}

TEST(V4l2NodeSelection, ColourAutoTakesTheSiblingOfTheSameDevice) {
  const std::vector<NodeInfo> nodes = twoCameras(0, 6);
  EXPECT_EQ(colourPath(nodes, {Kind::kAuto, ""}, "/dev/video0"), "/dev/video4");
  EXPECT_EQ(colourPath(nodes, {Kind::kAuto, ""}, "/dev/video6"), "/dev/video8");
  // A device without a colour node: none (not the other camera's).
  std::vector<NodeInfo> depth_only = {nodes[0], nodes[3], nodes[4]};
  EXPECT_EQ(colourPath(depth_only, {Kind::kAuto, ""}, "/dev/video0"), "none");
}

TEST(V4l2NodeSelection, ColourByNameNeverTheDepthNode) {
  const std::vector<NodeInfo> nodes = twoCameras(0, 6);
  EXPECT_EQ(colourPath(nodes, {Kind::kSerial, "AAA"}, "/dev/video0"), "/dev/video4");
  EXPECT_EQ(colourPath(nodes, {Kind::kBus, "2-2"}, "/dev/video6"), "/dev/video8");
  // Another camera's colour beside this depth: allowed when named.
  EXPECT_EQ(colourPath(nodes, {Kind::kSerial, "BBB"}, "/dev/video0"), "/dev/video8");
  // Both offering depth and colour (vivid): the one that is not the depth node.
  std::vector<NodeInfo> vivid = {node(0, "", "", {V4L2_PIX_FMT_Y16, V4L2_PIX_FMT_YUYV}),
                                 node(1, "", "", {V4L2_PIX_FMT_Y16, V4L2_PIX_FMT_YUYV})};
  for (NodeInfo& v : vivid) v.sysfs.usb = {};
  vivid[0].caps.bus_info = "platform:vivid-000";
  vivid[1].caps.bus_info = "platform:vivid-001";
  EXPECT_EQ(colourPath(vivid, {Kind::kBus, "platform:vivid-001"}, "/dev/video0"), "/dev/video1");
  EXPECT_EQ(colourPath(vivid, {Kind::kBus, "platform:vivid-000"}, "/dev/video0"), "none");
  EXPECT_EQ(colourPath(vivid, {Kind::kAuto, ""}, "/dev/video0"), "none");  // other bus: not a sibling
}

TEST(V4l2NodeSelection, ReplugUnderOtherNumbersFindsTheSameCameraByPath) {
  // First open: camera A's depth at /dev/video0, Z16.
  const SeenNode seen_a{"usb-0000:00:14.0-2-1", "AAA", V4L2_PIX_FMT_Z16};
  // Re-plugged: B now holds video0..2, A comes back at video10.
  const std::vector<NodeInfo> after = twoCameras(10, 0);
  EXPECT_EQ(depthPath(after, {Kind::kPath, "/dev/video0"}, seen_a), "/dev/video10");
  // The format used before picks the depth node over the infrared node.
  std::vector<NodeInfo> ir_first = after;
  std::swap(ir_first[0], ir_first[1]);
  EXPECT_EQ(depthPath(ir_first, {Kind::kPath, "/dev/video0"}, seen_a), "/dev/video10");
  // Same place again: the old path.
  EXPECT_EQ(depthPath(twoCameras(0, 6), {Kind::kPath, "/dev/video0"}, seen_a), "/dev/video0");
  // Gone.
  const std::vector<NodeInfo> only_b = {after[3], after[4]};
  EXPECT_EQ(depthPath(only_b, {Kind::kPath, "/dev/video0"}, seen_a), "none");
  // Its colour node, named by path at the first open, found likewise.
  const SeenNode seen_a_colour{"usb-0000:00:14.0-2-1", "AAA", V4L2_PIX_FMT_YUYV};
  EXPECT_EQ(colourPath(after, {Kind::kPath, "/dev/video4"}, "/dev/video10", seen_a_colour), "/dev/video14");
}

TEST(V4l2NodeSelection, WithoutASerialTheBusInfoIdentifies) {
  std::vector<NodeInfo> nodes = twoCameras(3, 0);
  for (NodeInfo& n : nodes) n.sysfs.usb.serial.clear();
  const SeenNode seen{"usb-0000:00:14.0-2-1", "", V4L2_PIX_FMT_Z16};
  EXPECT_EQ(depthPath(nodes, {Kind::kPath, "/dev/video0"}, seen), "/dev/video3");
}

}  // namespace
}  // namespace fovea::hal::v4l2
