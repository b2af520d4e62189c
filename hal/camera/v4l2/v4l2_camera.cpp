#include "hal/camera/v4l2/v4l2_camera.h"

#include <linux/videodev2.h>
#include <poll.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <utility>

#include "core/clock.h"
#include "hal/calibration_file.h"
#include "hal/camera/registration/registration.h"
#include "hal/usb/usb_reset.h"

namespace fovea::hal::v4l2 {

namespace {

std::string formatList(const std::vector<uint32_t>& formats) {
  std::string text;
  for (uint32_t f : formats) {
    if (!text.empty()) text += ", ";
    text += fourccText(f);
  }
  return text.empty() ? "nothing" : text;
}

std::string sizeText(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

std::string sizeList(const std::vector<FrameSize>& sizes) {
  std::string text;
  for (const FrameSize& s : sizes) {
    if (!text.empty()) text += ", ";
    text += sizeText(s.width, s.height);
    if (s.range) text += ".." + sizeText(s.max_width, s.max_height);
  }
  return text.empty() ? "no sizes" : text;
}

std::string rateText(double fps) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", std::round(fps * 100.0) / 100.0);
  return buf;
}

bool sizeOffered(const std::vector<FrameSize>& sizes, int w, int h) {
  for (const FrameSize& s : sizes) {
    if (!s.range && s.width == w && s.height == h) return true;
    if (s.range && w >= s.width && w <= s.max_width && h >= s.height && h <= s.max_height) return true;
  }
  return false;
}

// The size to negotiate: the requested one, or without a request 640x480 (the
// node's first size when it lacks 640x480). False when the node does not offer
// the requested size (a node listing no sizes takes any).
bool chooseSize(const std::vector<FrameSize>& sizes, int requested_w, int requested_h, int& w, int& h) {
  w = requested_w;
  h = requested_h;
  if (w == 0) {
    w = 640;
    h = 480;
    if (!sizes.empty() && !sizeOffered(sizes, w, h)) {
      w = sizes.front().width;
      h = sizes.front().height;
    }
    return true;
  }
  return sizes.empty() || sizeOffered(sizes, w, h);
}

Status deniedError(const std::vector<std::string>& denied) {
  std::string list;
  for (const std::string& d : denied) list += (list.empty() ? "" : ", ") + d;
  return {ErrorCode::kUnavailable,
          "v4l2: permission denied opening " + list +
              ": add the service's user to the video group (sudo usermod -aG video $USER, then log in again) or "
              "install fovea's udev rule 60-fovea-rgbd-cameras.rules (docs/cameras-usb.md)"};
}

// The modes of one format: "depth Y16 640x480 @ 30/25/15 fps".
void appendModes(const V4l2Node& node, const char* what, uint32_t fourcc, std::vector<std::string>& modes) {
  const std::string name = fourccText(fourcc);
  for (const FrameSize& s : node.frameSizes(fourcc)) {
    std::string line = std::string(what) + " " + name + " " + sizeText(s.width, s.height);
    if (s.range) {
      line += ".." + sizeText(s.max_width, s.max_height);
    } else {
      const std::vector<double> rates = node.frameRates(fourcc, s.width, s.height);
      for (std::size_t i = 0; i < rates.size(); ++i) line += (i == 0 ? " @ " : "/") + rateText(rates[i]);
      if (!rates.empty()) line += " fps";
    }
    modes.push_back(std::move(line));
  }
}

void appendNodeModes(const NodeInfo& info, bool depth, std::vector<std::string>& modes) {
  V4l2Node node(V4l2Node::Io::kRaw);
  if (!node.open(info.path)) return;
  if (depth) {
    for (uint32_t f : kDepthFourccs) {
      if (offersFormat(info.formats, f)) appendModes(node, "depth", f, modes);
    }
  } else {
    for (uint32_t f : kColourFourccs) {
      if (offersFormat(info.formats, f)) appendModes(node, "colour", f, modes);
    }
  }
}

std::string modelOf(const NodeInfo& info) {
  const UsbIdentity& usb = info.sysfs.usb;
  if (!usb.product.empty()) return usb.manufacturer.empty() ? usb.product : usb.manufacturer + " " + usb.product;
  return info.caps.card;
}

std::string detailOf(const NodeInfo& info) {
  std::string detail = info.path + ", " + info.caps.driver + ", " + info.caps.bus_info;
  const UsbIdentity& usb = info.sysfs.usb;
  if (!usb.vendor_id.empty()) detail += ", USB " + usb.vendor_id + ":" + usb.product_id + " port " + usb.port;
  return detail;
}

// The nodes of a colour sibling: colour formats, no depth, same device.
const NodeInfo* colourSibling(const std::vector<NodeInfo>& nodes, const NodeInfo& depth) {
  for (const NodeInfo& n : nodes) {
    if (&n != &depth && n.colour && !n.depth && sameDevice(n, depth)) return &n;
  }
  return nullptr;
}

Status calibrationSizeError(const char* what, const CameraIntrinsics& k, int w, int h, const std::string& source) {
  return {ErrorCode::kInvalidArgument, "v4l2: the " + std::string(what) + " calibration (from " + source + ") is for " +
                                           sizeText(k.width, k.height) + " but the node delivers " + sizeText(w, h) +
                                           ": calibrate at that size or ask for it (" +
                                           (std::string(what) == "depth" ? "size=" : "colour_size=") +
                                           sizeText(k.width, k.height) + ")"};
}

}  // namespace

CameraIntrinsics intrinsicsFromHfov(int width, int height, double hfov_deg) {
  constexpr double kPi = 3.14159265358979323846;
  const double f = 0.5 * width / std::tan(0.5 * hfov_deg * kPi / 180.0);
  return {width, height, f, f, 0.5 * (width - 1), 0.5 * (height - 1)};
}

std::string v4l2CameraHelp() {
  return "v4l2:/dev/videoN|serial=SERIAL|bus=BUS_INFO|auto[,colour=none|auto|/dev/videoM|serial=..|bus=..,size=WxH,fps=N,"
         "format=Z16|Y16,colour_size=WxH,colour_format=YUYV|UYVY|MJPG|RGB3|BGR3,depth_scale=M,calib=FILE,buffers=N,"
         "pair_tolerance_ms=T,hfov_deg=D,colour_hfov_deg=D,extrinsics=identity]  a UVC depth camera's depth node "
         "(Z16/Y16; `fovead cameras` lists them) and optionally its colour node (colour=auto: the sibling node of the "
         "same USB device), paired by timestamp and registered to depth. V4L2 reports no intrinsics: give a "
         "calibration (board profile, calib=FILE) or hfov_deg=D from the datasheet for an approximate pinhole. "
         "Defaults: 640x480, 30 fps, depth_scale 0.001 m, 4 buffers, tolerance half a depth frame";
}

Result<std::vector<DeviceListing>> discoverV4l2Cameras() { return discoverV4l2CamerasIn(V4l2Paths{}); }

Result<std::vector<DeviceListing>> discoverV4l2CamerasIn(const V4l2Paths& paths) {
  const NodeScan scan = scanNodes(paths);
  if (!scan.denied.empty()) return deniedError(scan.denied);
  std::vector<DeviceListing> listings;
  for (const NodeInfo& n : scan.nodes) {
    if (!n.depth) continue;
    DeviceListing listing;
    // The most stable name that is unique: the USB serial, the bus path, the node.
    int same_serial = 0;
    int same_bus = 0;
    for (const NodeInfo& m : scan.nodes) {
      if (!m.depth) continue;
      same_serial += !n.sysfs.usb.serial.empty() && m.sysfs.usb.serial == n.sysfs.usb.serial;
      same_bus += !n.caps.bus_info.empty() && m.caps.bus_info == n.caps.bus_info;
    }
    if (same_serial == 1) {
      listing.spec = "v4l2:serial=" + n.sysfs.usb.serial;
    } else if (same_bus == 1) {
      listing.spec = "v4l2:bus=" + n.caps.bus_info;
    } else {
      listing.spec = "v4l2:" + n.path;
    }
    listing.model = modelOf(n);
    listing.serial = n.sysfs.usb.serial;
    listing.detail = detailOf(n);
    appendNodeModes(n, true, listing.modes);
    if (const NodeInfo* c = colourSibling(scan.nodes, n)) {
      listing.detail += "; colour node " + c->path + " (add colour=auto and a calibration)";
      appendNodeModes(*c, false, listing.modes);
    }
    listings.push_back(std::move(listing));
  }
  for (const NodeInfo& n : scan.nodes) {
    if (n.depth || !n.colour) continue;
    bool sibling = false;
    for (const NodeInfo& d : scan.nodes) sibling = sibling || (d.depth && sameDevice(d, n));
    if (sibling) continue;
    DeviceListing listing;
    listing.spec = "colour=" + n.path;
    listing.model = modelOf(n);
    listing.serial = n.sysfs.usb.serial;
    listing.detail = detailOf(n) + "; a colour node without depth: give it as colour= beside a depth node";
    appendNodeModes(n, false, listing.modes);
    listings.push_back(std::move(listing));
  }
  return listings;
}

V4l2Camera::V4l2Camera(V4l2CameraOptions options, V4l2Paths paths)
    : options_(std::move(options)), paths_(std::move(paths)) {
  info_.name = "v4l2:" + selectorText(options_.depth);
  info_.depth_scale_m = options_.depth_scale_m;
  info_.fps = options_.fps > 0 ? options_.fps : 30.0;
}

V4l2Camera::~V4l2Camera() { closeNodes(); }

Result<std::unique_ptr<Camera>> V4l2Camera::create(std::string_view args) {
  Result<V4l2CameraOptions> options = parseV4l2CameraOptions(args);
  if (!options) return options.status();
  return std::unique_ptr<Camera>(std::make_unique<V4l2Camera>(std::move(options).value()));
}

Status V4l2Camera::setCalibration(const CameraCalibration& calibration) {
  // A colour calibration without colour=... is harmless: a board profile may
  // describe a colour camera this spec leaves out.
  const auto valid = [](const std::optional<StreamCalibration>& c) {
    if (!c) return true;
    const CameraIntrinsics& k = c->intrinsics;
    return k.width > 0 && k.height > 0 && std::isfinite(k.fx) && std::isfinite(k.fy) && k.fx > 0 && k.fy > 0 &&
           std::isfinite(k.cx) && std::isfinite(k.cy);
  };
  if (!valid(calibration.depth) || !valid(calibration.colour)) {
    return {ErrorCode::kInvalidArgument, "v4l2: the calibration from " + calibration.source +
                                             " has intrinsics without a positive size and focal length"};
  }
  calibration_ = calibration;
  return Status::ok();
}

Status V4l2Camera::resetDevice() {
  if (usb_.port.empty()) {
    return {ErrorCode::kUnavailable, "v4l2: " + (depth_.path().empty() ? selectorText(options_.depth) : depth_.path()) +
                                         " is not on USB (or was never opened): no port to reset"};
  }
  Result<usb::UsbDeviceSelector> which = usb::usbSelectorFromPortPath(usb_.port);
  if (!which) return which.status();
  return usb::resetUsbDevice(which.value());
}

PairingCounts V4l2Camera::pairingCounts() const { return pairer_ ? pairer_->counts() : PairingCounts{}; }

Result<std::string> V4l2Camera::resolveDepthPath() {
  const NodeSelector& sel = options_.depth;
  // First open by path: the path as given, its errors as they come.
  if (sel.kind == NodeSelector::Kind::kPath && seen_depth_.empty()) return sel.value;
  const NodeScan scan = scanNodes(paths_);
  if (const int i = pickDepthNode(scan.nodes, sel, seen_depth_); i >= 0) return scan.nodes[static_cast<std::size_t>(i)].path;
  if (!scan.denied.empty()) return deniedError(scan.denied);
  if (sel.kind == NodeSelector::Kind::kPath) {
    return Result<std::string>(ErrorCode::kNotFound,
                               "v4l2: the depth camera of " + sel.value + " (" + seen_depth_.bus_info +
                                   ") is gone: is it still plugged in? `fovead cameras` lists what is there");
  }
  std::string seen;
  for (const NodeInfo& n : scan.nodes) {
    if (!n.depth) continue;
    seen += (seen.empty() ? "" : "; ") + n.path + " bus " + n.caps.bus_info +
            (n.sysfs.usb.serial.empty() ? "" : " serial " + n.sysfs.usb.serial);
  }
  return Result<std::string>(
      ErrorCode::kNotFound, "v4l2: no depth node with " + selectorText(sel) + ": is the camera plugged in? " +
                                (seen.empty() ? std::string("no V4L2 node offers Z16 or Y16 depth")
                                              : "depth nodes seen: " + seen) +
                                " (`fovead cameras` lists them)");
}

Result<std::string> V4l2Camera::resolveColourPath() {
  const NodeSelector& sel = options_.colour;
  if (sel.kind == NodeSelector::Kind::kPath && seen_colour_.empty()) return sel.value;
  const NodeScan scan = scanNodes(paths_);
  if (const int i = pickColourNode(scan.nodes, sel, depth_.path(), seen_colour_); i >= 0) {
    return scan.nodes[static_cast<std::size_t>(i)].path;
  }
  if (!scan.denied.empty()) return deniedError(scan.denied);
  if (sel.kind == NodeSelector::Kind::kAuto) {
    return Result<std::string>(ErrorCode::kNotFound,
                               "v4l2: colour=auto: the device of " + depth_.path() + " (" + depth_.caps().bus_info +
                                   ") has no other node with a colour format (YUYV, UYVY, MJPG, RGB3, BGR3); name "
                                   "one with colour=/dev/videoM or drop colour=");
  }
  return Result<std::string>(ErrorCode::kNotFound, "v4l2: no colour node with " + selectorText(sel) +
                                                       " (`fovead cameras` lists the nodes): is it plugged in?");
}

Status V4l2Camera::negotiateDepth() {
  const std::vector<uint32_t> formats = depth_.formats();
  uint32_t fourcc = options_.depth_format;
  if (fourcc == 0) {
    for (uint32_t f : kDepthFourccs) {
      if (fourcc == 0 && offersFormat(formats, f)) fourcc = f;
    }
  }
  if (fourcc == 0 || !offersFormat(formats, fourcc)) {
    return {ErrorCode::kInvalidArgument,
            "v4l2: " + depth_.path() + " (" + depth_.caps().card + ") offers no " +
                (fourcc == 0 ? std::string("Z16 or Y16") : fourccText(fourcc)) +
                " depth format; it offers " + formatList(formats) +
                (offersColour(formats) && !offersDepth(formats) ? " (a colour node? give it as colour=)" : "") +
                "; `fovead cameras` lists the depth nodes"};
  }
  const std::vector<FrameSize> sizes = depth_.frameSizes(fourcc);
  int w = 0;
  int h = 0;
  if (!chooseSize(sizes, options_.width, options_.height, w, h)) {
    return {ErrorCode::kInvalidArgument, "v4l2: " + depth_.path() + " offers no " + fourccText(fourcc) + " at " +
                                             sizeText(w, h) + "; it offers " + sizeList(sizes)};
  }
  if (Status s = depth_.setFormat(fourcc, w, h); !s) return s;
  const std::vector<double> rates = depth_.frameRates(fourcc, w, h);
  int fps = options_.fps;
  if (fps == 0 && std::find(rates.begin(), rates.end(), 30.0) != rates.end()) fps = 30;
  if (fps != 0) {
    if (Status s = depth_.setFps(fps); !s) return s;
    if (std::abs(depth_.fps() - fps) > 0.5) {
      std::string offered;
      for (double r : rates) offered += (offered.empty() ? "" : ", ") + rateText(r);
      return {ErrorCode::kInvalidArgument, "v4l2: " + depth_.path() + " runs " + fourccText(fourcc) + " " +
                                               sizeText(w, h) + " at " + rateText(depth_.fps()) + " fps, not " +
                                               std::to_string(fps) + " (it offers " +
                                               (offered.empty() ? std::string("no list") : offered) + ")"};
    }
  }
  return Status::ok();
}

Status V4l2Camera::negotiateColour() {
  const std::vector<uint32_t> formats = colour_.formats();  // through libv4l2: emulated formats included
  uint32_t fourcc = options_.colour_format;
  if (fourcc == 0) {
    for (uint32_t f : kColourFourccs) {
      if (fourcc == 0 && offersFormat(formats, f)) fourcc = f;
    }
  }
  if (fourcc == 0 || !offersFormat(formats, fourcc)) {
    return {ErrorCode::kInvalidArgument,
            "v4l2: colour node " + colour_.path() + " (" + colour_.caps().card + ") offers no " +
                (fourcc == 0 ? std::string("YUYV, UYVY, MJPG, RGB3 or BGR3") : fourccText(fourcc)) +
                "; it offers " + formatList(formats)};
  }
  const std::vector<FrameSize> sizes = colour_.frameSizes(fourcc);
  int w = 0;
  int h = 0;
  if (!chooseSize(sizes, options_.colour_width, options_.colour_height, w, h)) {
    return {ErrorCode::kInvalidArgument, "v4l2: colour node " + colour_.path() + " offers no " + fourccText(fourcc) +
                                             " at " + sizeText(w, h) + "; it offers " + sizeList(sizes)};
  }
  if (Status s = colour_.setFormat(fourcc, w, h); !s) return s;
  // The colour node runs at the depth rate when it can (pairing wants it).
  const int fps = static_cast<int>(std::lround(depth_.fps() > 0 ? depth_.fps() : 30.0));
  const std::vector<double> rates = colour_.frameRates(fourcc, w, h);
  if (rates.empty() || std::find(rates.begin(), rates.end(), static_cast<double>(fps)) != rates.end()) {
    (void)colour_.setFps(fps);  // a node that refuses keeps its rate; pairing copes
  }
  if ((fourcc == V4L2_PIX_FMT_YUYV || fourcc == V4L2_PIX_FMT_UYVY) && w % 2 != 0) {
    return {ErrorCode::kInvalidArgument, "v4l2: colour width " + std::to_string(w) + " is odd; 4:2:2 needs even"};
  }
  if (fourcc == V4L2_PIX_FMT_MJPEG) {
    if (Status s = mjpeg_.create(); !s) return s;
  }
  return Status::ok();
}

Status V4l2Camera::prepareCalibration() {
  // calib=FILE, then what setCalibration() gave (the board profile) on top:
  // the profile is the more specific of the two.
  CameraCalibration calibration;
  if (!options_.calib_path.empty()) {
    Result<CameraCalibration> file = loadCalibrationFile(options_.calib_path);
    if (!file) return {file.status().code(), "v4l2: calib=" + options_.calib_path + ": " + file.status().message()};
    calibration = std::move(file).value();
  }
  if (calibration_.depth) calibration.depth = calibration_.depth;
  if (calibration_.colour) calibration.colour = calibration_.colour;
  if (calibration_.T_colour_depth) calibration.T_colour_depth = calibration_.T_colour_depth;
  if (calibration_.depth_scale_m) calibration.depth_scale_m = calibration_.depth_scale_m;
  if (!calibration_.empty()) {
    calibration.source = calibration.source.empty() ? calibration_.source
                                                    : calibration.source + " and " + calibration_.source;
  }
  const int w = depth_.width();
  const int h = depth_.height();
  StreamCalibration depth_cal;
  if (calibration.depth) {
    depth_cal = *calibration.depth;
    const CameraIntrinsics& k = depth_cal.intrinsics;
    if (k.width != w || k.height != h) return calibrationSizeError("depth", k, w, h, calibration.source);
  } else if (options_.hfov_deg > 0.0) {
    depth_cal.intrinsics = intrinsicsFromHfov(w, h, options_.hfov_deg);
  } else {
    return {ErrorCode::kInvalidArgument,
            "v4l2: no depth intrinsics for " + depth_.path() +
                ": a V4L2 node does not report them. Give a calibration file (calib=FILE) or the board profile's "
                "calibration, or hfov_deg=D with the depth camera's horizontal field of view from its datasheet "
                "(RealSense D435: 87, Orbbec Astra: 58) for an approximate pinhole"};
  }
  info_.intrinsics = depth_cal.intrinsics;
  info_.depth_scale_m = options_.depth_scale_given ? options_.depth_scale_m
                                                   : calibration.depth_scale_m.value_or(options_.depth_scale_m);
  if (!hasColour()) return Status::ok();

  hal::RegistrationParams params;
  params.depth = depth_cal;
  params.depth_scale_m = info_.depth_scale_m;
  const int cw = colour_.width();
  const int ch = colour_.height();
  if (calibration.colour) {
    params.colour = *calibration.colour;
    const CameraIntrinsics& k = params.colour.intrinsics;
    if (k.width != cw || k.height != ch) return calibrationSizeError("colour", k, cw, ch, calibration.source);
  } else if (options_.colour_hfov_deg > 0.0) {
    params.colour.intrinsics = intrinsicsFromHfov(cw, ch, options_.colour_hfov_deg);
  } else {
    return {ErrorCode::kInvalidArgument,
            "v4l2: no colour intrinsics for " + colour_.path() +
                ": give them in a calibration file (calib=FILE) or the board profile, or colour_hfov_deg=D from the "
                "datasheet for an approximate pinhole (or drop colour= for depth alone)"};
  }
  if (calibration.T_colour_depth) {
    params.T_colour_depth = *calibration.T_colour_depth;
  } else if (!options_.extrinsics_identity) {
    return {ErrorCode::kInvalidArgument,
            "v4l2: no depth-to-colour extrinsics: give them in a calibration file (calib=FILE) or the board "
            "profile, or extrinsics=identity to accept colour shifted by the distance between the two lenses"};
  }
  Result<hal::DepthToColourRegistration> registration = hal::DepthToColourRegistration::create(params);
  if (!registration) {
    return {registration.status().code(), "v4l2: colour registration: " + registration.status().message()};
  }
  registration_ = std::make_unique<hal::DepthToColourRegistration>(std::move(registration).value());
  return Status::ok();
}

Status V4l2Camera::open() {
  closeNodes();
  Result<std::string> depth_path = resolveDepthPath();
  if (!depth_path) return depth_path.status();
  if (Status s = depth_.open(depth_path.value()); !s) return s;
  if (Status s = negotiateDepth(); !s) {
    closeNodes();
    return s;
  }
  const std::string node_name = depth_.path().substr(depth_.path().rfind('/') + 1);
  const VideoNodeSysfs sysfs = readVideoNodeSysfs(paths_.sysfs_root, node_name);
  usb_ = sysfs.usb;
  seen_depth_ = {depth_.caps().bus_info, usb_.serial, depth_.pixelFormat()};
  info_.model = !usb_.product.empty() ? usb_.product : depth_.caps().card;
  info_.serial = usb_.serial;

  if (hasColour()) {
    Result<std::string> colour_path = resolveColourPath();
    if (!colour_path) {
      closeNodes();
      return colour_path.status();
    }
    Status s = colour_.open(colour_path.value());
    if (s) s = negotiateColour();
    if (!s) {
      closeNodes();
      return s;
    }
    const std::string colour_name = colour_.path().substr(colour_.path().rfind('/') + 1);
    seen_colour_ = {colour_.caps().bus_info, readVideoNodeSysfs(paths_.sysfs_root, colour_name).usb.serial,
                    colour_.pixelFormat()};
  }
  if (Status s = prepareCalibration(); !s) {
    closeNodes();
    return s;
  }
  if (Status s = depth_.allocateBuffers(options_.buffers); !s) {
    closeNodes();
    return s;
  }
  info_.fps = depth_.fps() > 0 ? depth_.fps() : info_.fps;
  info_.device_buffer_bytes = depth_.mappedBytes();
  if (hasColour()) {
    if (Status s = colour_.allocateBuffers(options_.buffers); !s) {
      closeNodes();
      return s;
    }
    info_.device_buffer_bytes += colour_.mappedBytes();
    const std::size_t rgb_bytes = static_cast<std::size_t>(colour_.width()) * colour_.height() * 3;
    colour_rgb_.assign(kColourSlots, std::vector<uint8_t>(rgb_bytes));
    const double depth_fps = depth_.fps() > 0 ? depth_.fps() : 30.0;
    const double colour_fps = colour_.fps() > 0 ? colour_.fps() : depth_fps;
    colour_period_ns_ = static_cast<int64_t>(1e9 / colour_fps);
    const int64_t tolerance_ns =
        options_.pair_tolerance_ns > 0 ? options_.pair_tolerance_ns : static_cast<int64_t>(0.5e9 / depth_fps);
    pairer_.emplace(static_cast<std::size_t>(kColourSlots), tolerance_ns);
  }
  opened_ = true;
  return Status::ok();
}

Status V4l2Camera::start() {
  if (!opened_) return {ErrorCode::kUnavailable, "v4l2 camera: call open() before start()"};
  if (started_) return Status::ok();
  if (Status s = depth_.startStreaming(); !s) return s;
  if (hasColour()) {
    if (Status s = colour_.startStreaming(); !s) {
      depth_.stopStreaming();
      return s;
    }
  }
  pending_ = false;
  have_colour_ = false;
  consecutive_unpaired_ = 0;
  if (pairer_) pairer_->clear();
  started_ = true;
  return Status::ok();
}

void V4l2Camera::closeNodes() {
  started_ = false;
  opened_ = false;
  pending_ = false;
  depth_.close();
  colour_.close();
  registration_.reset();
  pairer_.reset();
}

void V4l2Camera::stop() { closeNodes(); }

Status V4l2Camera::gone() {
  counters_.disconnect();
  started_ = false;
  pending_ = false;
  return {ErrorCode::kNotFound, "device gone"};
}

int V4l2Camera::drainColour() {
  for (;;) {
    // DQBUF only what poll says is there: libv4l2 prints every failed DQBUF,
    // EAGAIN included, and the frame path must not log. POLLERR is left to
    // acquire()'s poll.
    pollfd ready{colour_.fd(), POLLIN, 0};
    if (::poll(&ready, 1, 0) <= 0 || (ready.revents & POLLIN) == 0) return 0;
    V4l2Node::Frame f;
    const int err = colour_.dequeue(f);
    if (err == EAGAIN) return 0;
    if (err != 0) return err;
    const int slot = pairer_->nextColourSlot();
    uint8_t* rgb = colour_rgb_[static_cast<std::size_t>(slot)].data();
    const int w = colour_.width();
    const int h = colour_.height();
    const std::size_t stride = colour_.bytesPerLine();
    bool ok = !f.error_flag;
    if (ok) {
      switch (colour_.pixelFormat()) {
        case V4L2_PIX_FMT_YUYV: ok = yuyvToRgb(f.data, f.bytesused, stride, w, h, rgb); break;
        case V4L2_PIX_FMT_UYVY: ok = uyvyToRgb(f.data, f.bytesused, stride, w, h, rgb); break;
        case V4L2_PIX_FMT_RGB24: ok = rgb24ToRgb(f.data, f.bytesused, stride, w, h, rgb); break;
        case V4L2_PIX_FMT_BGR24: ok = bgr24ToRgb(f.data, f.bytesused, stride, w, h, rgb); break;
        case V4L2_PIX_FMT_MJPEG: ok = mjpeg_.decode(f.data, f.bytesused, w, h, rgb); break;
        default: ok = false; break;
      }
    }
    if (ok) {
      pairer_->pushColour(f.stamp_ns);
      latest_colour_stamp_ns_ = f.stamp_ns;
      have_colour_ = true;
    } else {
      counters_.badFrame();
    }
    if (const int q = colour_.requeue(f.index); q != 0) return q;
  }
}

// Error messages stay within std::string's small-buffer capacity (15
// characters in libstdc++), so even the error paths do not allocate.
Status V4l2Camera::acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) {
  if (!started_) {
    counters_.error();
    return {ErrorCode::kUnavailable, "not started"};
  }
  if (!slot.setSize(depth_.width(), depth_.height())) {
    counters_.error();
    return {ErrorCode::kCapacityExceeded, "slot too small"};
  }
  const bool colour = hasColour();
  // Bounded so that now + timeout cannot overflow (nanoseconds::max() is a valid argument).
  const auto deadline =
      std::chrono::steady_clock::now() + std::clamp<std::chrono::nanoseconds>(timeout, std::chrono::nanoseconds(0),
                                                                              std::chrono::hours(24));
  for (;;) {
    if (Status s = takeReadyFrames(colour); !s) return s;
    int64_t wait_for_colour_ns = 0;  // > 0: the pending depth frame waits this long more for colour
    if (pending_) {
      std::optional<int> colour_slot;
      if (colour) {
        bool dropped = false;
        if (Status s = pairPendingDepth(colour_slot, wait_for_colour_ns, dropped); !s) return s;
        if (dropped) continue;
      }
      if (wait_for_colour_ns == 0) return deliverPendingDepth(slot, colour_slot);
    }
    // Nothing to deliver yet: wait for either node.
    if (Status s = waitForNodes(deadline, wait_for_colour_ns, colour); !s) return s;
  }
}

// Takes the colour frames that are ready into the pairer and, unless a depth
// frame is already pending, dequeues the next depth frame if there is one.
Status V4l2Camera::takeReadyFrames(bool colour) {
  if (colour) {
    if (const int err = drainColour(); err != 0) {
      if (err == ENODEV) return gone();
      counters_.error();
      return {ErrorCode::kIoError, "colour dqbuf"};
    }
  }
  if (pending_) return Status::ok();
  const int err = depth_.dequeue(pending_depth_);
  if (err == ENODEV) return gone();
  if (err != 0 && err != EAGAIN) {
    counters_.error();
    return {ErrorCode::kIoError, "depth dqbuf"};
  }
  if (err == 0) {
    const bool size_ok = pending_depth_.bytesused >=
                         packedFrameBytes(depth_.bytesPerLine(), static_cast<std::size_t>(depth_.width()) * 2,
                                          depth_.height());
    if (pending_depth_.error_flag || !size_ok) {
      if (depth_.requeue(pending_depth_.index) == ENODEV) return gone();
      counters_.badFrame();
      return {ErrorCode::kInvalidInput, pending_depth_.error_flag ? "frame error" : "bad frame size"};
    }
    pending_ = true;
  }
  return Status::ok();
}

// Decides the pending depth frame's colour: its colour slot, or a time to
// wait for the colour that may still be in flight (wait_for_colour_ns > 0),
// or no colour at all (the depth frame is given back: dropped).
Status V4l2Camera::pairPendingDepth(std::optional<int>& colour_slot, int64_t& wait_for_colour_ns, bool& dropped) {
  // A colour frame later than the depth frame means no later one can be
  // nearer; otherwise wait for the colour that may still be in flight.
  const int64_t give_up_ns = pending_depth_.stamp_ns + pairer_->toleranceNs() + 2 * colour_period_ns_;
  const int64_t now_ns = monotonicNs();
  if ((!have_colour_ || latest_colour_stamp_ns_ < pending_depth_.stamp_ns) && now_ns < give_up_ns) {
    wait_for_colour_ns = give_up_ns - now_ns;
    return Status::ok();
  }
  colour_slot = pairer_->pairDepth(pending_depth_.stamp_ns);
  if (colour_slot) return Status::ok();
  pending_ = false;
  dropped = true;
  if (depth_.requeue(pending_depth_.index) == ENODEV) return gone();
  if (++consecutive_unpaired_ >= kMaxUnpairedDepth) {
    consecutive_unpaired_ = 0;
    counters_.error();
    return {ErrorCode::kInvalidInput, "colour unpaired"};
  }
  return Status::ok();
}

// Converts the pending depth frame into the slot, registers the paired colour
// frame (colour_slot, with colour) to it and gives the depth buffer back.
Status V4l2Camera::deliverPendingDepth(RgbdFrame& slot, const std::optional<int>& colour_slot) {
  const bool colour = hasColour();
  pending_ = false;
  const bool ok = depth16ToDepth(pending_depth_.data, pending_depth_.bytesused, depth_.bytesPerLine(), depth_.width(),
                                 depth_.height(), slot.depth());
  const int64_t stamp_ns = pending_depth_.stamp_ns;
  if (depth_.requeue(pending_depth_.index) == ENODEV) return gone();
  if (!ok) {
    counters_.badFrame();
    return {ErrorCode::kInvalidInput, "bad frame size"};
  }
  if (colour) {
    consecutive_unpaired_ = 0;
    (void)registration_->apply(slot.depth(), colour_rgb_[static_cast<std::size_t>(*colour_slot)].data(), slot.rgb());
  }
  slot.intrinsics = info_.intrinsics;
  slot.depth_scale_m = info_.depth_scale_m;
  slot.T_world_cam = Pose{};
  slot.has_rgb = colour;
  slot.stamp_ns = stamp_ns;
  slot.sequence = sequence_++;
  stalled_ = false;
  counters_.frameDelivered();
  return Status::ok();
}

// Polls the depth node (unless a depth frame is pending) and the colour node
// until one is ready, the deadline passes (a timeout) or wait_for_colour_ns, if
// given, is over; ok to look again.
Status V4l2Camera::waitForNodes(std::chrono::steady_clock::time_point deadline, int64_t wait_for_colour_ns,
                                bool colour) {
  const auto now = std::chrono::steady_clock::now();
  if (now >= deadline) {
    counters_.timeout();
    if (!stalled_) counters_.stall();
    stalled_ = true;
    return {ErrorCode::kUnavailable, "timeout"};
  }
  int64_t wait_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(deadline - now).count();
  if (wait_for_colour_ns > 0) wait_ns = std::min(wait_ns, wait_for_colour_ns);
  pollfd fds[2] = {{depth_.fd(), static_cast<short>(pending_ ? 0 : POLLIN), 0}, {colour_.fd(), POLLIN, 0}};
  const int wait_ms = static_cast<int>(std::min<int64_t>((wait_ns + 999'999) / 1'000'000, 60'000));
  const int r = ::poll(fds, colour ? 2 : 1, wait_ms);
  if (r < 0 && errno != EINTR) {
    counters_.error();
    return {ErrorCode::kIoError, "poll failed"};
  }
  for (int i = 0; i < (colour ? 2 : 1) && r > 0; ++i) {
    if ((fds[i].revents & POLLNVAL) != 0) return gone();
    // POLLERR without POLLIN: the node was unregistered (unplugged, driver
    // unloaded), or the queue failed; QUERYCAP's ENODEV says which.
    if ((fds[i].revents & (POLLERR | POLLHUP)) != 0 && (fds[i].revents & POLLIN) == 0) {
      if (i == 0 && pending_) continue;  // depth was not polled for input
      if (!(i == 0 ? depth_ : colour_).present()) return gone();
      counters_.error();
      return {ErrorCode::kIoError, "poll error"};
    }
  }
  return Status::ok();
}

}  // namespace fovea::hal::v4l2
