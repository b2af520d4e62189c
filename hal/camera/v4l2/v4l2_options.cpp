#include "hal/spec_options.h"
#include "hal/camera/v4l2/v4l2_options.h"

#include <linux/videodev2.h>

#include <charconv>
#include <cmath>
#include <utility>

namespace fovea::hal::v4l2 {

namespace {

constexpr std::string_view kForms =
    "v4l2:/dev/videoN|serial=SERIAL|bus=BUS_INFO|auto[,colour=/dev/videoM|serial=..|bus=..|auto|none,size=WxH,fps=N,"
    "format=Z16|Y16,colour_size=WxH,colour_format=YUYV|UYVY|MJPG|RGB3|BGR3,depth_scale=M,calib=FILE,buffers=N,"
    "pair_tolerance_ms=T,hfov_deg=D,colour_hfov_deg=D,extrinsics=identity]";
constexpr std::string_view kKeys =
    "colour, size, fps, format, colour_size, colour_format, depth_scale, calib, buffers, pair_tolerance_ms, "
    "hfov_deg, colour_hfov_deg, extrinsics";
constexpr int kMaxSide = 16384;
constexpr int kMaxBuffers = 32;

Status invalid(std::string message) { return {ErrorCode::kInvalidArgument, "v4l2: " + std::move(message)}; }

// "serial=X", "bus=X", a path or "auto"; for colour also "none".
Status parseSelector(std::string_view what, std::string_view text, bool colour, NodeSelector& out) {
  const auto prefixed = [&](std::string_view prefix) { return text.substr(0, prefix.size()) == prefix; };
  if (colour && text == "none") {
    out = {NodeSelector::Kind::kNone, ""};
  } else if (text == "auto") {
    out = {NodeSelector::Kind::kAuto, ""};
  } else if (prefixed("serial=")) {
    out = {NodeSelector::Kind::kSerial, std::string(text.substr(7))};
  } else if (prefixed("bus=")) {
    out = {NodeSelector::Kind::kBus, std::string(text.substr(4))};
  } else if (prefixed("/dev/")) {
    out = {NodeSelector::Kind::kPath, std::string(text)};
  } else {
    return invalid(std::string(what) + ": expected /dev/videoN, serial=SERIAL, bus=BUS_INFO" +
                   (colour ? ", auto or none" : " or auto") + ", got '" + std::string(text) + "'");
  }
  if (out.kind != NodeSelector::Kind::kNone && out.kind != NodeSelector::Kind::kAuto && out.value.empty()) {
    return invalid(std::string(what) + ": '" + std::string(text) + "' names nothing");
  }
  return Status::ok();
}

Status parseFourcc(std::string_view key, std::string_view value, bool colour, uint32_t& out) {
  struct Name {
    std::string_view name;
    uint32_t fourcc;
    bool colour;
  };
  static constexpr Name kNames[] = {
      {"Z16", V4L2_PIX_FMT_Z16, false},   {"Y16", V4L2_PIX_FMT_Y16, false},   {"YUYV", V4L2_PIX_FMT_YUYV, true},
      {"UYVY", V4L2_PIX_FMT_UYVY, true},  {"MJPG", V4L2_PIX_FMT_MJPEG, true}, {"RGB3", V4L2_PIX_FMT_RGB24, true},
      {"BGR3", V4L2_PIX_FMT_BGR24, true},
  };
  std::string accepted;
  for (const Name& n : kNames) {
    if (n.colour != colour) continue;
    if (n.name == value) {
      out = n.fourcc;
      return Status::ok();
    }
    if (!accepted.empty()) accepted += '|';
    accepted += n.name;
  }
  return invalid(std::string(key) + ": expected " + accepted + ", got '" + std::string(value) + "'");
}

}  // namespace

std::string fourccText(uint32_t fourcc) {
  std::string text(4, ' ');
  for (int i = 0; i < 4; ++i) {
    const char c = static_cast<char>((fourcc >> (8 * i)) & 0xff);
    text[static_cast<std::size_t>(i)] = (c >= 0x20 && c < 0x7f) ? c : '?';
  }
  while (!text.empty() && text.back() == ' ') text.pop_back();  // "Z16 " -> "Z16"
  return text;
}

std::string selectorText(const NodeSelector& selector) {
  switch (selector.kind) {
    case NodeSelector::Kind::kNone: return "none";
    case NodeSelector::Kind::kAuto: return "auto";
    case NodeSelector::Kind::kPath: return selector.value;
    case NodeSelector::Kind::kSerial: return "serial=" + selector.value;
    case NodeSelector::Kind::kBus: return "bus=" + selector.value;
  }
  return "?";
}

Result<V4l2CameraOptions> parseV4l2CameraOptions(std::string_view args) {
  V4l2CameraOptions options;
  if (args.empty()) return invalid("expected " + std::string(kForms));
  // The depth selector is the first item; "serial=" and "bus=" contain '=' too.
  const SpecTokens tokens = tokenizeSpec(args);
  if (Status s = parseSelector("depth node", tokens.head.value_or(""), false, options.depth); !s) return s;
  for (const auto& [key, value, has_value] : tokens.items) {
    if (!has_value) {
      return invalid("option '" + std::string(key) + "' is not key=value (keys: " + std::string(kKeys) + ")");
    }
    if (key == "colour" || key == "color") {
      if (Status s = parseSelector("colour", value, true, options.colour); !s) return s;
    } else if (key == "size") {
      if (Status s = parseSpecSize("v4l2", key, value, 1, kMaxSide, options.width, options.height); !s) return s;
    } else if (key == "colour_size" || key == "color_size") {
      if (Status s = parseSpecSize("v4l2", key, value, 1, kMaxSide, options.colour_width, options.colour_height); !s) return s;
    } else if (key == "fps") {
      if (!parseSpecInt(value, options.fps) || options.fps < 1 || options.fps > 1000) {
        return invalid("fps: expected an integer in 1..1000, got '" + std::string(value) + "'");
      }
    } else if (key == "format") {
      if (Status s = parseFourcc(key, value, false, options.depth_format); !s) return s;
    } else if (key == "colour_format" || key == "color_format") {
      if (Status s = parseFourcc(key, value, true, options.colour_format); !s) return s;
    } else if (key == "depth_scale") {
      if (!parseSpecDouble(value, options.depth_scale_m) || !(options.depth_scale_m > 0.0) ||
          options.depth_scale_m > 1.0) {
        return invalid("depth_scale: expected metres per depth unit in (0, 1] (0.001 for millimetres), got '" +
                       std::string(value) + "'");
      }
      options.depth_scale_given = true;
    } else if (key == "calib") {
      if (value.empty()) return invalid("calib: expected a calibration file path");
      options.calib_path = std::string(value);
    } else if (key == "buffers") {
      if (!parseSpecInt(value, options.buffers) || options.buffers < 2 || options.buffers > kMaxBuffers) {
        return invalid("buffers: expected an integer in 2.." + std::to_string(kMaxBuffers) + ", got '" +
                       std::string(value) + "'");
      }
    } else if (key == "pair_tolerance_ms") {
      double ms = 0.0;
      if (!parseSpecDouble(value, ms) || !(ms > 0.0) || ms > 1000.0) {
        return invalid("pair_tolerance_ms: expected milliseconds in (0, 1000], got '" + std::string(value) + "'");
      }
      options.pair_tolerance_ns = static_cast<int64_t>(std::llround(ms * 1e6));
    } else if (key == "hfov_deg" || key == "colour_hfov_deg" || key == "color_hfov_deg") {
      double deg = 0.0;
      if (!parseSpecDouble(value, deg) || !(deg >= 10.0) || !(deg <= 170.0)) {
        return invalid(std::string(key) + ": expected a horizontal field of view in 10..170 degrees, got '" +
                       std::string(value) + "'");
      }
      (key == "hfov_deg" ? options.hfov_deg : options.colour_hfov_deg) = deg;
    } else if (key == "extrinsics") {
      if (value != "identity") {
        return invalid("extrinsics: the only value is 'identity' (give real extrinsics in a calibration file), got '" +
                       std::string(value) + "'");
      }
      options.extrinsics_identity = true;
    } else {
      return invalid("unknown option '" + std::string(key) + "' (keys: " + std::string(kKeys) + ")");
    }
  }
  if (options.colour.kind == NodeSelector::Kind::kNone &&
      (options.colour_width != 0 || options.colour_format != 0 || options.colour_hfov_deg != 0.0 ||
       options.extrinsics_identity)) {
    return invalid("colour_size, colour_format, colour_hfov_deg and extrinsics need a colour node (colour=...)");
  }
  return options;
}

}  // namespace fovea::hal::v4l2
