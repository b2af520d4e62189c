// Which V4L2 node a spec means: every capture node seen now (scanNodes), and
// pure functions that pick the depth node and the colour node from that list
// for a selector, also after the device re-enumerated under other node numbers
// (what the first open saw: SeenNode). Tested on made-up node lists.
#pragma once

#include <linux/videodev2.h>

#include <cstdint>
#include <string>
#include <vector>

#include "hal/camera/v4l2/sysfs.h"
#include "hal/camera/v4l2/v4l2_node.h"
#include "hal/camera/v4l2/v4l2_options.h"

namespace fovea::hal::v4l2 {

// Where device nodes and sysfs live; tests point them at a fake tree.
struct V4l2Paths {
  std::string dev_root = "/dev";
  std::string sysfs_root = "/sys";
};

// Depth formats in order of preference, and the colour formats fovea converts
// itself (RGB3 late: a node that offers it natively is rare; libv4l2 emulates
// it for the rest).
inline constexpr uint32_t kDepthFourccs[] = {V4L2_PIX_FMT_Z16, V4L2_PIX_FMT_Y16};
inline constexpr uint32_t kColourFourccs[] = {V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_UYVY, V4L2_PIX_FMT_MJPEG,
                                              V4L2_PIX_FMT_RGB24, V4L2_PIX_FMT_BGR24};
// Whether `formats` (a node's fourccs) holds `fourcc`.
bool offersFormat(const std::vector<uint32_t>& formats, uint32_t fourcc);
bool offersDepth(const std::vector<uint32_t>& formats);
bool offersColour(const std::vector<uint32_t>& formats);

// One capture node as discovery and node selection see it.
struct NodeInfo {
  std::string path;  // "/dev/video2"
  NodeCaps caps;
  VideoNodeSysfs sysfs;
  std::vector<uint32_t> formats;  // native (raw ioctls, no libv4l2 emulation)
  bool depth = false;             // offers Z16 or Y16
  bool colour = false;            // offers a colour format fovea converts
};

struct NodeScan {
  std::vector<NodeInfo> nodes;      // capture nodes that opened, by number
  std::vector<std::string> denied;  // nodes the user may not open
};
// Opens every /dev/videoN read-only for a moment (QUERYCAP, ENUM_FMT); nodes
// that are not capture nodes (uvcvideo's metadata nodes) are left out.
NodeScan scanNodes(const V4l2Paths& paths);

// The same USB device (sysfs), or for other buses the same bus_info.
bool sameDevice(const NodeInfo& a, const NodeInfo& b);
// serial= the USB serial, bus= the bus_info or the USB port, a path itself.
bool matchesSelector(const NodeInfo& node, const NodeSelector& selector);

// What the first open found, to find the same device again.
struct SeenNode {
  std::string bus_info;
  std::string serial;
  uint32_t format = 0;  // the format negotiated then
  bool empty() const { return bus_info.empty() && serial.empty(); }
};

// The depth node for `selector` (index into nodes, -1 for none). With `seen`
// (a reopen): a path still held by the same device, else that device's node
// wherever it is now (preferring one offering the format used before).
int pickDepthNode(const std::vector<NodeInfo>& nodes, const NodeSelector& selector, const SeenNode& seen);
// The colour node: never the depth node; nodes without depth formats first;
// auto: the depth node's device; a path on reopen: the device seen before.
int pickColourNode(const std::vector<NodeInfo>& nodes, const NodeSelector& selector, const std::string& depth_path,
                   const SeenNode& seen);

}  // namespace fovea::hal::v4l2
