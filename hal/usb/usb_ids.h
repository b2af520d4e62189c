// The RGB-D cameras fovea knows by USB vendor and product id: one table, the
// single source of truth for model names in `fovead cameras`, the hot-plug log
// and the udev rules fovea ships (udevRules() below). Pure data: no libusb.
//
// Each entry was checked against a public source (the ids' comments in
// usb_ids.cpp say which); an id nobody could confirm is left out, because a
// wrong id is worse than a missing one.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

namespace fovea::hal::usb {

// Which fovea camera backend streams the device (what to put before the ':'
// of the spec), or none when fovea has no path to its depth.
enum class UsbCameraBackend : uint8_t {
  kOpenNI2,  // openni2: (PrimeSense-protocol depth)
  kV4l2,     // v4l2: (UVC depth, Z16/Y16)
  kNone,     // no fovea backend (needs a vendor SDK fovea does not use)
};

const char* usbCameraBackendName(UsbCameraBackend backend);  // "openni2", "v4l2", "none"

struct KnownUsbCamera {
  uint16_t vendor_id = 0;
  uint16_t product_id = 0;
  std::string_view model;  // "Orbbec Astra", "Intel RealSense D435"
  UsbCameraBackend backend = UsbCameraBackend::kNone;
  // Depth at full rate needs a USB 3 (SuperSpeed) link.
  bool wants_usb3 = false;
  // What the user should know beyond the backend ("colour only", "needs
  // libfreenect2"); "" when nothing.
  std::string_view note;
};

// Every known camera, sorted by (vendor_id, product_id), no duplicates.
std::span<const KnownUsbCamera> knownUsbCameras();

// The entry for (vendor, product), or nullptr. No allocation (binary search).
const KnownUsbCamera* findKnownUsbCamera(uint16_t vendor_id, uint16_t product_id);

// The vendor's name for a vendor id of the table ("Orbbec"), "" for others.
std::string_view usbVendorName(uint16_t vendor_id);

// Access for the group and the logged-in user (uaccess), the file fovea
// installs as lib/udev/rules.d/60-fovea-rgbd-cameras.rules (60: before
// systemd's 73-seat-late.rules, which turns the uaccess tag into an ACL).
inline constexpr std::string_view kUdevRulesFileName = "60-fovea-rgbd-cameras.rules";
inline constexpr std::string_view kUdevUsbGroup = "plugdev";  // the USB device node (libusb, OpenNI2)
inline constexpr std::string_view kUdevVideoGroup = "video";  // its V4L2 nodes (uvcvideo)

// The rules file: a comment header, then per table entry one rule for the USB
// device node (SUBSYSTEM=="usb") and one for its video4linux nodes.
std::string udevRules();

}  // namespace fovea::hal::usb
