// Internal to hal/usb (libusb builds only): a libusb context that closes itself
// and the few conversions the listing, the reset and the monitor share.
#pragma once

#include <libusb.h>

#include <cstddef>
#include <cstdint>
#include <string>

#include "core/result.h"
#include "hal/usb/usb_devices.h"

namespace fovea::hal::usb::detail {

class LibusbContext {
 public:
  LibusbContext() = default;
  ~LibusbContext() { reset(); }
  LibusbContext(const LibusbContext&) = delete;
  LibusbContext& operator=(const LibusbContext&) = delete;
  // kIoError naming libusb's error and the likely cause.
  Status init();
  void reset();
  libusb_context* get() const { return ctx_; }

 private:
  libusb_context* ctx_ = nullptr;
};

// "1-2.3" into out (NUL-terminated, truncated to size); no allocation. The
// root hub itself (no ports) is "1-0" as in sysfs' usb1... rarely needed.
std::size_t formatPortPath(libusb_device* device, char* out, std::size_t size);

UsbSpeed speedOf(libusb_device* device);

// "LIBUSB_ERROR_ACCESS (Access denied (insufficient permissions))"
std::string libusbErrorText(int error);

}  // namespace fovea::hal::usb::detail
