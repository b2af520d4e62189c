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

#include <arpa/inet.h>
#include <dirent.h>
#include <linux/netlink.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
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

// A stand-in for udevd's broadcast, for the VM only. Debian's libusb is built
// with libudev, whose monitor listens to udevd's netlink group (2), not to the
// kernel's (1); the VM runs no udevd, so libusb's hot-plug would hear nothing.
// This forwards each kernel uevent to group 2 in libudev's message format
// (header, then the kernel's KEY=value properties), as udevd does after
// processing it. On a real system udevd does this and fovea needs nothing.
class UeventForwarder {
 public:
  ~UeventForwarder() { stop(); }

  bool start() {
    in_ = socket(AF_NETLINK, SOCK_RAW | SOCK_CLOEXEC, NETLINK_KOBJECT_UEVENT);
    out_ = socket(AF_NETLINK, SOCK_RAW | SOCK_CLOEXEC, NETLINK_KOBJECT_UEVENT);
    if (in_ < 0 || out_ < 0) return false;
    sockaddr_nl kernel{};
    kernel.nl_family = AF_NETLINK;
    kernel.nl_groups = 1;  // the kernel's uevents
    if (bind(in_, reinterpret_cast<sockaddr*>(&kernel), sizeof kernel) != 0) return false;
    run_ = true;
    thread_ = std::thread([this] { loop(); });
    return true;
  }
  void stop() {
    run_ = false;
    if (thread_.joinable()) thread_.join();
    if (in_ >= 0) close(in_);
    if (out_ >= 0) close(out_);
    in_ = out_ = -1;
  }

 private:
  // systemd's string_hash32: MurmurHash2, seed 0 (libudev's socket filter compares it).
  static uint32_t murmur2(const char* key) {
    const uint32_t m = 0x5bd1e995;
    std::size_t len = std::strlen(key);
    uint32_t h = static_cast<uint32_t>(len);
    const auto* data = reinterpret_cast<const unsigned char*>(key);
    while (len >= 4) {
      uint32_t k;
      std::memcpy(&k, data, 4);
      k *= m;
      k ^= k >> 24;
      k *= m;
      h *= m;
      h ^= k;
      data += 4;
      len -= 4;
    }
    switch (len) {
      case 3: h ^= static_cast<uint32_t>(data[2]) << 16; [[fallthrough]];
      case 2: h ^= static_cast<uint32_t>(data[1]) << 8; [[fallthrough]];
      case 1: h ^= data[0]; h *= m; break;
      default: break;
    }
    h ^= h >> 13;
    h *= m;
    h ^= h >> 15;
    return h;
  }

  struct Header {  // libudev's monitor_netlink_header
    char prefix[8];
    uint32_t magic, header_size, properties_off, properties_len;
    uint32_t filter_subsystem_hash, filter_devtype_hash, filter_tag_bloom_hi, filter_tag_bloom_lo;
  };

  void loop() {
    std::vector<char> buf(8192);
    while (run_) {
      pollfd p{in_, POLLIN, 0};
      if (poll(&p, 1, 50) <= 0) continue;
      const ssize_t n = recv(in_, buf.data(), buf.size() - 1, 0);
      if (n <= 0) continue;
      buf[static_cast<std::size_t>(n)] = '\0';
      const std::size_t first = std::strlen(buf.data()) + 1;  // "add@/devices/..."
      if (first >= static_cast<std::size_t>(n)) continue;
      std::string subsystem, devtype;
      for (std::size_t i = first; i < static_cast<std::size_t>(n); i += std::strlen(&buf[i]) + 1) {
        if (std::strncmp(&buf[i], "SUBSYSTEM=", 10) == 0) subsystem = &buf[i + 10];
        if (std::strncmp(&buf[i], "DEVTYPE=", 8) == 0) devtype = &buf[i + 8];
      }
      Header h{};
      std::memcpy(h.prefix, "libudev", 8);
      h.magic = htonl(0xfeedcafe);
      h.header_size = sizeof h;
      h.properties_off = sizeof h;
      h.properties_len = static_cast<uint32_t>(static_cast<std::size_t>(n) - first);
      h.filter_subsystem_hash = htonl(murmur2(subsystem.c_str()));
      if (!devtype.empty()) h.filter_devtype_hash = htonl(murmur2(devtype.c_str()));
      iovec iov[2] = {{&h, sizeof h}, {&buf[first], h.properties_len}};
      sockaddr_nl udev{};
      udev.nl_family = AF_NETLINK;
      udev.nl_groups = 2;  // udevd's group, where libudev monitors listen
      msghdr msg{};
      msg.msg_name = &udev;
      msg.msg_namelen = sizeof udev;
      msg.msg_iov = iov;
      msg.msg_iovlen = 2;
      (void)sendmsg(out_, &msg, 0);
    }
  }

  int in_ = -1, out_ = -1;
  std::atomic<bool> run_{false};
  std::thread thread_;
};

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
    if (std::getenv("FOVEA_VM") != nullptr && access("/run/udev/control", F_OK) != 0) {
      ASSERT_TRUE(forwarder_.start()) << "cannot forward uevents: " << std::strerror(errno);
    }
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
  // Writing the UDC it is already bound to fails (EBUSY): only change state.
  bool bind(bool on) {
    std::string current;
    std::getline(std::ifstream(udc_file_) >> std::ws, current);
    if (on ? current == udc_name_ : current.empty()) return true;
    std::ofstream out(udc_file_);
    out << (on ? udc_name_ : std::string()) << "\n";
    out.flush();
    return static_cast<bool>(out);
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

  UeventForwarder forwarder_;
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

// The reset was issued: libusb_reset_device succeeded, or reported NOT_FOUND
// because the device re-enumerated after it. A kNotFound from a selector that
// matched nothing (or a device that went away before the reset) is a failure:
// the test could not otherwise tell a reset from a selector that never matched.
bool resetWasIssued(const Status& s) {
  if (s.isOk()) return true;
  return s.code() == ErrorCode::kNotFound &&
         s.message().find("re-enumerated or vanished after the reset") != std::string::npos;
}

TEST_F(UsbGadget, PortResetThenFoundAgain) {
  UsbCameraDevice d;
  ASSERT_TRUE(findGadget(d));
  Result<UsbDeviceSelector> by_port = usbSelectorFromPortPath(d.port_path);
  ASSERT_TRUE(by_port.isOk());
  const Status reset = resetUsbDevice(by_port.value());
  std::printf("reset by port %s: %s\n", d.port_path.c_str(), reset.toString().c_str());
  EXPECT_TRUE(resetWasIssued(reset)) << reset.toString();
  UsbCameraDevice again;
  ASSERT_TRUE(findGadget(again)) << "the gadget did not come back after the reset";
  EXPECT_EQ(again.port_path, d.port_path);

  UsbDeviceSelector by_id;
  by_id.vendor_id = kVendor;
  by_id.product_id = kProduct;
  by_id.serial = again.serial;
  const Status reset2 = resetUsbDevice(by_id);
  EXPECT_TRUE(resetWasIssued(reset2)) << reset2.toString();
  ASSERT_TRUE(findGadget(again));

  UsbDeviceSelector wrong_serial = by_id;
  wrong_serial.serial = "not-" + again.serial;
  const Status unmatched = resetUsbDevice(wrong_serial);
  EXPECT_EQ(unmatched.code(), ErrorCode::kNotFound);
  EXPECT_FALSE(resetWasIssued(unmatched)) << unmatched.toString();
}

}  // namespace
}  // namespace fovea::hal::usb
