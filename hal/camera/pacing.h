// Pacing a synthetic or recorded camera at its own rate (realtime=on): the mock
// and TUM cameras wait for a frame's due time, and time out, the same way.
#pragma once

#include <chrono>
#include <thread>

#include "core/result.h"
#include "hal/camera.h"

namespace fovea::hal {

// Sleeps until `due` (`now`: the clock read the caller decided with). A frame
// due later than `timeout` allows is a counted timeout, after sleeping out the
// timeout as a real device's wait would. The message fits std::string's small
// buffer: no allocation on this path.
inline Status waitForFrameDue(std::chrono::steady_clock::time_point due, std::chrono::steady_clock::time_point now,
                              std::chrono::nanoseconds timeout, CameraCounterSet& counters) {
  if (due <= now) return Status::ok();
  if (due - now > timeout) {
    std::this_thread::sleep_for(timeout);
    counters.timeout();
    return Status(ErrorCode::kUnavailable, "timeout");
  }
  std::this_thread::sleep_until(due);
  return Status::ok();
}

}  // namespace fovea::hal
