// The mock scene the map benchmarks run on (fovea-map-delta, fovea-map-link,
// fovea-map-accuracy): its camera spec from --scene, --path and --size, and the
// camera with its noiseless twin, which gives the true surface. One place, so
// that the programs read the same options the same way.
#pragma once

#include <memory>
#include <string>

#include "hal/camera.h"

namespace fovea::bench {

// "mock:SCENE,path=PATH,size=WxH" from --scene (default living-room), --path
// (default `default_path`) and --size (default 640x480).
std::string mockSceneSpec(int argc, char** argv, const char* default_path);

// The mock camera of a spec and its noiseless twin (the same spec with
// noise=off: the same path and poses), both open and started.
struct MockTwins {
  std::unique_ptr<hal::Camera> noisy;
  std::unique_ptr<hal::Camera> truth;
};

// Creates, opens and starts both cameras. Returns 0, or the exit status after
// printing "<program>: why" to stderr: 2 when the spec is refused, 1 when a
// camera did not start.
int openMockTwins(const char* program, const std::string& spec, MockTwins& twins);

}  // namespace fovea::bench
