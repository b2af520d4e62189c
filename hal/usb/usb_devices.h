// The known RGB-D cameras (hal/usb/usb_ids.h) connected now, found with libusb,
// for `fovead cameras` and the service's log. Built without libusb,
// listUsbCameras() says so (kUnavailable) and the rest still works.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/result.h"
#include "hal/usb/usb_ids.h"

namespace fovea::hal::usb {

enum class UsbSpeed : uint8_t { kUnknown, kLow, kFull, kHigh, kSuper, kSuperPlus };

// "USB 1.1 (12 Mbit/s)", "USB 2 (480 Mbit/s)", "USB 3 (5 Gbit/s)"...
const char* usbSpeedName(UsbSpeed speed);

struct UsbCameraDevice {
  const KnownUsbCamera* known = nullptr;  // never null in listUsbCameras()'s result
  uint16_t vendor_id = 0;
  uint16_t product_id = 0;
  uint8_t bus = 0;
  uint8_t address = 0;
  std::string port_path;     // bus and port chain as sysfs names it: "1-2.3"
  std::string serial;        // "" when the device has none or it could not be read
  std::string serial_error;  // why not: "no permission (udev rule)", "device has no serial number"...
  UsbSpeed speed = UsbSpeed::kUnknown;
  // The camera wants USB 3 and the link is slower (or unknown): depth will not
  // run at full rate; plug it into a blue (SuperSpeed) port with a USB 3 cable.
  bool too_slow() const;
};

// Every connected device whose (vendor, product) is in the table, in bus order.
// Reading a serial needs to open the device: without permission the device is
// still listed, with serial_error saying so. kUnavailable when fovea was built
// without libusb; kIoError naming libusb's error when libusb cannot start (no
// usbfs: a container without /dev/bus/usb).
Result<std::vector<UsbCameraDevice>> listUsbCameras();

// One line: "Orbbec Astra 2bc5:0401 at 1-2.3 (bus 1 address 5), USB 2 (480 Mbit/s),
// serial 17122730029, backend openni2", plus the warnings (too slow, serial
// unreadable, note).
std::string formatUsbCamera(const UsbCameraDevice& device);

// Can this platform's libusb report hot-plug events? kUnavailable (with the
// reason) when not, or when built without libusb.
Status usbHotplugSupported();

}  // namespace fovea::hal::usb
