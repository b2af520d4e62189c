// What sysfs says about a V4L2 node beyond what the node itself reports: the
// USB device it belongs to (serial, vendor and product ids, port), so a camera
// can be named by its serial and found again after it re-enumerates under
// another /dev/videoN. The roots are parameters so tests read a fake tree.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace fovea::hal::v4l2 {

struct UsbIdentity {
  std::string device_path;  // the USB device's sysfs directory (resolved); "" when the node is not on USB
  std::string port;         // its name there, the port path ("1-1.2"), what a USB reset looks for
  std::string vendor_id;    // "8086" (idVendor)
  std::string product_id;   // "0b07" (idProduct)
  std::string serial;       // "" when the device has none
  std::string manufacturer;
  std::string product;
  std::string busnum;       // "1"
  std::string devnum;       // "4"
};

struct VideoNodeSysfs {
  std::string node;   // "video2"
  std::string card;   // the name attribute ("Intel(R) RealSense(TM) Depth Ca")
  int index = -1;     // the index attribute: which node of the interface (uvcvideo: 0 video, 1 metadata)
  UsbIdentity usb;
};

// The video nodes under dev_root ("video0", "video1", ... by number); empty
// when there are none or dev_root cannot be read.
std::vector<std::string> listVideoNodes(const std::string& dev_root);

// Reads sysfs_root/class/video4linux/NODE and walks up from its device link
// to the USB device (the first directory with idVendor). Missing attributes
// stay empty; never fails.
VideoNodeSysfs readVideoNodeSysfs(const std::string& sysfs_root, std::string_view node);

}  // namespace fovea::hal::v4l2
