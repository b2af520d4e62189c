// Test doubles for the service (firmware/service.h): a mock GPIO chip the test
// can read and drive while the service runs, a camera that stalls on demand,
// and a fake systemd NOTIFY_SOCKET.
#pragma once

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/result.h"
#include "firmware/service.h"
#include "firmware/service_config.h"
#include "hal/camera.h"
#include "hal/gpio.h"
#include "hal/gpio/mock/mock_gpio.h"
#include "tests/support/test_time.h"

namespace fovea::test {

// The mock chip behind a mutex: the service's supervisor drives it while the
// test reads events and flips inputs (MockGpio itself is single-threaded).
class LockedGpio final : public hal::Gpio {
 public:
  const std::string& name() const override { return mock_.name(); }
  unsigned lineCount() const override { return mock_.lineCount(); }
  Status requestOutput(unsigned offset, std::string_view consumer, bool initial_value) override {
    std::lock_guard<std::mutex> lock(mutex_);
    return mock_.requestOutput(offset, consumer, initial_value);
  }
  Status requestInput(unsigned offset, std::string_view consumer) override {
    std::lock_guard<std::mutex> lock(mutex_);
    return mock_.requestInput(offset, consumer);
  }
  bool set(unsigned offset, bool value) override {
    std::lock_guard<std::mutex> lock(mutex_);
    return mock_.set(offset, value);
  }
  bool get(unsigned offset, bool& value) override {
    std::lock_guard<std::mutex> lock(mutex_);
    return mock_.get(offset, value);
  }
  void releaseAll() override {
    std::lock_guard<std::mutex> lock(mutex_);
    mock_.releaseAll();
  }
  hal::GpioCounters counters() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    return mock_.counters();
  }

  void setInput(unsigned offset, bool value) {
    std::lock_guard<std::mutex> lock(mutex_);
    mock_.setInput(offset, value);
  }
  std::size_t changesOf(unsigned offset) const {
    std::lock_guard<std::mutex> lock(mutex_);
    return mock_.eventsOf(offset).size();
  }
  bool value(unsigned offset) const {
    std::lock_guard<std::mutex> lock(mutex_);
    return mock_.value(offset);
  }

 private:
  mutable std::mutex mutex_;
  hal::mock::MockGpio mock_{8};
};

// A camera that delegates to another until told to stall; then acquire() waits
// out its timeout and reports kUnavailable, as a camera that stopped delivering.
// Told to blind, it delivers frames without a valid depth pixel (a lens covered:
// what a tracker cannot track).
class StallableCamera final : public hal::Camera {
 public:
  explicit StallableCamera(std::unique_ptr<hal::Camera> inner) : inner_(std::move(inner)) {}
  Status open() override { return inner_->open(); }
  Status start() override { return inner_->start(); }
  Status acquire(hal::RgbdFrame& slot, std::chrono::nanoseconds timeout) override {
    if (stalled_.load()) {
      std::this_thread::sleep_for(std::min<std::chrono::nanoseconds>(timeout, std::chrono::milliseconds(20)));
      return {ErrorCode::kUnavailable, "stalled (test)"};
    }
    const Status s = inner_->acquire(slot, timeout);
    if (s && blind_.load()) std::fill(slot.depth(), slot.depth() + slot.pixelCount(), uint16_t{0});
    return s;
  }
  void stop() override { inner_->stop(); }
  const hal::CameraInfo& info() const override { return inner_->info(); }
  hal::CameraCounters counters() const override { return inner_->counters(); }

  void stall(bool on) { stalled_.store(on); }
  void blind(bool on) { blind_.store(on); }

 private:
  std::unique_ptr<hal::Camera> inner_;
  std::atomic<bool> stalled_{false};
  std::atomic<bool> blind_{false};
};

// A unix datagram socket bound where NOTIFY_SOCKET points, as systemd's.
class FakeNotifySocket {
 public:
  explicit FakeNotifySocket(std::string path) : path_(std::move(path)) {
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path_.c_str(), sizeof addr.sun_path - 1);
    unlink(path_.c_str());
    bound_ = fd_ >= 0 && bind(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) == 0;
  }
  ~FakeNotifySocket() {
    if (fd_ >= 0) close(fd_);
    unlink(path_.c_str());
  }
  bool bound() const { return bound_; }
  const std::string& path() const { return path_; }
  // Every message waiting, and those arriving within wait_ms.
  std::vector<std::string> receive(int wait_ms) {
    std::vector<std::string> out;
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(wait_ms);
    for (;;) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now());
      timeval tv{0, static_cast<suseconds_t>(std::max<int64_t>(1, left.count()) * 1000)};
      setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
      char buffer[2048];
      const ssize_t n = recv(fd_, buffer, sizeof buffer, 0);
      if (n >= 0) {
        out.emplace_back(buffer, static_cast<std::size_t>(n));
      } else if (std::chrono::steady_clock::now() >= end) {
        break;
      }
    }
    return out;
  }
  // Messages until done(messages) holds or a wait for `expected` ends, scaled and
  // with test::waitUntil's margin: for what must come, even on a loaded machine,
  // where a fixed window may hold too few.
  template <class Predicate>
  std::vector<std::string> receiveUntil(Predicate&& done, std::chrono::milliseconds expected) {
    std::vector<std::string> out;
    const auto end = std::chrono::steady_clock::now() + kWaitMargin * scaled(expected);
    while (!done(out) && std::chrono::steady_clock::now() < end) {
      for (std::string& m : receive(20)) out.push_back(std::move(m));
    }
    return out;
  }

 private:
  std::string path_;
  int fd_ = -1;
  bool bound_ = false;
};

// A small, fast service configuration for tests: mock camera at 160x120,
// mock GPIO lines heartbeat 0, streaming 1, fault 2, privacy input 3.
inline firmware::ServiceConfig smallServiceConfig(double fps = 60.0) {
  firmware::ServiceConfig config;
  config.camera.spec = "mock:living-room,size=160x120,realtime=on,fps=" + std::to_string(fps);
  config.pipeline.max_points = 160 * 120;
  config.pipeline.max_voxels = 160 * 120;
  // Scaled: under qemu on a loaded machine a 300 ms gap between frames happens
  // without any stall, and its fault would race the tests' checks of the lines.
  config.camera.stall_timeout_ms = static_cast<int64_t>(300 * timeScale());
  config.gpio.lines.heartbeat_line = 0;
  config.gpio.lines.streaming_line = 1;
  config.gpio.lines.fault_line = 2;
  config.gpio.lines.privacy_line = 3;
  config.gpio.lines.heartbeat_period_ns = 50'000'000;
  config.runtime.status_interval_ms = 200;
  config.stream.link.listen.clear();  // no stream unless a test asks
  return config;
}

// A created and started service whose run() supervises in a thread. Stops and
// joins on destruction, so a failed ASSERT that returns early leaves no thread
// running (std::thread's destructor would terminate the test binary).
struct RunningService {
  std::unique_ptr<firmware::Service> service;
  std::thread supervisor;

  RunningService() = default;
  RunningService(const RunningService&) = delete;
  RunningService& operator=(const RunningService&) = delete;
  ~RunningService() { stop(); }

  // Creates and starts the service; the status says why not.
  Status start(const firmware::ServiceConfig& config, firmware::Service::Environment environment) {
    Result<std::unique_ptr<firmware::Service>> created = firmware::Service::create(config, std::move(environment));
    if (!created) return created.status();
    service = std::move(created.value());
    if (Status s = service->start(); !s) return s;
    supervisor = std::thread([this] { service->run(); });
    return Status::ok();
  }
  void stop() {
    if (!service) return;
    service->requestStop();
    if (supervisor.joinable()) supervisor.join();
  }
};

}  // namespace fovea::test
