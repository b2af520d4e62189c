#include "hal/camera.h"

#include <string>

#include "hal/camera/mock/mock_camera.h"
#ifdef FOVEA_HAVE_PNG
#include "hal/camera/tum/tum_camera.h"
#endif

namespace fovea::hal {

namespace {

// The backends compiled in, one line each. Explicit on purpose: a static
// self-registration would be dropped by the linker from a static library.
struct Backend {
  std::string_view name;
  // args: the spec after "name:" ("" when there is no ':').
  Result<std::unique_ptr<Camera>> (*create)(std::string_view args);
  std::string (*help)();
};

const Backend kBackends[] = {
    {"mock", &mock::MockCamera::create, &mock::mockCameraHelp},
#ifdef FOVEA_HAVE_PNG
    {"tum", &tum::TumCamera::create, &tum::tumCameraHelp},
#endif
};

std::string backendNames() {
  std::string names;
  for (const Backend& backend : kBackends) {
    if (!names.empty()) names += '|';
    names += backend.name;
  }
  return names;
}

}  // namespace

Result<std::unique_ptr<Camera>> createCamera(std::string_view spec) {
  const std::size_t colon = spec.find(':');
  const std::string_view name = spec.substr(0, colon);
  const std::string_view args =
      colon == std::string_view::npos ? std::string_view() : spec.substr(colon + 1);
  for (const Backend& backend : kBackends) {
    if (backend.name == name) return backend.create(args);
  }
  return Result<std::unique_ptr<Camera>>(
      ErrorCode::kInvalidArgument, "camera: unknown backend '" + std::string(name) + "' in '" +
                                       std::string(spec) + "'; accepted: " + backendNames() +
                                       " (spec: backend:name[,key=value...])");
}

std::string cameraSpecHelp() {
  std::string help;
  for (const Backend& backend : kBackends) {
    help += backend.help();
    help += '\n';
  }
  return help;
}

}  // namespace fovea::hal
