// What toolchain/lsan.supp's OpenNI2 line lets through (the test openni2.leaks,
// ASan tree only: tests/unit/hal/CMakeLists.txt). It opens OpenNI2's Dummy
// device with fovea's camera, so fovea's OpenNI2 runtime is the one in use
// (it keeps the drivers loaded under ASan) and its streams start and stop,
// then it does what a bug in fovea could:
//
//   openni2_leak_probe clean    a stream created and destroyed: no report, exit 0
//   openni2_leak_probe forget   a stream created and never destroyed (its handle
//                               dropped): LeakSanitizer must report it, through
//                               libOpenNI2.so, and fail the process
//
// The old suppression (leak:libOpenNI2.so, with the slow unwinder) hid the second.
#include <OpenNI.h>

#include <cstdio>
#include <cstring>
#include <memory>

#include "hal/camera.h"
#include "hal/camera/openni2/openni2_camera.h"

int main(int argc, char** argv) {
  const bool forget = argc == 2 && std::strcmp(argv[1], "forget") == 0;
  if (argc != 2 || (!forget && std::strcmp(argv[1], "clean") != 0)) {
    std::fprintf(stderr, "usage: openni2_leak_probe clean|forget\n");
    return 2;
  }
  fovea::Result<std::unique_ptr<fovea::hal::Camera>> created = fovea::hal::openni2::OpenNI2Camera::create("Dummy");
  std::unique_ptr<fovea::hal::Camera> camera = created.isOk() ? std::move(created).value() : nullptr;
  if (camera == nullptr || !camera->open().isOk() || !camera->start().isOk()) {
    std::fprintf(stderr, "openni2_leak_probe: cannot start OpenNI2's Dummy device through fovea\n");
    return 2;
  }
  camera->stop();  // start() and stop() leak inside libOpenNI2: suppressed, by name
  {
    openni::Device device;
    if (device.open("Dummy") != openni::STATUS_OK) {
      std::fprintf(stderr, "openni2_leak_probe: a second handle on the Dummy: %s\n", openni::OpenNI::getExtendedError());
      return 2;
    }
    OniStreamHandle stream = nullptr;
    if (oniDeviceCreateStream(device._getHandle(), ONI_SENSOR_DEPTH, &stream) != ONI_STATUS_OK) {
      std::fprintf(stderr, "openni2_leak_probe: no depth stream: %s\n", openni::OpenNI::getExtendedError());
      return 2;
    }
    if (!forget) oniStreamDestroy(stream);
    stream = nullptr;  // forget: the only handle gone, the stream never destroyed
    device.close();
  }
  camera.reset();  // the last user of fovea's OpenNI2 runtime: it shuts down here
  // stderr, unbuffered: LeakSanitizer aborts the process before stdout would be flushed.
  std::fprintf(stderr, "openni2_leak_probe: %s: done; leaks are reported at exit\n", forget ? "forget" : "clean");
  return 0;
}
