// The camera interface every backend implements (mock, TUM recordings, OpenNI2,
// V4L2, libcamera). Errors are values; acquire() never allocates or throws.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"
#include "hal/backend_table.h"
#include "hal/calibration.h"
#include "hal/frame.h"

namespace fovea::hal {

struct CameraInfo {
  std::string name;              // e.g. "mock:living-room"
  std::string model;             // what the device says it is ("Orbbec Astra"); "" when unknown
  std::string serial;            // "" when unknown
  CameraIntrinsics intrinsics;   // of the depth image, which colour is registered to
  double depth_scale_m = 0.001;
  double fps = 30.0;
  // A world point of interest the backend knows, e.g. the centre of a mock
  // scene; demos aim the gaze at it. Empty for real cameras.
  std::optional<Eigen::Vector3d> focus_point_m;
  // Memory the backend holds outside the heap for the whole run (V4L2 mmap
  // streaming buffers, say); the service adds it to its memory budget.
  std::size_t device_buffer_bytes = 0;
};

// Named counters instead of per-event logging; the supervisor reports them.
struct CameraCounters {
  uint64_t frames_delivered = 0;
  uint64_t timeouts = 0;
  uint64_t errors = 0;            // failed acquire() calls other than timeouts
  uint64_t stalls = 0;            // episodes of no frames (each also counts its timeouts)
  uint64_t disconnects = 0;       // the device went away (acquire() -> kNotFound)
  uint64_t bad_frames = 0;        // frames rejected as malformed (wrong size), not delivered
  uint64_t injected_garbage = 0;  // mock only: delivered frames of deliberate garbage
};

// What a backend counts as it runs: bumped on the thread that calls acquire(),
// read by the supervisor on another. Every backend holds one of these.
class CameraCounterSet {
 public:
  void frameDelivered() { frames_delivered_.fetch_add(1, std::memory_order_relaxed); }
  void timeout() { timeouts_.fetch_add(1, std::memory_order_relaxed); }
  void error() { errors_.fetch_add(1, std::memory_order_relaxed); }
  void stall() { stalls_.fetch_add(1, std::memory_order_relaxed); }
  void disconnect() { disconnects_.fetch_add(1, std::memory_order_relaxed); }
  void badFrame() { bad_frames_.fetch_add(1, std::memory_order_relaxed); }
  void injectedGarbage() { injected_garbage_.fetch_add(1, std::memory_order_relaxed); }
  CameraCounters snapshot() const {
    CameraCounters c;
    c.frames_delivered = frames_delivered_.load(std::memory_order_relaxed);
    c.timeouts = timeouts_.load(std::memory_order_relaxed);
    c.errors = errors_.load(std::memory_order_relaxed);
    c.stalls = stalls_.load(std::memory_order_relaxed);
    c.disconnects = disconnects_.load(std::memory_order_relaxed);
    c.bad_frames = bad_frames_.load(std::memory_order_relaxed);
    c.injected_garbage = injected_garbage_.load(std::memory_order_relaxed);
    return c;
  }

 private:
  std::atomic<uint64_t> frames_delivered_{0};
  std::atomic<uint64_t> timeouts_{0};
  std::atomic<uint64_t> errors_{0};
  std::atomic<uint64_t> stalls_{0};
  std::atomic<uint64_t> disconnects_{0};
  std::atomic<uint64_t> bad_frames_{0};
  std::atomic<uint64_t> injected_garbage_{0};
};

class Camera {
 public:
  virtual ~Camera() = default;

  // Probes the device and prepares buffers; may allocate. Clear error when absent.
  virtual Status open() = 0;
  virtual Status start() = 0;
  // Fills the caller's slot with the next frame (size, intrinsics, pose, stamp).
  // kUnavailable on timeout or when not started; kCapacityExceeded when the slot
  // is smaller than the frame; kNotFound when the device has gone away (stop,
  // open and start again to reconnect); kInvalidInput when the device handed over
  // a malformed frame (nothing is written, the next frame may be fine). Never
  // allocates.
  virtual Status acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) = 0;
  virtual void stop() = 0;

  // Resets the device on its bus (a USB port reset) so that the reopen that
  // follows finds it fresh; hal::CaptureRetry calls it before reopening a camera
  // whose stream stalled. kUnavailable, and nothing done, when the backend has
  // no such reset; kNotFound when the device is gone.
  virtual Status resetDevice() { return {ErrorCode::kUnavailable, "this camera has no device reset"}; }

  // Calibration from the board profile or a calibration file, used from the
  // next open(): what it sets overrides what the device reports, what it leaves
  // unset comes from the device. kInvalidArgument when the backend cannot use
  // it (a recording or a mock knows its own calibration exactly).
  virtual Status setCalibration(const CameraCalibration& calibration) {
    return {ErrorCode::kInvalidArgument, "camera " + info().name + " takes no external calibration (from " +
                                             calibration.source + ")"};
  }

  virtual const CameraInfo& info() const = 0;
  virtual CameraCounters counters() const = 0;
};

// Creates a camera from a spec "backend:name[,key=value...]", e.g.
// "mock:living-room,seed=7,path=orbit,size=640x480,fps=30". The backends compiled
// in are listed in one table in camera.cpp (no static self-registration).
Result<std::unique_ptr<Camera>> createCamera(std::string_view spec);

// One line per backend and its options, for --help.
std::string cameraSpecHelp();

// The names of the backends compiled in ("mock", "tum"...), in table order.
std::vector<std::string_view> cameraBackendNames();

// Every camera backend fovea knows, compiled in or not, for `fovead cameras`.
struct CameraBackendStatus {
  std::string_view name;
  bool compiled = false;
  std::string_view why_not;  // when not compiled: what was missing at build time and how to get it
};
std::vector<CameraBackendStatus> cameraBackendStatus();

// The devices each compiled backend that can enumerate sees now, backend by
// backend (a backend whose enumeration failed gives its error, not a list).
struct CameraDiscovery {
  std::string_view backend;
  Result<std::vector<DeviceListing>> devices;
};
std::vector<CameraDiscovery> discoverCameras();

}  // namespace fovea::hal
