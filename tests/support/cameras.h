// A camera for a test, opened and started: one place for the tests that read
// frames from a backend (the mock, a TUM recording) outside the service.
#pragma once

#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "hal/camera.h"

namespace fovea::test {

// A camera opened and started, or null with the reason added as a failure.
inline std::unique_ptr<hal::Camera> startedCamera(const std::string& spec) {
  Result<std::unique_ptr<hal::Camera>> camera = hal::createCamera(spec);
  if (!camera.isOk()) {
    ADD_FAILURE() << spec << ": " << camera.status().toString();
    return nullptr;
  }
  Status s = camera.value()->open();
  if (s.isOk()) s = camera.value()->start();
  if (!s.isOk()) {
    ADD_FAILURE() << spec << ": " << s.toString();
    return nullptr;
  }
  return std::move(camera.value());
}

}  // namespace fovea::test
