// The mock scene the map benchmarks run on: its spec and the camera with its
// noiseless twin.
#include "bench/mock_scene.h"

#include <cstdio>

#include "bench/bench_input.h"

namespace fovea::bench {

std::string mockSceneSpec(int argc, char** argv, const char* default_path) {
  const std::string scene = option(argc, argv, "--scene", "living-room");
  const std::string path = option(argc, argv, "--path", default_path);
  const std::string size = option(argc, argv, "--size", "640x480");
  return "mock:" + scene + ",path=" + path + ",size=" + size;
}

int openMockTwins(const char* program, const std::string& spec, MockTwins& twins) {
  auto noisy = hal::createCamera(spec);
  auto truth = hal::createCamera(spec + ",noise=off");  // the same path, noiseless: the true surface
  if (!noisy || !truth) {
    std::fprintf(stderr, "%s: %s\n", program, (noisy ? truth.status() : noisy.status()).message().c_str());
    return 2;
  }
  twins.noisy = std::move(noisy.value());
  twins.truth = std::move(truth.value());
  hal::Camera& a = *twins.noisy;
  hal::Camera& b = *twins.truth;
  if (!a.open() || !a.start() || !b.open() || !b.start()) {
    std::fprintf(stderr, "%s: the mock camera did not start\n", program);
    return 1;
  }
  return 0;
}

}  // namespace fovea::bench
