#include "hal/camera.h"

#include <string>

#include "hal/backend_table.h"
#include "hal/camera/mock/mock_camera.h"
#ifdef FOVEA_HAVE_PNG
#include "hal/camera/tum/tum_camera.h"
#endif

namespace fovea::hal {

namespace {

const Backend<Camera> kBackends[] = {
    {"mock", &mock::MockCamera::create, &mock::mockCameraHelp},
#ifdef FOVEA_HAVE_PNG
    {"tum", &tum::TumCamera::create, &tum::tumCameraHelp},
#endif
};

}  // namespace

Result<std::unique_ptr<Camera>> createCamera(std::string_view spec) {
  return createFromSpec<Camera>(kBackends, "camera", spec, " (spec: backend:name[,key=value...])");
}

std::string cameraSpecHelp() { return backendsHelp<Camera>(kBackends); }

std::vector<std::string_view> cameraBackendNames() { return backendNames<Camera>(kBackends); }

}  // namespace fovea::hal
