// fovead cameras: what a new user runs after plugging a camera in. Lists every
// camera the compiled backends see now, with the spec to paste into --camera or
// camera.spec, and says which backends this build has and why a missing one is
// missing. Finding no camera is an answer, not a failure: exit 0.
#include <cstdio>
#include <string>

#include "firmware/commands.h"
#include "hal/camera.h"

namespace fovea::firmware {

namespace {

const char* kCamerasHelp =
    "usage: fovead cameras\n"
    "\n"
    "Lists the cameras this build's backends can see now: the spec to pass to\n"
    "--camera (or camera.spec in a configuration file), the model, the serial and\n"
    "the modes; then which camera backends are compiled in, and for each missing one\n"
    "what its build lacked. Exits 0 whether or not a camera is found.\n";

void printListing(const hal::DeviceListing& device) {
  std::printf("  %s\n", device.spec.c_str());
  std::string about = device.model.empty() ? std::string("unknown model") : device.model;
  if (!device.serial.empty()) about += ", serial " + device.serial;
  if (!device.detail.empty()) about += ", " + device.detail;
  std::printf("      %s\n", about.c_str());
  for (const std::string& mode : device.modes) std::printf("      %s\n", mode.c_str());
}

}  // namespace

int camerasCommand(int argc, char** argv) {
  if (argc == 3 && (std::string(argv[2]) == "--help" || std::string(argv[2]) == "-h")) {
    std::fputs(kCamerasHelp, stdout);
    return kExitOk;
  }
  if (argc != 2) {
    std::fprintf(stderr, "fovead cameras: unexpected argument '%s' (see --help)\n", argv[2]);
    return kExitUsage;
  }

  std::size_t found = 0;
  for (const hal::CameraDiscovery& backend : hal::discoverCameras()) {
    const std::string name(backend.backend);
    if (!backend.devices) {
      std::printf("%s: cannot list cameras: %s\n", name.c_str(), backend.devices.status().message().c_str());
      continue;
    }
    const auto& devices = backend.devices.value();
    if (devices.empty()) {
      std::printf("%s: no camera found\n", name.c_str());
      continue;
    }
    std::printf("%s: %zu camera%s\n", name.c_str(), devices.size(), devices.size() == 1 ? "" : "s");
    for (const hal::DeviceListing& device : devices) printListing(device);
    found += devices.size();
  }

  std::printf("\nbackends:");
  for (const hal::CameraBackendStatus& backend : hal::cameraBackendStatus()) {
    if (backend.compiled) std::printf(" %.*s", static_cast<int>(backend.name.size()), backend.name.data());
  }
  std::printf(" (compiled in)\n");
  for (const hal::CameraBackendStatus& backend : hal::cameraBackendStatus()) {
    if (!backend.compiled) {
      std::printf("  %.*s: not compiled in: %.*s\n", static_cast<int>(backend.name.size()), backend.name.data(),
                  static_cast<int>(backend.why_not.size()), backend.why_not.data());
    }
  }
  if (found == 0) {
    std::printf(
        "\nNo camera found. Plug the camera in (USB 3 for depth cameras) and run this again;\n"
        "if `lsusb` lists it but nothing here does, see README.md, \"Use a real camera\"\n"
        "(permissions: the udev rule fovea installs). Without a camera, the mock camera\n"
        "always works: fovead serve --camera mock:living-room\n");
  }
  return kExitOk;
}

}  // namespace fovea::firmware
