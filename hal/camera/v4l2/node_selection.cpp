#include "hal/camera/v4l2/node_selection.h"

#include <algorithm>
#include <cerrno>

namespace fovea::hal::v4l2 {

bool offersFormat(const std::vector<uint32_t>& formats, uint32_t fourcc) {
  return std::find(formats.begin(), formats.end(), fourcc) != formats.end();
}

bool offersDepth(const std::vector<uint32_t>& formats) {
  return std::any_of(std::begin(kDepthFourccs), std::end(kDepthFourccs),
                     [&](uint32_t f) { return offersFormat(formats, f); });
}

bool offersColour(const std::vector<uint32_t>& formats) {
  return std::any_of(std::begin(kColourFourccs), std::end(kColourFourccs),
                     [&](uint32_t f) { return offersFormat(formats, f); });
}

NodeScan scanNodes(const V4l2Paths& paths) {
  NodeScan scan;
  for (const std::string& name : listVideoNodes(paths.dev_root)) {
    NodeInfo info;
    info.path = paths.dev_root + "/" + name;
    V4l2Node node(V4l2Node::Io::kRaw);
    if (Status s = node.open(info.path); !s) {
      if (node.lastOpenErrno() == EACCES || node.lastOpenErrno() == EPERM) scan.denied.push_back(info.path);
      continue;  // gone meanwhile, or not a capture node
    }
    info.caps = node.caps();
    info.formats = node.formats();
    info.sysfs = readVideoNodeSysfs(paths.sysfs_root, name);
    info.depth = offersDepth(info.formats);
    info.colour = offersColour(info.formats);
    scan.nodes.push_back(std::move(info));
  }
  return scan;
}

bool sameDevice(const NodeInfo& a, const NodeInfo& b) {
  if (!a.sysfs.usb.device_path.empty() || !b.sysfs.usb.device_path.empty()) {
    return a.sysfs.usb.device_path == b.sysfs.usb.device_path;
  }
  return !a.caps.bus_info.empty() && a.caps.bus_info == b.caps.bus_info;
}

bool matchesSelector(const NodeInfo& node, const NodeSelector& selector) {
  switch (selector.kind) {
    case NodeSelector::Kind::kPath: return node.path == selector.value;
    case NodeSelector::Kind::kSerial: return !node.sysfs.usb.serial.empty() && node.sysfs.usb.serial == selector.value;
    case NodeSelector::Kind::kBus:
      return node.caps.bus_info == selector.value ||
             (!node.sysfs.usb.port.empty() && node.sysfs.usb.port == selector.value);
    case NodeSelector::Kind::kNone:
    case NodeSelector::Kind::kAuto: return false;
  }
  return false;
}

namespace {

bool isSeen(const NodeInfo& n, const SeenNode& seen) {
  if (!seen.serial.empty()) return n.sysfs.usb.serial == seen.serial;
  return n.caps.bus_info == seen.bus_info;
}

}  // namespace

int pickDepthNode(const std::vector<NodeInfo>& nodes, const NodeSelector& selector, const SeenNode& seen) {
  const int n = static_cast<int>(nodes.size());
  if (selector.kind == NodeSelector::Kind::kAuto && seen.empty()) {
    // The first node offering the preferred depth format: a RealSense's depth
    // node (Z16) before its infrared node (Y16), on whichever camera it is.
    for (const uint32_t fourcc : kDepthFourccs) {
      for (int i = 0; i < n; ++i) {
        if (std::find(nodes[i].formats.begin(), nodes[i].formats.end(), fourcc) != nodes[i].formats.end()) return i;
      }
    }
    return -1;
  }
  if ((selector.kind == NodeSelector::Kind::kPath || selector.kind == NodeSelector::Kind::kAuto) && !seen.empty()) {
    // Still the same device under its old path? Else its node under a new one
    // (auto: the device the first open took, not whichever comes first now),
    // the one offering the format used before first (a RealSense's infrared
    // node shares the device and may offer Y16 too).
    for (int i = 0; i < n; ++i) {
      if (nodes[i].path == selector.value && nodes[i].depth && isSeen(nodes[i], seen)) return i;
    }
    for (int pass = 0; pass < 2; ++pass) {
      for (int i = 0; i < n; ++i) {
        const bool format_ok = pass == 1 || seen.format == 0 ||
                               std::find(nodes[i].formats.begin(), nodes[i].formats.end(), seen.format) !=
                                   nodes[i].formats.end();
        if (nodes[i].depth && isSeen(nodes[i], seen) && format_ok) return i;
      }
    }
    return -1;
  }
  for (int pass = 0; pass < 2; ++pass) {
    for (int i = 0; i < n; ++i) {
      const bool format_ok = pass == 1 || seen.format == 0 ||
                             std::find(nodes[i].formats.begin(), nodes[i].formats.end(), seen.format) !=
                                 nodes[i].formats.end();
      if (nodes[i].depth && matchesSelector(nodes[i], selector) && format_ok) return i;
    }
  }
  return -1;
}

int pickColourNode(const std::vector<NodeInfo>& nodes, const NodeSelector& selector, const std::string& depth_path,
                   const SeenNode& seen) {
  const NodeInfo* depth = nullptr;
  for (const NodeInfo& n : nodes) {
    if (n.path == depth_path) depth = &n;
  }
  const int count = static_cast<int>(nodes.size());
  // Nodes without depth formats first: a UVC device's colour node shares the
  // depth node's bus_info; vivid's nodes offer both.
  for (int pass = 0; pass < 2; ++pass) {
    for (int i = 0; i < count; ++i) {
      const NodeInfo& n = nodes[i];
      if (n.path == depth_path || !n.colour || (pass == 0 && n.depth)) continue;
      bool match = false;
      if (selector.kind == NodeSelector::Kind::kPath && !seen.empty()) {
        match = isSeen(n, seen);
      } else if (selector.kind == NodeSelector::Kind::kAuto) {
        match = pass == 0 && depth != nullptr && sameDevice(n, *depth);
      } else {
        match = matchesSelector(n, selector);
      }
      if (match) return i;
    }
  }
  return -1;
}

}  // namespace fovea::hal::v4l2
