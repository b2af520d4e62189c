// The known-camera table, the udev rules made from it, and the pure helpers of
// hal/usb (selectors, the sysfs lookup, formatting). No USB needed.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "hal/usb/usb_devices.h"
#include "hal/usb/usb_ids.h"
#include "hal/usb/usb_monitor.h"
#include "hal/usb/usb_reset.h"
#include "tests/support/programs.h"

namespace fovea::hal::usb {
namespace {

std::string hex4(uint16_t v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "%04x", v);
  return buf;
}

TEST(UsbIds, TableIsSortedWithoutDuplicatesAndComplete) {
  const auto table = knownUsbCameras();
  ASSERT_GT(table.size(), 30u);
  for (std::size_t i = 1; i < table.size(); ++i) {
    const auto& a = table[i - 1];
    const auto& b = table[i];
    EXPECT_TRUE(a.vendor_id < b.vendor_id || (a.vendor_id == b.vendor_id && a.product_id < b.product_id))
        << hex4(b.vendor_id) << ":" << hex4(b.product_id) << " out of order or duplicated";
  }
  for (const KnownUsbCamera& c : table) {
    EXPECT_FALSE(c.model.empty()) << hex4(c.vendor_id) << ":" << hex4(c.product_id);
    EXPECT_FALSE(usbVendorName(c.vendor_id).empty()) << "no vendor name for " << hex4(c.vendor_id);
    EXPECT_NE(c.product_id, 0u);
    // A camera fovea cannot stream says what it needs instead.
    if (c.backend == UsbCameraBackend::kNone) {
      EXPECT_FALSE(c.note.empty()) << c.model;
    }
  }
}

TEST(UsbIds, LookupFindsTheCamerasUsersPlugIn) {
  struct Expect {
    uint16_t vid, pid;
    const char* model;
    UsbCameraBackend backend;
  };
  const Expect expected[] = {
      {0x2bc5, 0x0401, "Orbbec Astra", UsbCameraBackend::kOpenNI2},
      {0x2bc5, 0x0403, "Orbbec Astra Pro", UsbCameraBackend::kOpenNI2},
      {0x2bc5, 0x066b, "Orbbec Femto Bolt", UsbCameraBackend::kV4l2},
      {0x8086, 0x0ad3, "Intel RealSense D415", UsbCameraBackend::kV4l2},
      {0x8086, 0x0b07, "Intel RealSense D435", UsbCameraBackend::kV4l2},
      {0x8086, 0x0b3a, "Intel RealSense D435i", UsbCameraBackend::kV4l2},
      {0x8086, 0x0b5c, "Intel RealSense D455", UsbCameraBackend::kV4l2},
      {0x8086, 0x0b5b, "Intel RealSense D405", UsbCameraBackend::kV4l2},
      {0x1d27, 0x0601, "Asus Xtion PRO LIVE", UsbCameraBackend::kOpenNI2},
      {0x045e, 0x02ae, "Microsoft Kinect (Xbox 360) camera", UsbCameraBackend::kNone},
      {0x045e, 0x02d8, "Microsoft Kinect v2", UsbCameraBackend::kNone},
      {0x2b03, 0xf582, "Stereolabs ZED", UsbCameraBackend::kNone},
      {0x03e7, 0x2485, "Luxonis OAK (Myriad X, not booted)", UsbCameraBackend::kNone},
  };
  for (const Expect& e : expected) {
    const KnownUsbCamera* c = findKnownUsbCamera(e.vid, e.pid);
    ASSERT_NE(c, nullptr) << hex4(e.vid) << ":" << hex4(e.pid);
    EXPECT_EQ(c->model, e.model);
    EXPECT_EQ(c->backend, e.backend) << e.model;
  }
  EXPECT_TRUE(findKnownUsbCamera(0x8086, 0x0b07)->wants_usb3);
  EXPECT_FALSE(findKnownUsbCamera(0x2bc5, 0x0401)->wants_usb3);
}

TEST(UsbIds, LookupOfEveryEntryAndOfUnknownIds) {
  for (const KnownUsbCamera& c : knownUsbCameras()) EXPECT_EQ(findKnownUsbCamera(c.vendor_id, c.product_id), &c);
  EXPECT_EQ(findKnownUsbCamera(0, 0), nullptr);
  EXPECT_EQ(findKnownUsbCamera(0xffff, 0xffff), nullptr);
  EXPECT_EQ(findKnownUsbCamera(0x2bc5, 0xffff), nullptr);  // known vendor, unknown product
  EXPECT_EQ(findKnownUsbCamera(0x1d6b, 0x0002), nullptr);  // a root hub
  EXPECT_EQ(usbVendorName(0x1d6b), "");
  EXPECT_STREQ(usbCameraBackendName(UsbCameraBackend::kOpenNI2), "openni2");
  EXPECT_STREQ(usbCameraBackendName(UsbCameraBackend::kV4l2), "v4l2");
  EXPECT_STREQ(usbCameraBackendName(UsbCameraBackend::kNone), "none");
}

// What a test can tell of udev syntax: every rule is comma-separated
// KEY[{attr}]OP"value" pairs, match keys compare (==), assignment keys assign
// (=, +=), and each rule matches a subsystem and assigns something.
void expectValidUdevRule(const std::string& line) {
  static const std::regex pair(R"re(^([A-Z]+)(\{[A-Za-z_]+\})?(==|!=|\+=|:=|=)"([^"]*)"$)re");
  const std::set<std::string> match_keys = {"SUBSYSTEM", "ATTR", "ATTRS", "ENV", "KERNEL"};
  const std::set<std::string> assign_keys = {"MODE", "GROUP", "TAG"};
  std::stringstream in(line);
  std::string token;
  bool has_subsystem = false, has_assignment = false;
  while (std::getline(in, token, ',')) {
    if (!token.empty() && token.front() == ' ') token.erase(0, 1);
    std::smatch m;
    ASSERT_TRUE(std::regex_match(token, m, pair)) << "bad token '" << token << "' in: " << line;
    const std::string key = m[1], op = m[3];
    if (match_keys.count(key)) {
      EXPECT_TRUE(op == "==" || op == "!=") << token;
      has_subsystem = has_subsystem || key == "SUBSYSTEM";
    } else {
      ASSERT_TRUE(assign_keys.count(key)) << "unexpected key " << key;
      EXPECT_TRUE(op == "=" || op == "+=") << token;
      has_assignment = true;
    }
    if ((key == "ATTR" || key == "ATTRS") && (m[2] == "{idVendor}" || m[2] == "{idProduct}")) {
      EXPECT_TRUE(std::regex_match(std::string(m[4]), std::regex("[0-9a-f]{4}"))) << token;
    }
    if (key == "MODE") {
      EXPECT_EQ(m[4], "0660");
    }
  }
  EXPECT_TRUE(has_subsystem) << line;
  EXPECT_TRUE(has_assignment) << line;
}

void expectRulesCoverTheTable(const std::string& rules) {
  std::vector<std::string> lines;
  std::stringstream in(rules);
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    expectValidUdevRule(line);
    lines.push_back(line);
  }
  EXPECT_EQ(lines.size(), 2 * knownUsbCameras().size());
  for (const KnownUsbCamera& c : knownUsbCameras()) {
    const std::string usb = "SUBSYSTEM==\"usb\", ENV{DEVTYPE}==\"usb_device\", ATTR{idVendor}==\"" + hex4(c.vendor_id) +
                            "\", ATTR{idProduct}==\"" + hex4(c.product_id) +
                            "\", MODE=\"0660\", GROUP=\"plugdev\", TAG+=\"uaccess\"";
    const std::string video = "SUBSYSTEM==\"video4linux\", ATTRS{idVendor}==\"" + hex4(c.vendor_id) +
                              "\", ATTRS{idProduct}==\"" + hex4(c.product_id) +
                              "\", MODE=\"0660\", GROUP=\"video\", TAG+=\"uaccess\"";
    EXPECT_EQ(std::count(lines.begin(), lines.end(), usb), 1) << c.model;
    EXPECT_EQ(std::count(lines.begin(), lines.end(), video), 1) << c.model;
  }
}

TEST(UsbUdevRules, EveryTableEntryHasAValidUsbAndVideoRule) { expectRulesCoverTheTable(udevRules()); }

TEST(UsbUdevRules, HeaderSaysHowToInstall) {
  const std::string rules = udevRules();
  EXPECT_EQ(rules.rfind("# 60-fovea-rgbd-cameras.rules", 0), 0u);
  EXPECT_NE(rules.find("udevadm control --reload && udevadm trigger"), std::string::npos);
  EXPECT_NE(rules.find("# Orbbec Astra (fovea backend: openni2)"), std::string::npos);
}

// The file the build generated (and installs) is the table's rules.
TEST(UsbUdevRules, TheGeneratedFileIsTheTablesRules) {
#ifdef FOVEA_UDEV_RULES_FILE
  const std::string path = test::buildDir() + "/" + FOVEA_UDEV_RULES_FILE;
  std::ifstream in(path);
  ASSERT_TRUE(in) << path << " was not generated";
  std::stringstream content;
  content << in.rdbuf();
  EXPECT_EQ(content.str(), udevRules());
  expectRulesCoverTheTable(content.str());
#else
  GTEST_SKIP() << "cross build without an emulator: the rules file is not generated at build time";
#endif
}

TEST(UsbSelector, PortPaths) {
  for (const char* good : {"1-2", "1-2.3", "12-1.4.2.1"}) {
    Result<UsbDeviceSelector> s = usbSelectorFromPortPath(good);
    ASSERT_TRUE(s.isOk()) << good;
    EXPECT_EQ(s->port_path, good);
    EXPECT_EQ(s->describe(), std::string("port ") + good);
  }
  for (const char* bad : {"", "1", "1-", "-2", "1-2.", "1-.2", "a-1", "1-2:1.0", "usb-0000:00:14.0-1", "1-2..3"}) {
    Result<UsbDeviceSelector> s = usbSelectorFromPortPath(bad);
    ASSERT_FALSE(s.isOk()) << bad;
    EXPECT_EQ(s.status().code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(s.status().message().find("e.g. 1-2.3"), std::string::npos);
  }
}

TEST(UsbSelector, OpenNI2Uris) {
  Result<UsbDeviceSelector> s = usbSelectorFromOpenNI2Uri("2bc5/0401@1/5");
  ASSERT_TRUE(s.isOk()) << s.status().toString();
  EXPECT_EQ(s->vendor_id, 0x2bc5);
  EXPECT_EQ(s->product_id, 0x0401);
  EXPECT_EQ(s->bus, 1);
  EXPECT_EQ(s->address, 5);
  EXPECT_EQ(s->describe(), "bus 1 address 5");
  ASSERT_TRUE(usbSelectorFromOpenNI2Uri("1D27/0601@3/127").isOk());
  for (const char* bad : {"", "Dummy", "2bc5/0401", "2bc5/0401@1", "2bc5@1/5", "2bc5/0401@1/0", "2bc5/0401@300/5",
                          "12345/0401@1/5", "zz/0401@1/5", "2bc5/0401@1/5x"}) {
    EXPECT_EQ(usbSelectorFromOpenNI2Uri(bad).status().code(), ErrorCode::kInvalidArgument) << bad;
  }
  UsbDeviceSelector by_id;
  by_id.vendor_id = 0x8086;
  by_id.product_id = 0x0b07;
  by_id.serial = "123";
  EXPECT_EQ(by_id.describe(), "8086:0b07 serial 123");
  EXPECT_TRUE(UsbDeviceSelector{}.empty());
  EXPECT_FALSE(by_id.empty());
}

// A fake sysfs: video0 is a UVC camera on port 1-2.3, video1 a platform device
// (vivid), video2 does not exist.
class FakeSysfs : public ::testing::Test {
 protected:
  void SetUp() override {
    namespace fs = std::filesystem;
    char tmpl[] = "/tmp/fovea-sysfs-XXXXXX";
    ASSERT_NE(mkdtemp(tmpl), nullptr);
    root_ = tmpl;
    const fs::path usb = root_ / "devices/pci0000:00/0000:00:14.0/usb1/1-2/1-2.3";
    fs::create_directories(usb / "1-2.3:1.0");
    std::ofstream(usb / "idVendor") << "8086\n";
    std::ofstream(usb / "idProduct") << "0b07\n";
    std::ofstream(usb / "serial") << "841612070123\n";
    fs::create_directories(root_ / "devices/platform/vivid.0");
    fs::create_directories(root_ / "class/video4linux/video0");
    fs::create_directories(root_ / "class/video4linux/video1");
    fs::create_directory_symlink("../../../devices/pci0000:00/0000:00:14.0/usb1/1-2/1-2.3/1-2.3:1.0",
                                 root_ / "class/video4linux/video0/device");
    fs::create_directory_symlink("../../../devices/platform/vivid.0", root_ / "class/video4linux/video1/device");
  }
  void TearDown() override { std::filesystem::remove_all(root_); }
  std::filesystem::path root_;
};

TEST_F(FakeSysfs, AUvcNodeGivesItsUsbPortIdsAndSerial) {
  Result<UsbDeviceSelector> s = usbSelectorForVideoNode("/dev/video0", root_.string());
  ASSERT_TRUE(s.isOk()) << s.status().toString();
  EXPECT_EQ(s->port_path, "1-2.3");
  EXPECT_EQ(s->vendor_id, 0x8086);
  EXPECT_EQ(s->product_id, 0x0b07);
  EXPECT_EQ(s->serial, "841612070123");
}

TEST_F(FakeSysfs, APlatformNodeIsNotUsbAndAMissingNodeIsNotFound) {
  Result<UsbDeviceSelector> vivid = usbSelectorForVideoNode("/dev/video1", root_.string());
  EXPECT_EQ(vivid.status().code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(vivid.status().message().find("not a USB device"), std::string::npos) << vivid.status().message();
  Result<UsbDeviceSelector> missing = usbSelectorForVideoNode("/dev/video2", root_.string());
  EXPECT_EQ(missing.status().code(), ErrorCode::kNotFound);
  EXPECT_EQ(usbSelectorForVideoNode("/dev/null", root_.string()).status().code(), ErrorCode::kNotFound);
}

TEST(UsbFormat, ACameraLineSaysModelPortSpeedSerialAndWarnings) {
  UsbCameraDevice d;
  d.known = findKnownUsbCamera(0x8086, 0x0b07);
  d.vendor_id = 0x8086;
  d.product_id = 0x0b07;
  d.bus = 2;
  d.address = 7;
  d.port_path = "2-1";
  d.speed = UsbSpeed::kHigh;
  d.serial_error = "serial unreadable: no permission (udev rule: ...)";
  EXPECT_TRUE(d.too_slow());
  const std::string line = formatUsbCamera(d);
  EXPECT_EQ(line.rfind("Intel RealSense D435 8086:0b07 at 2-1 (bus 2 address 7), USB 2 (480 Mbit/s)", 0), 0u) << line;
  EXPECT_NE(line.find("serial unreadable: no permission"), std::string::npos) << line;
  EXPECT_NE(line.find("backend v4l2"), std::string::npos) << line;
  EXPECT_NE(line.find("depth cameras need USB 3"), std::string::npos) << line;
  EXPECT_EQ(line.find('\n'), std::string::npos);

  d.speed = UsbSpeed::kSuper;
  d.serial = "841612070123";
  EXPECT_FALSE(d.too_slow());
  const std::string fast = formatUsbCamera(d);
  EXPECT_NE(fast.find("USB 3 (5 Gbit/s), serial 841612070123, backend v4l2"), std::string::npos) << fast;
  EXPECT_EQ(fast.find("WARNING"), std::string::npos) << fast;

  UsbCameraDevice astra;
  astra.known = findKnownUsbCamera(0x2bc5, 0x0401);
  astra.speed = UsbSpeed::kHigh;  // an Astra is a USB 2 camera: no warning
  EXPECT_FALSE(astra.too_slow());
  EXPECT_NE(formatUsbCamera(astra).find("Orbbec's OpenNI2 driver"), std::string::npos);
}

TEST(UsbFormat, EventLines) {
  UsbEvent e;
  e.known = findKnownUsbCamera(0x2bc5, 0x0401);
  e.vendor_id = 0x2bc5;
  e.product_id = 0x0401;
  std::snprintf(e.port_path.data(), e.port_path.size(), "1-2");
  char line[128];
  formatUsbEvent(e, line, sizeof line);
  EXPECT_STREQ(line, "usb: Orbbec Astra (2bc5:0401) arrived at 1-2");
  e.kind = UsbEvent::Kind::kLeft;
  formatUsbEvent(e, line, sizeof line);
  EXPECT_STREQ(line, "usb: Orbbec Astra (2bc5:0401) left 1-2");
  char tiny[8];
  EXPECT_EQ(formatUsbEvent(e, tiny, sizeof tiny), 7u);
  EXPECT_STREQ(tiny, "usb: Or");
}

}  // namespace
}  // namespace fovea::hal::usb
