// hal/usb with libusb: enumeration, the hot-plug capability and the port reset.
#include <libusb.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "hal/usb/libusb_support.h"
#include "hal/usb/usb_devices.h"
#include "hal/usb/usb_reset.h"

namespace fovea::hal::usb {

namespace detail {

Status LibusbContext::init() {
  reset();
  const int r = libusb_init(&ctx_);
  if (r != 0) {
    ctx_ = nullptr;
    return {ErrorCode::kIoError, "libusb cannot start: " + libusbErrorText(r) +
                                     " (no /dev/bus/usb? In a container, pass the USB bus through)"};
  }
  return Status::ok();
}

void LibusbContext::reset() {
  if (ctx_ != nullptr) libusb_exit(ctx_);
  ctx_ = nullptr;
}

std::size_t formatPortPath(libusb_device* device, char* out, std::size_t size) {
  if (size == 0) return 0;
  uint8_t ports[8];
  const int n = libusb_get_port_numbers(device, ports, sizeof ports);
  int len = std::snprintf(out, size, "%u-", libusb_get_bus_number(device));
  if (n <= 0) len = std::snprintf(out, size, "%u-0", libusb_get_bus_number(device));
  for (int i = 0; i < n && len >= 0 && static_cast<std::size_t>(len) < size; ++i) {
    len += std::snprintf(out + len, size - static_cast<std::size_t>(len), i == 0 ? "%u" : ".%u", ports[i]);
  }
  return len < 0 ? 0 : std::min(static_cast<std::size_t>(len), size - 1);
}

UsbSpeed speedOf(libusb_device* device) {
  switch (libusb_get_device_speed(device)) {
    case LIBUSB_SPEED_LOW: return UsbSpeed::kLow;
    case LIBUSB_SPEED_FULL: return UsbSpeed::kFull;
    case LIBUSB_SPEED_HIGH: return UsbSpeed::kHigh;
    case LIBUSB_SPEED_SUPER: return UsbSpeed::kSuper;
    case LIBUSB_SPEED_SUPER_PLUS: return UsbSpeed::kSuperPlus;
    default: return UsbSpeed::kUnknown;
  }
}

std::string libusbErrorText(int error) {
  return std::string(libusb_error_name(error)) + " (" + libusb_strerror(error) + ")";
}

}  // namespace detail

namespace {

constexpr const char* kUdevHint = "install fovea's udev rule 60-fovea-rgbd-cameras.rules and join group plugdev";

// The serial string, or why it could not be read.
void readSerial(libusb_device* device, const libusb_device_descriptor& desc, UsbCameraDevice& out) {
  libusb_device_handle* handle = nullptr;
  const int r = libusb_open(device, &handle);
  if (r == LIBUSB_ERROR_ACCESS) {
    out.serial_error = std::string("serial unreadable: no permission (udev rule: ") + kUdevHint + ")";
    return;
  }
  if (r != 0) {
    out.serial_error = "serial unreadable: " + detail::libusbErrorText(r);
    return;
  }
  if (desc.iSerialNumber == 0) {
    out.serial_error = "device has no serial number";
  } else {
    unsigned char buf[128];
    const int n = libusb_get_string_descriptor_ascii(handle, desc.iSerialNumber, buf, sizeof buf);
    if (n < 0) {
      out.serial_error = "serial unreadable: " + detail::libusbErrorText(n);
    } else {
      out.serial.assign(reinterpret_cast<const char*>(buf), static_cast<std::size_t>(n));
    }
  }
  libusb_close(handle);
}

// The device list, freed on scope exit.
class DeviceList {
 public:
  explicit DeviceList(libusb_context* ctx) : count_(libusb_get_device_list(ctx, &list_)) {}
  ~DeviceList() {
    if (list_ != nullptr) libusb_free_device_list(list_, 1);
  }
  DeviceList(const DeviceList&) = delete;
  DeviceList& operator=(const DeviceList&) = delete;
  ssize_t count() const { return count_; }
  libusb_device* operator[](ssize_t i) const { return list_[i]; }

 private:
  libusb_device** list_ = nullptr;
  ssize_t count_;
};

std::string portPath(libusb_device* device) {
  char buf[32];
  const std::size_t n = detail::formatPortPath(device, buf, sizeof buf);
  return std::string(buf, n);
}

}  // namespace

Result<std::vector<UsbCameraDevice>> listUsbCameras() {
  using R = Result<std::vector<UsbCameraDevice>>;
  detail::LibusbContext ctx;
  if (Status s = ctx.init(); !s) return s;
  DeviceList list(ctx.get());
  if (list.count() < 0) {
    return R(ErrorCode::kIoError, "libusb cannot list USB devices: " + detail::libusbErrorText(static_cast<int>(list.count())));
  }
  std::vector<UsbCameraDevice> out;
  for (ssize_t i = 0; i < list.count(); ++i) {
    libusb_device* device = list[i];
    libusb_device_descriptor desc{};
    if (libusb_get_device_descriptor(device, &desc) != 0) continue;
    const KnownUsbCamera* known = findKnownUsbCamera(desc.idVendor, desc.idProduct);
    if (known == nullptr) continue;
    UsbCameraDevice d;
    d.known = known;
    d.vendor_id = desc.idVendor;
    d.product_id = desc.idProduct;
    d.bus = libusb_get_bus_number(device);
    d.address = libusb_get_device_address(device);
    d.port_path = portPath(device);
    d.speed = detail::speedOf(device);
    readSerial(device, desc, d);
    out.push_back(std::move(d));
  }
  std::sort(out.begin(), out.end(), [](const UsbCameraDevice& a, const UsbCameraDevice& b) {
    return a.bus != b.bus ? a.bus < b.bus : a.port_path < b.port_path;
  });
  return out;
}

Status usbHotplugSupported() {
  if (libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) == 0) {
    return {ErrorCode::kUnavailable, "this platform's libusb has no hot-plug support (LIBUSB_CAP_HAS_HOTPLUG)"};
  }
  return Status::ok();
}

Status resetUsbDevice(const UsbDeviceSelector& which) {
  if (which.empty()) {
    return {ErrorCode::kInvalidArgument, "usb reset: no device selected (give a port path, bus/address or vendor/product)"};
  }
  detail::LibusbContext ctx;
  if (Status s = ctx.init(); !s) return {s.code(), "usb reset of " + which.describe() + ": " + s.message()};
  DeviceList list(ctx.get());
  if (list.count() < 0) {
    return {ErrorCode::kIoError, "usb reset: cannot list devices: " + detail::libusbErrorText(static_cast<int>(list.count()))};
  }
  libusb_device* target = nullptr;
  bool permission_denied = false;  // a vendor/product match whose serial we could not read
  for (ssize_t i = 0; i < list.count() && target == nullptr; ++i) {
    libusb_device* device = list[i];
    if (!which.port_path.empty()) {
      if (portPath(device) == which.port_path) target = device;
      continue;
    }
    if (which.address != 0) {
      if (libusb_get_bus_number(device) == which.bus && libusb_get_device_address(device) == which.address) target = device;
      continue;
    }
    libusb_device_descriptor desc{};
    if (libusb_get_device_descriptor(device, &desc) != 0) continue;
    if (desc.idVendor != which.vendor_id || desc.idProduct != which.product_id) continue;
    if (which.serial.empty()) {
      target = device;
      continue;
    }
    UsbCameraDevice probe;
    readSerial(device, desc, probe);
    if (probe.serial == which.serial) target = device;
    if (probe.serial.empty() && probe.serial_error.find("no permission") != std::string::npos) permission_denied = true;
  }
  if (target == nullptr) {
    if (permission_denied) {
      return {ErrorCode::kUnavailable, "usb reset of " + which.describe() + ": no permission to read serial numbers (" +
                                           kUdevHint + ")"};
    }
    return {ErrorCode::kNotFound, "usb reset: no USB device at " + which.describe() +
                                      " (unplugged? `lsusb -t` shows what is connected)"};
  }
  libusb_device_handle* handle = nullptr;
  if (const int r = libusb_open(target, &handle); r != 0) {
    if (r == LIBUSB_ERROR_ACCESS) {
      return {ErrorCode::kUnavailable, "usb reset of " + which.describe() + ": no permission (" + kUdevHint + ")"};
    }
    if (r == LIBUSB_ERROR_NO_DEVICE || r == LIBUSB_ERROR_NOT_FOUND) {
      return {ErrorCode::kNotFound, "usb reset of " + which.describe() + ": the device went away"};
    }
    return {ErrorCode::kIoError, "usb reset of " + which.describe() + ": cannot open: " + detail::libusbErrorText(r)};
  }
  const int r = libusb_reset_device(handle);
  libusb_close(handle);
  if (r == 0) return Status::ok();
  if (r == LIBUSB_ERROR_NOT_FOUND || r == LIBUSB_ERROR_NO_DEVICE) {
    return {ErrorCode::kNotFound, "usb reset of " + which.describe() +
                                      ": the device re-enumerated or vanished after the reset: find it again"};
  }
  return {ErrorCode::kIoError, "usb reset of " + which.describe() + ": " + detail::libusbErrorText(r)};
}

}  // namespace fovea::hal::usb
