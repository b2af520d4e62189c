// OpenNI2 video modes and the geometry they give: a mode's description, the
// choice of the depth and colour modes among those a sensor offers, and the
// intrinsics of a field of view. Pure functions of what the device reports,
// apart from the camera so that they read (and are tested) without a device.
#include "hal/camera/openni2/openni2_camera.h"

#include <OpenNI.h>

#include <algorithm>
#include <cmath>

namespace fovea::hal::openni2 {

namespace {

const char* pixelFormatName(int format) {
  switch (format) {
    case openni::PIXEL_FORMAT_DEPTH_1_MM: return "DEPTH_1_MM";
    case openni::PIXEL_FORMAT_DEPTH_100_UM: return "DEPTH_100_UM";
    case openni::PIXEL_FORMAT_SHIFT_9_2: return "SHIFT_9_2";
    case openni::PIXEL_FORMAT_SHIFT_9_3: return "SHIFT_9_3";
    case openni::PIXEL_FORMAT_RGB888: return "RGB888";
    case openni::PIXEL_FORMAT_YUV422: return "YUV422";
    case openni::PIXEL_FORMAT_GRAY8: return "GRAY8";
    case openni::PIXEL_FORMAT_GRAY16: return "GRAY16";
    case openni::PIXEL_FORMAT_JPEG: return "JPEG";
    case openni::PIXEL_FORMAT_YUYV: return "YUYV";
    default: return "format?";
  }
}

}  // namespace

std::string describeVideoMode(const VideoModeDesc& mode) {
  return std::to_string(mode.width) + "x" + std::to_string(mode.height) + " @ " + std::to_string(mode.fps) + " fps " +
         pixelFormatName(mode.pixel_format);
}

Result<int> chooseVideoMode(const std::vector<VideoModeDesc>& modes, const std::vector<int>& formats, int width,
                            int height, int fps, const VideoModeDesc& preferred, std::string_view sensor) {
  const auto formatRank = [&](int format) {
    const auto it = std::find(formats.begin(), formats.end(), format);
    return it == formats.end() ? -1 : static_cast<int>(it - formats.begin());
  };
  int best = -1;
  for (std::size_t i = 0; i < modes.size(); ++i) {
    const VideoModeDesc& m = modes[i];
    const int rank = formatRank(m.pixel_format);
    if (rank < 0) continue;
    if (width > 0 && (m.width != width || m.height != height)) continue;
    if (fps > 0 && m.fps != fps) continue;
    if (width == 0) {
      const bool is_preferred = m.width == preferred.width && m.height == preferred.height &&
                                (fps > 0 || m.fps == preferred.fps);
      if (is_preferred && (best < 0 || !(modes[best].width == preferred.width &&
                                         modes[best].height == preferred.height) ||
                           rank < formatRank(modes[best].pixel_format))) {
        best = static_cast<int>(i);
        continue;
      }
      if (best >= 0 && modes[best].width == preferred.width && modes[best].height == preferred.height) continue;
    }
    if (best < 0 || rank < formatRank(modes[best].pixel_format)) best = static_cast<int>(i);
  }
  if (best >= 0) return best;
  std::string wanted = width > 0 ? std::to_string(width) + "x" + std::to_string(height) : std::string("any size");
  wanted += fps > 0 ? " @ " + std::to_string(fps) + " fps" : std::string(" at any rate");
  std::string accepted;
  for (int f : formats) accepted += (accepted.empty() ? "" : "|") + std::string(pixelFormatName(f));
  std::string listed;
  for (const VideoModeDesc& m : modes) listed += "\n  " + describeVideoMode(m);
  if (modes.empty()) listed = " none";
  return Result<int>(ErrorCode::kInvalidArgument,
                     "openni2: the " + std::string(sensor) + " sensor has no mode " + wanted + " in " + accepted +
                         "; pick size= and fps= from the modes it offers:" + listed);
}

CameraIntrinsics intrinsicsFromFov(int width, int height, double hfov_rad, double vfov_rad) {
  CameraIntrinsics k;
  k.width = width;
  k.height = height;
  k.fx = width / (2.0 * std::tan(hfov_rad / 2.0));
  k.fy = height / (2.0 * std::tan(vfov_rad / 2.0));
  // OpenNI's CoordinateConverter maps pixel x to (x / w - 0.5) * z * 2 tan(hfov / 2).
  k.cx = width / 2.0;
  k.cy = height / 2.0;
  return k;
}

}  // namespace fovea::hal::openni2
