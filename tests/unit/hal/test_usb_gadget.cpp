// hal/usb against the real kernel: a USB gadget made with configfs on the
// dummy_hcd virtual host controller, carrying Orbbec's ids 2bc5:0401 (an
// "Orbbec Astra"), as tests/vm/suites/usb.sh sets it up in the arm64 VM.
// Enumeration with the right model name, hot-plug removal and arrival as the
// test unbinds and binds the gadget (writing its configfs UDC file), and a port
// reset after which the device is found again.
//
// Environment (from the suite): FOVEA_USB_GADGET_DIR, the gadget's configfs
// directory; FOVEA_USB_GADGET_SERIAL, the serial it carries.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <dirent.h>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "hal/usb/usb_devices.h"
#include "hal/usb/usb_monitor.h"
#include "hal/usb/usb_reset.h"

namespace fovea::hal::usb {
namespace {

constexpr uint16_t kVendor = 0x2bc5;
constexpr uint16_t kProduct = 0x0401;

class UsbGadget : public ::testing::Test {
 protected:
  void SetUp() override {
    const char* dir = std::getenv("FOVEA_USB_GADGET_DIR");
    if (dir == nullptr || !std::ifstream(std::string(dir) + "/UDC")) {
      GTEST_SKIP() << "no dummy_hcd gadget: runs in tests/vm/run-vm (FOVEA_VM_SUITES=usb)";
    }
    udc_file_ = std::string(dir) + "/UDC";
    const char* serial = std::getenv("FOVEA_USB_GADGET_SERIAL");
    serial_ = serial ? serial : "";
    udc_name_ = firstUdc();
    ASSERT_FALSE(udc_name_.empty()) << "no UDC in /sys/class/udc (is dummy_hcd loaded?)";
    ASSERT_TRUE(bind(true));
  }

  static std::string firstUdc() {
    std::string name;
    if (DIR* d = opendir("/sys/class/udc")) {
      while (dirent* e = readdir(d)) {
        if (e->d_name[0] != '.') name = e->d_name;
      }
      closedir(d);
    }
    return name;
  }

  // Writes the UDC name (bind: the device appears on the dummy host) or an
  // empty line (unbind: it disappears).
  bool bind(bool on) {
    std::ofstream out(udc_file_);
    out << (on ? udc_name_ : std::string()) << "\n";
    out.flush();
    return static_cast<bool>(out) || !on;  // unbinding an unbound gadget fails harmlessly
  }

  // The gadget as listUsbCameras() sees it, waiting up to 10 s for it.
  bool findGadget(UsbCameraDevice& out) {
    for (int i = 0; i < 100; ++i) {
      Result<std::vector<UsbCameraDevice>> list = listUsbCameras();
      if (list.isOk()) {
        for (const UsbCameraDevice& d : list.value()) {
          if (d.vendor_id == kVendor && d.product_id == kProduct) {
            out = d;
            return true;
          }
        }
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return false;
  }

  // The next event for the gadget's ids of the given kind (others are skipped).
  static bool nextEvent(UsbMonitor& monitor, UsbEvent::Kind kind, UsbEvent& out) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < end) {
      if (!monitor.waitEvent(out, std::chrono::milliseconds(200))) continue;
      if (out.vendor_id == kVendor && out.product_id == kProduct && out.kind == kind) return true;
    }
    return false;
  }

  std::string udc_file_;
  std::string udc_name_;
  std::string serial_;
};

TEST_F(UsbGadget, EnumerationFindsItWithTheModelNameSerialAndPort) {
  UsbCameraDevice d;
  ASSERT_TRUE(findGadget(d)) << "the gadget 2bc5:0401 never appeared to libusb";
  ASSERT_NE(d.known, nullptr);
  EXPECT_EQ(d.known->model, "Orbbec Astra");
  EXPECT_FALSE(d.port_path.empty());
  EXPECT_TRUE(usbSelectorFromPortPath(d.port_path).isOk()) << d.port_path;
  if (!serial_.empty()) {
    EXPECT_EQ(d.serial, serial_) << d.serial_error;
  }
  EXPECT_NE(d.speed, UsbSpeed::kUnknown);
  const std::string line = formatUsbCamera(d);
  std::printf("listed: %s\n", line.c_str());
  EXPECT_EQ(line.rfind("Orbbec Astra 2bc5:0401 at " + d.port_path, 0), 0u) << line;
}

TEST_F(UsbGadget, HotplugSeesTheRemovalAndTheArrival) {
  UsbCameraDevice d;
  ASSERT_TRUE(findGadget(d));
  UsbMonitor monitor;
  const Status started = monitor.start();
  ASSERT_TRUE(started.isOk()) << started.toString();

  ASSERT_TRUE(bind(false));
  UsbEvent left;
  ASSERT_TRUE(nextEvent(monitor, UsbEvent::Kind::kLeft, left)) << "no removal event after unbinding the gadget";
  EXPECT_STREQ(left.port_path.data(), d.port_path.c_str());

  ASSERT_TRUE(bind(true));
  UsbEvent arrived;
  ASSERT_TRUE(nextEvent(monitor, UsbEvent::Kind::kArrived, arrived)) << "no arrival event after binding the gadget";
  ASSERT_NE(arrived.known, nullptr);
  EXPECT_EQ(arrived.known->model, "Orbbec Astra");
  EXPECT_STREQ(arrived.port_path.data(), d.port_path.c_str());
  EXPECT_FALSE(arrived.present_at_start);
  char line[128];
  formatUsbEvent(arrived, line, sizeof line);
  std::printf("%s\n", line);

  const UsbMonitorCounters c = monitor.counters();
  EXPECT_TRUE(c.available);
  EXPECT_GE(c.arrivals, 1u);
  EXPECT_GE(c.removals, 1u);
  EXPECT_EQ(c.dropped_events, 0u);
  monitor.stop();
  EXPECT_FALSE(monitor.running());
}

TEST_F(UsbGadget, MonitorReportsItAsPresentAtStart) {
  UsbCameraDevice d;
  ASSERT_TRUE(findGadget(d));
  UsbMonitorOptions options;
  options.report_present = true;
  UsbMonitor monitor(options);
  ASSERT_TRUE(monitor.start().isOk());
  UsbEvent event;
  ASSERT_TRUE(monitor.poll(event)) << "start() reported nothing present";
  EXPECT_TRUE(event.present_at_start);
  EXPECT_EQ(event.vendor_id, kVendor);
  EXPECT_EQ(monitor.counters().arrivals, 1u);
}

// libusb_reset_device succeeds, or reports NOT_FOUND when the device
// re-enumerated: both are fine, and the device is then found again.
TEST_F(UsbGadget, PortResetThenFoundAgain) {
  UsbCameraDevice d;
  ASSERT_TRUE(findGadget(d));
  Result<UsbDeviceSelector> by_port = usbSelectorFromPortPath(d.port_path);
  ASSERT_TRUE(by_port.isOk());
  const Status reset = resetUsbDevice(by_port.value());
  std::printf("reset by port %s: %s\n", d.port_path.c_str(), reset.toString().c_str());
  EXPECT_TRUE(reset.isOk() || reset.code() == ErrorCode::kNotFound) << reset.toString();
  UsbCameraDevice again;
  ASSERT_TRUE(findGadget(again)) << "the gadget did not come back after the reset";
  EXPECT_EQ(again.port_path, d.port_path);

  UsbDeviceSelector by_id;
  by_id.vendor_id = kVendor;
  by_id.product_id = kProduct;
  by_id.serial = again.serial;
  const Status reset2 = resetUsbDevice(by_id);
  EXPECT_TRUE(reset2.isOk() || reset2.code() == ErrorCode::kNotFound) << reset2.toString();
  ASSERT_TRUE(findGadget(again));

  UsbDeviceSelector wrong_serial = by_id;
  wrong_serial.serial = "not-" + again.serial;
  EXPECT_EQ(resetUsbDevice(wrong_serial).code(), ErrorCode::kNotFound);
}

}  // namespace
}  // namespace fovea::hal::usb
