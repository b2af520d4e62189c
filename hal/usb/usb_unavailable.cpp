// hal/usb in a build without libusb: the same functions, saying so.
#include <string>
#include <vector>

#include "hal/usb/usb_devices.h"
#include "hal/usb/usb_monitor.h"
#include "hal/usb/usb_reset.h"

namespace fovea::hal::usb {

namespace {
constexpr const char* kNoLibusb =
    "fovea was built without libusb (apt-get install libusb-1.0-0-dev, then configure again)";
}

Result<std::vector<UsbCameraDevice>> listUsbCameras() {
  return Result<std::vector<UsbCameraDevice>>(ErrorCode::kUnavailable, kNoLibusb);
}

Status usbHotplugSupported() { return {ErrorCode::kUnavailable, kNoLibusb}; }

Status resetUsbDevice(const UsbDeviceSelector& which) {
  return {ErrorCode::kUnavailable, "usb reset of " + which.describe() + ": " + kNoLibusb};
}

struct UsbMonitor::Impl {};

UsbMonitor::UsbMonitor(const UsbMonitorOptions&) : impl_(std::make_unique<Impl>()) {}
UsbMonitor::~UsbMonitor() = default;
Status UsbMonitor::start() {
  unavailable_reason_ = kNoLibusb;
  return {ErrorCode::kUnavailable, unavailable_reason_};
}
void UsbMonitor::stop() {}
bool UsbMonitor::running() const { return false; }
bool UsbMonitor::poll(UsbEvent&) { return false; }
bool UsbMonitor::waitEvent(UsbEvent&, std::chrono::milliseconds) { return false; }
UsbMonitorCounters UsbMonitor::counters() const { return {}; }

}  // namespace fovea::hal::usb
