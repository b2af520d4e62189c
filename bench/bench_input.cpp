#include "bench/bench_input.h"

#include <cstring>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include "hal/camera.h"

namespace fovea::bench {

namespace {

Result<FrameInput> grab(const std::string& spec, int index) {
  Result<std::unique_ptr<hal::Camera>> created = hal::createCamera(spec);
  if (!created) return created.status();
  hal::Camera& camera = *created.value();
  if (Status s = camera.open(); !s) return s;
  if (Status s = camera.start(); !s) return s;
  const hal::CameraIntrinsics& k = camera.info().intrinsics;
  FrameInput input{hal::RgbdFrame(k.width, k.height), {}, {}};
  for (int i = 0; i <= index; ++i) {
    if (Status s = camera.acquire(input.frame, std::chrono::seconds(5)); !s) {
      return Status(s.code(), spec + ": frame " + std::to_string(i) + ": " + s.message());
    }
  }
  camera.stop();
  input.gaze.origin_m = input.frame.T_world_cam.t_world_cam;
  if (camera.info().focus_point_m) {
    input.gaze.direction = *camera.info().focus_point_m - input.gaze.origin_m;
    input.description = camera.info().name + " " + std::to_string(k.width) + "x" + std::to_string(k.height) +
                        ", gaze from the camera to the scene centre";
  } else {
    input.gaze.direction = input.frame.T_world_cam.R_world_cam.col(2);
    input.description = camera.info().name + " frame " + std::to_string(index) + " " + std::to_string(k.width) +
                        "x" + std::to_string(k.height) + ", gaze along the optical axis";
  }
  return input;
}

}  // namespace

Result<FrameInput> mockLivingRoom(int width, int height) {
  return grab("mock:living-room,size=" + std::to_string(width) + "x" + std::to_string(height), 0);
}

Result<FrameInput> tumFrame(const std::string& path, int index) {
#ifdef FOVEA_HAVE_PNG
  if (index < 0) return Status(ErrorCode::kInvalidArgument, "--frame: must be >= 0");
  return grab("tum:" + path + ",loop=off,frames=" + std::to_string(index + 1), index);
#else
  (void)path;
  (void)index;
  return Status(ErrorCode::kNotFound, "TUM input: this build has no TUM backend (libpng was not found)");
#endif
}

double trueDepthAt(const hal::RgbdFrame& truth, double u, double v) {
  const int u0 = static_cast<int>(std::floor(u)), v0 = static_cast<int>(std::floor(v));
  if (u0 < 0 || v0 < 0 || u0 + 1 >= truth.width() || v0 + 1 >= truth.height()) return std::nan("");
  double z[4];
  for (int j = 0; j < 4; ++j) {
    const uint16_t raw = truth.depth()[static_cast<std::size_t>(v0 + j / 2) * truth.width() + u0 + j % 2];
    if (raw == 0) return std::nan("");
    z[j] = raw * truth.depth_scale_m;
  }
  const auto [lo, hi] = std::minmax({z[0], z[1], z[2], z[3]});
  if (hi - lo > 0.05 * lo) return std::nan("");
  const double fu = u - u0, fv = v - v0;
  return (z[0] * (1 - fu) + z[1] * fu) * (1 - fv) + (z[2] * (1 - fu) + z[3] * fu) * fv;
}

std::string option(int argc, char** argv, const char* name, const char* fallback) {
  for (int i = 1; i + 1 < argc; ++i) {
    if (std::strcmp(argv[i], name) == 0) return argv[i + 1];
  }
  return fallback;
}

}  // namespace fovea::bench
