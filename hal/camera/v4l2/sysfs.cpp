#include "hal/camera/v4l2/sysfs.h"

#include <algorithm>
#include <charconv>
#include <filesystem>
#include <fstream>

namespace fovea::hal::v4l2 {

namespace fs = std::filesystem;

namespace {

// The first line of a sysfs attribute, trailing whitespace cut; "" when absent.
std::string readAttribute(const fs::path& path) {
  std::ifstream in(path);
  std::string line;
  if (!in || !std::getline(in, line)) return {};
  while (!line.empty() && (line.back() == '\n' || line.back() == '\r' || line.back() == ' ')) line.pop_back();
  return line;
}

// "video12" -> 12; -1 for anything else ("video-foo", "vbi0").
int videoNumber(std::string_view name) {
  if (name.substr(0, 5) != "video" || name.size() == 5) return -1;
  int n = -1;
  const std::string_view digits = name.substr(5);
  const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), n);
  return ec == std::errc() && end == digits.data() + digits.size() ? n : -1;
}

}  // namespace

std::vector<std::string> listVideoNodes(const std::string& dev_root) {
  std::vector<std::pair<int, std::string>> found;
  std::error_code ec;
  for (fs::directory_iterator it(dev_root, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const int n = videoNumber(name);
    if (n >= 0) found.emplace_back(n, name);
  }
  std::sort(found.begin(), found.end());
  std::vector<std::string> names;
  for (auto& [n, name] : found) names.push_back(std::move(name));
  return names;
}

VideoNodeSysfs readVideoNodeSysfs(const std::string& sysfs_root, std::string_view node) {
  VideoNodeSysfs out;
  out.node = std::string(node);
  const fs::path class_dir = fs::path(sysfs_root) / "class" / "video4linux" / std::string(node);
  out.card = readAttribute(class_dir / "name");
  const std::string index = readAttribute(class_dir / "index");
  if (!index.empty()) {
    int i = -1;
    const auto [end, ec] = std::from_chars(index.data(), index.data() + index.size(), i);
    if (ec == std::errc()) out.index = i;
  }
  std::error_code ec;
  fs::path dir = fs::canonical(class_dir / "device", ec);
  if (ec) return out;
  const fs::path root = fs::canonical(sysfs_root, ec);
  // Up from the interface (uvcvideo binds to 1-1:1.0) to the device (1-1),
  // staying inside the sysfs root.
  for (int depth = 0; depth < 8 && !dir.empty() && dir != root && dir != dir.root_path(); ++depth) {
    if (fs::exists(dir / "idVendor", ec)) {
      out.usb.device_path = dir.string();
      out.usb.port = dir.filename().string();
      out.usb.vendor_id = readAttribute(dir / "idVendor");
      out.usb.product_id = readAttribute(dir / "idProduct");
      out.usb.serial = readAttribute(dir / "serial");
      out.usb.manufacturer = readAttribute(dir / "manufacturer");
      out.usb.product = readAttribute(dir / "product");
      out.usb.busnum = readAttribute(dir / "busnum");
      out.usb.devnum = readAttribute(dir / "devnum");
      break;
    }
    dir = dir.parent_path();
  }
  return out;
}

}  // namespace fovea::hal::v4l2
