#include "hal/camera.h"

#include <string>

#include "hal/backend_table.h"
#include "hal/camera/mock/mock_camera.h"
#ifdef FOVEA_HAVE_PNG
#include "hal/camera/tum/tum_camera.h"
#endif
#ifdef FOVEA_HAVE_OPENNI2
#include "hal/camera/openni2/openni2_camera.h"
#endif
#ifdef FOVEA_HAVE_V4L2
#include "hal/camera/v4l2/v4l2_camera.h"
#endif
#ifdef FOVEA_HAVE_LIBCAMERA
#include "hal/camera/libcamera/libcamera_camera.h"
#endif

namespace fovea::hal {

namespace {

const Backend<Camera> kBackends[] = {
    {"mock", &mock::MockCamera::create, &mock::mockCameraHelp, nullptr},
#ifdef FOVEA_HAVE_PNG
    {"tum", &tum::TumCamera::create, &tum::tumCameraHelp, nullptr},
#endif
#ifdef FOVEA_HAVE_OPENNI2
    {"openni2", &openni2::OpenNI2Camera::create, &openni2::openni2CameraHelp, &openni2::discoverOpenNI2Cameras},
#endif
#ifdef FOVEA_HAVE_V4L2
    {"v4l2", &v4l2::V4l2Camera::create, &v4l2::v4l2CameraHelp, &v4l2::discoverV4l2Cameras},
#endif
#ifdef FOVEA_HAVE_LIBCAMERA
    {"libcamera", [](std::string_view args) { return libcam::LibcameraCamera::create(args, &createCamera); },
     &libcam::libcameraCameraHelp, &libcam::discoverLibcameraCameras},
#endif
};

// Every backend fovea has, and what a build without it lacked.
struct KnownBackend {
  std::string_view name;
  std::string_view why_not;
};
const KnownBackend kKnownBackends[] = {
    {"mock", ""},
    {"tum", "libpng was not found when fovea was configured (apt-get install libpng-dev, then configure again)"},
    {"openni2", "OpenNI2 was not found when fovea was configured (apt-get install libopenni2-dev, then configure again)"},
    {"v4l2", "the V4L2 headers and libv4l2 were not found when fovea was configured (apt-get install libv4l-dev, then "
             "configure again)"},
    {"libcamera", "libcamera was not found when fovea was configured (apt-get install libcamera-dev, then configure "
                  "again)"},
};

}  // namespace

Result<std::unique_ptr<Camera>> createCamera(std::string_view spec) {
  std::string hint = " (spec: backend:name[,key=value...])";
  const std::string_view name = spec.substr(0, spec.find(':'));
  for (const KnownBackend& known : kKnownBackends) {
    bool compiled = false;
    for (const Backend<Camera>& backend : kBackends) compiled = compiled || backend.name == known.name;
    if (known.name == name && !compiled) hint = "; this build has no " + std::string(name) + " backend: " + std::string(known.why_not);
  }
  return createFromSpec<Camera>(kBackends, "camera", spec, hint);
}

std::string cameraSpecHelp() { return backendsHelp<Camera>(kBackends); }

std::vector<std::string_view> cameraBackendNames() { return backendNames<Camera>(kBackends); }

std::vector<CameraBackendStatus> cameraBackendStatus() {
  std::vector<CameraBackendStatus> status;
  for (const KnownBackend& known : kKnownBackends) {
    bool compiled = false;
    for (const Backend<Camera>& backend : kBackends) compiled = compiled || backend.name == known.name;
    status.push_back({known.name, compiled, compiled ? std::string_view() : known.why_not});
  }
  return status;
}

std::vector<CameraDiscovery> discoverCameras() {
  std::vector<CameraDiscovery> found;
  for (const Backend<Camera>& backend : kBackends) {
    if (backend.discover != nullptr) found.push_back({backend.name, backend.discover()});
  }
  return found;
}

}  // namespace fovea::hal
