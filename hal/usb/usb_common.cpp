// The parts of hal/usb that need no libusb: names, formatting, selectors and
// the sysfs lookup of a V4L2 node's USB device.
#include <cerrno>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

#include "hal/usb/usb_devices.h"
#include "hal/usb/usb_monitor.h"
#include "hal/usb/usb_reset.h"

namespace fovea::hal::usb {

namespace {

// "1-2.3": a bus number, '-', then port numbers separated by '.'.
bool isPortPath(std::string_view s) {
  const std::size_t dash = s.find('-');
  if (dash == 0 || dash == std::string_view::npos || dash + 1 >= s.size()) return false;
  for (std::size_t i = 0; i < dash; ++i) {
    if (s[i] < '0' || s[i] > '9') return false;
  }
  bool digit_before = false;
  for (std::size_t i = dash + 1; i < s.size(); ++i) {
    if (s[i] == '.') {
      if (!digit_before) return false;
      digit_before = false;
    } else if (s[i] >= '0' && s[i] <= '9') {
      digit_before = true;
    } else {
      return false;
    }
  }
  return digit_before;
}

bool parseHex16(std::string_view s, uint16_t& out) {
  if (s.empty() || s.size() > 4) return false;
  unsigned v = 0;
  for (char c : s) {
    v <<= 4;
    if (c >= '0' && c <= '9') v |= static_cast<unsigned>(c - '0');
    else if (c >= 'a' && c <= 'f') v |= static_cast<unsigned>(c - 'a' + 10);
    else if (c >= 'A' && c <= 'F') v |= static_cast<unsigned>(c - 'A' + 10);
    else return false;
  }
  out = static_cast<uint16_t>(v);
  return true;
}

bool parseDec8(std::string_view s, uint8_t& out) {
  if (s.empty() || s.size() > 3) return false;
  unsigned v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + static_cast<unsigned>(c - '0');
  }
  if (v > 255) return false;
  out = static_cast<uint8_t>(v);
  return true;
}

std::string readFirstLine(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::string line;
  if (in) std::getline(in, line);
  while (!line.empty() && (line.back() == '\n' || line.back() == '\r' || line.back() == ' ')) line.pop_back();
  return line;
}

}  // namespace

const char* usbSpeedName(UsbSpeed speed) {
  switch (speed) {
    case UsbSpeed::kUnknown: return "unknown speed";
    case UsbSpeed::kLow: return "USB 1.0 (1.5 Mbit/s)";
    case UsbSpeed::kFull: return "USB 1.1 (12 Mbit/s)";
    case UsbSpeed::kHigh: return "USB 2 (480 Mbit/s)";
    case UsbSpeed::kSuper: return "USB 3 (5 Gbit/s)";
    case UsbSpeed::kSuperPlus: return "USB 3 (10 Gbit/s)";
  }
  return "?";
}

bool UsbCameraDevice::too_slow() const {
  return known != nullptr && known->wants_usb3 && speed != UsbSpeed::kSuper && speed != UsbSpeed::kSuperPlus;
}

std::string formatUsbCamera(const UsbCameraDevice& d) {
  char head[200];
  const std::string_view model = d.known ? d.known->model : std::string_view("unknown device");
  std::snprintf(head, sizeof head, "%.*s %04x:%04x at %s (bus %u address %u), %s", static_cast<int>(model.size()),
                model.data(), d.vendor_id, d.product_id, d.port_path.empty() ? "?" : d.port_path.c_str(), d.bus,
                d.address, usbSpeedName(d.speed));
  std::string line = head;
  if (!d.serial.empty()) {
    line += ", serial " + d.serial;
  } else if (!d.serial_error.empty()) {
    line += ", " + d.serial_error;
  }
  if (d.known) {
    line += ", backend ";
    line += usbCameraBackendName(d.known->backend);
    if (!d.known->note.empty()) {
      line += " (";
      line += d.known->note;
      line += ')';
    }
  }
  if (d.too_slow()) {
    line += "; WARNING: depth cameras need USB 3: this one runs at ";
    line += usbSpeedName(d.speed);
    line += ", plug it into a SuperSpeed (blue) port with a USB 3 cable";
  }
  return line;
}

std::size_t formatUsbEvent(const UsbEvent& e, char* out, std::size_t size) {
  if (size == 0) return 0;
  const std::string_view model = e.known ? e.known->model : std::string_view("USB device");
  const int n = std::snprintf(out, size, "usb: %.*s (%04x:%04x) %s %s%s", static_cast<int>(model.size()), model.data(),
                              e.vendor_id, e.product_id, e.kind == UsbEvent::Kind::kArrived ? "arrived at" : "left",
                              e.port_path.data(), e.present_at_start ? " (present at start)" : "");
  return n < 0 ? 0 : std::min(static_cast<std::size_t>(n), size - 1);
}

std::string UsbDeviceSelector::describe() const {
  char buf[96];
  if (!port_path.empty()) return "port " + port_path;
  if (address != 0) {
    std::snprintf(buf, sizeof buf, "bus %u address %u", bus, address);
    return buf;
  }
  std::snprintf(buf, sizeof buf, "%04x:%04x", vendor_id, product_id);
  std::string out = buf;
  if (!serial.empty()) out += " serial " + serial;
  return out;
}

Result<UsbDeviceSelector> usbSelectorFromPortPath(std::string_view port_path) {
  if (!isPortPath(port_path)) {
    return Result<UsbDeviceSelector>(ErrorCode::kInvalidArgument,
                                     "usb port path '" + std::string(port_path) +
                                         "': expected bus-port[.port...] as in /sys/bus/usb/devices, e.g. 1-2.3");
  }
  UsbDeviceSelector s;
  s.port_path = std::string(port_path);
  return s;
}

Result<UsbDeviceSelector> usbSelectorFromOpenNI2Uri(std::string_view uri) {
  const auto bad = [&] {
    return Result<UsbDeviceSelector>(ErrorCode::kInvalidArgument,
                                     "OpenNI2 device URI '" + std::string(uri) +
                                         "': expected vendor/product@bus/address, e.g. 2bc5/0401@1/5");
  };
  const std::size_t slash = uri.find('/');
  const std::size_t at = uri.find('@');
  if (slash == std::string_view::npos || at == std::string_view::npos || at < slash) return bad();
  const std::size_t slash2 = uri.find('/', at);
  if (slash2 == std::string_view::npos) return bad();
  UsbDeviceSelector s;
  if (!parseHex16(uri.substr(0, slash), s.vendor_id) || !parseHex16(uri.substr(slash + 1, at - slash - 1), s.product_id) ||
      !parseDec8(uri.substr(at + 1, slash2 - at - 1), s.bus) || !parseDec8(uri.substr(slash2 + 1), s.address) ||
      s.address == 0) {
    return bad();
  }
  return s;
}

Result<UsbDeviceSelector> usbSelectorForVideoNode(std::string_view device_node, std::string_view sysfs_root) {
  namespace fs = std::filesystem;
  using R = Result<UsbDeviceSelector>;
  const std::string node(device_node);
  const std::string name = fs::path(node).filename().string();
  const fs::path class_dir = fs::path(std::string(sysfs_root)) / "class" / "video4linux" / name;
  std::error_code ec;
  if (name.rfind("video", 0) != 0 || !fs::exists(class_dir, ec)) {
    return R(ErrorCode::kNotFound, node + ": no such V4L2 device (" + class_dir.string() + " is missing)");
  }
  const fs::path interface_dir = fs::canonical(class_dir / "device", ec);
  if (ec) return R(ErrorCode::kInvalidArgument, node + ": no device behind it in sysfs: not a USB camera");
  // A USB interface directory is named "<port path>:<config>.<interface>".
  const std::string iface = interface_dir.filename().string();
  const std::size_t colon = iface.find(':');
  if (colon == std::string::npos || !isPortPath(std::string_view(iface).substr(0, colon))) {
    return R(ErrorCode::kInvalidArgument, node + " is not a USB device (" + interface_dir.string() +
                                              "): it has no USB port to reset");
  }
  UsbDeviceSelector s;
  s.port_path = iface.substr(0, colon);
  const fs::path usb_dir = interface_dir.parent_path();
  (void)parseHex16(readFirstLine(usb_dir / "idVendor"), s.vendor_id);
  (void)parseHex16(readFirstLine(usb_dir / "idProduct"), s.product_id);
  s.serial = readFirstLine(usb_dir / "serial");
  return s;
}

}  // namespace fovea::hal::usb
