// A USB port reset of a camera whose stream stalled, for the camera backends'
// Camera::resetDevice() (hal/camera.h), which hal::CaptureRetry calls between
// stop() and the reopen that follows a stall.
//
// How a backend uses it:
//   - at open(), remember where the device is: a V4L2 backend calls
//     usbSelectorForVideoNode("/dev/video2") (sysfs: the node's USB device),
//     an OpenNI2 backend parses its device URI with usbSelectorFromOpenNI2Uri();
//     any backend can fill vendor_id/product_id/serial itself;
//   - in resetDevice(), after streaming stopped (buffers unmapped, interfaces
//     released): return resetUsbDevice(selector_).
//   - then open() finds the device again the usual way: after a reset the
//     kernel may re-enumerate it under a new address (OpenNI2 URI) or a new
//     /dev/videoN, so look it up by serial or port path, not by the old node.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "core/result.h"

namespace fovea::hal::usb {

// Which device to reset. The first set field wins: port_path, then bus and
// address, then vendor/product (with serial when several match).
struct UsbDeviceSelector {
  std::string port_path;  // "1-2.3": stays the same across re-enumeration on the same port
  uint8_t bus = 0;        // with address: changes when the device re-enumerates
  uint8_t address = 0;
  uint16_t vendor_id = 0;
  uint16_t product_id = 0;
  std::string serial;     // "" matches any

  bool empty() const { return port_path.empty() && address == 0 && vendor_id == 0; }
  // "port 1-2.3", "bus 1 address 5", "2bc5:0401 serial 123"
  std::string describe() const;
};

// "1-2.3" -> port_path. kInvalidArgument unless it looks like bus-port[.port...].
Result<UsbDeviceSelector> usbSelectorFromPortPath(std::string_view port_path);

// OpenNI2's Linux device URI "2bc5/0401@1/5" (vendor/product@bus/address, hex
// ids, decimal bus and address) -> vendor, product, bus, address.
Result<UsbDeviceSelector> usbSelectorFromOpenNI2Uri(std::string_view uri);

// The USB device behind a V4L2 node, from sysfs (/sys/class/video4linux/videoN/
// device is a symlink into the USB interface "1-2.3:1.0"): port path, vendor,
// product and serial. kNotFound when the node does not exist; kInvalidArgument
// when it is not a USB device (vivid, a CSI camera). `sysfs_root` is for tests.
Result<UsbDeviceSelector> usbSelectorForVideoNode(std::string_view device_node,
                                                  std::string_view sysfs_root = "/sys");

// Resets the selected device's port (libusb_reset_device). Ok: the device is
// back with the same address. kNotFound: no such device (before the reset), or
// the reset made it re-enumerate or vanish (find it again). kUnavailable: built
// without libusb, or no permission to open it (says which udev rule). kIoError
// otherwise. Blocks while the kernel resets the port (typically well under a
// second); call it from the capture thread after stop(), never per frame.
Status resetUsbDevice(const UsbDeviceSelector& which);

}  // namespace fovea::hal::usb
