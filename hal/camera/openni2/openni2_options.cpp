// The OpenNI2 backend's spec: its options, the help line, and the .oni URIs
// open() refuses. Apart from the camera because none of it needs OpenNI2.
#include "hal/spec_options.h"
#include "hal/camera/openni2/openni2_camera.h"

#include <utility>

namespace fovea::hal::openni2 {

namespace {

Status invalid(std::string message) { return Status(ErrorCode::kInvalidArgument, "openni2: " + std::move(message)); }

}  // namespace

Result<OpenNI2CameraOptions> parseOpenNI2CameraOptions(std::string_view args) {
  OpenNI2CameraOptions options;
  // The URI is optional: a first item with '=' is already an option.
  const SpecTokens tokens = tokenizeSpec(args, {.head = SpecTokenRules::Head::kFirstItemIfBare, .rest_key = {}, .bare_continues_value = false});
  options.uri = std::string(tokens.head.value_or(""));
  for (std::size_t i = 0; i < tokens.items.size(); ++i) {
    const auto& [key, value, has_value] = tokens.items[i];
    if (!has_value && key.empty()) {
      if (i + 1 == tokens.items.size()) break;  // a trailing comma
      return invalid("empty option in '" + std::string(args) + "'");
    }
    if (!has_value) {
      return invalid("option '" + std::string(key) +
                     "' is not key=value (keys: size, fps, colour, registration, sync)");
    }
    if (key == "size") {
      if (Status s = parseSpecSize("openni2", key, value, 1, 8192, options.width, options.height); !s) return s;
    } else if (key == "fps") {
      int fps = 0;
      if (!parseSpecInt(value, fps) || fps < 1 || fps > 1000) {
        return invalid("fps: expected a positive integer, got '" + std::string(value) + "'");
      }
      options.fps = fps;
    } else if (key == "colour" || key == "color") {
      if (Status s = parseSpecOnOff("openni2", key, value, options.colour); !s) return s;
    } else if (key == "registration") {
      if (Status s = parseSpecOnOff("openni2", key, value, options.registration); !s) return s;
    } else if (key == "sync") {
      if (Status s = parseSpecOnOff("openni2", key, value, options.sync); !s) return s;
    } else {
      return invalid("unknown option '" + std::string(key) + "' (keys: size, fps, colour, registration, sync)");
    }
  }
  return options;
}

std::string openni2CameraHelp() {
  return "openni2:[URI][,size=WxH,fps=N,colour=on|off,registration=on|off,sync=on|off]  an OpenNI2 camera "
         "(PrimeSense, Asus Xtion, Orbbec Astra): no URI takes the first device, URI as `fovead cameras` lists it, "
         "Dummy is OpenNI2's synthetic 320x240 device; registration=on (default) uses the device's depth-to-colour "
         "registration; .oni recordings are refused (Debian's OpenNI2 plays them without frames)";
}

bool isOniRecordingUri(std::string_view uri) {
  if (uri.size() < 4) return false;
  const std::string_view ext = uri.substr(uri.size() - 4);
  return ext[0] == '.' && (ext[1] == 'o' || ext[1] == 'O') && (ext[2] == 'n' || ext[2] == 'N') &&
         (ext[3] == 'i' || ext[3] == 'I');
}

}  // namespace fovea::hal::openni2
