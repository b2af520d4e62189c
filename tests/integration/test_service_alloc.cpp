// The service's fixed-memory promise, in-process with a counting allocator
// (this binary replaces malloc): after warm-up, 300 frames through all three
// stage threads and the supervisor allocate nothing, streaming or not; and the
// resident set stays flat over 1000 frames.
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <thread>

#include <gtest/gtest.h>

#include "firmware/sanitizer.h"

#include "firmware/service.h"
#include "net/operator_link.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/service_doubles.h"
#include "tests/support/test_time.h"

namespace fovea::firmware {
namespace {

using namespace std::chrono_literals;

// Waits (without allocating) until the service has foveated `frames` frames;
// the timeout scales under emulators and sanitizers (tests/support/test_time.h).
bool waitForFrames(const Service& service, uint64_t frames, std::chrono::seconds timeout) {
  return test::waitUntil([&] { return service.stats().frames_foveated >= frames; }, timeout);
}

TEST(ServiceAllocation, CounterSeesOtherThreads) {
  test::AllocationScope scope;
  std::thread t([] {
    void* volatile p = std::malloc(16);
    std::free(p);
  });
  t.join();
  EXPECT_GE(scope.allocations(), 2u);  // the thread's own start-up and the malloc
}

ServiceConfig allocConfig() {
  ServiceConfig config = test::smallServiceConfig(200.0);
  config.runtime.status_interval_ms = 100;  // the status line is formatted during the count too
  return config;
}

TEST(ServiceAllocation, ThreeHundredFramesAfterWarmUpWithoutStreaming) {
  Service::Environment environment;
  environment.gpio = std::make_unique<hal::mock::MockGpio>(8);
  ServiceConfig config = allocConfig();
  // The recording mock chip grows its event list: no output lines here, the
  // privacy input still read every few milliseconds.
  config.gpio.lines.heartbeat_line = config.gpio.lines.streaming_line = config.gpio.lines.fault_line =
      StatusLinesConfig::kNoLine;
  test::RunningService running;  // stops the service on every way out of the test
  const Status started = running.start(config, std::move(environment));
  ASSERT_TRUE(started.isOk()) << started.toString();
  Service& service = *running.service;
  ASSERT_TRUE(waitForFrames(service, 30, 10s));  // warm-up

  uint64_t allocations = 0, frames = 0;
  {
    test::AllocationScope scope;
    const uint64_t start = service.stats().frames_foveated;
    const bool ok = waitForFrames(service, start + 300, 20s);
    frames = service.stats().frames_foveated - start;
    allocations = scope.allocations();
    EXPECT_TRUE(ok);
  }
  running.stop();
  std::printf("steady state: %llu frames, %llu heap allocations\n", static_cast<unsigned long long>(frames),
              static_cast<unsigned long long>(allocations));
  EXPECT_GE(frames, 300u);
  EXPECT_EQ(allocations, 0u);
  EXPECT_GE(service.stats().status_lines, 1u);
}

TEST(ServiceAllocation, ThreeHundredFramesAfterWarmUpStreamingToAnOperator) {
  ServiceConfig config = allocConfig();
  config.gpio.lines.heartbeat_line = config.gpio.lines.streaming_line = config.gpio.lines.fault_line =
      StatusLinesConfig::kNoLine;
  config.camera.spec = "mock:living-room,size=160x120,realtime=on,fps=100";
  config.stream.link.listen = "127.0.0.1:0";
  config.stream.link.insecure = true;
  Service::Environment environment;
  environment.gpio = std::make_unique<hal::mock::MockGpio>(8);
  test::RunningService running;  // stops the service on every way out of the test
  const Status started = running.start(config, std::move(environment));
  ASSERT_TRUE(started.isOk()) << started.toString();
  Service& service = *running.service;

  net::OperatorLinkConfig op_config;
  op_config.insecure = true;
  Result<std::unique_ptr<net::OperatorLink>> op = net::OperatorLink::connect(service.localEndpoint().toString(), op_config);
  ASSERT_TRUE(op.isOk()) << op.status().toString();
  // The operator (its own allocations are not the service's: it runs before
  // and after the count, and during it only sends and receives into fixed buffers).
  std::atomic<bool> stop{false};
  std::thread operator_thread([&] {
    auto next = std::chrono::steady_clock::now();
    while (!stop.load()) {
      if (std::chrono::steady_clock::now() >= next) {
        net::GazeSample g;
        g.gaze_origin_m = {3.0, 0.35, 1.55};
        g.gaze_direction = {0.6, 0.8, 0.0};
        (void)op.value()->sendGaze(g);
        next += 10ms;
      }
      (void)op.value()->receive(2);
    }
  });
  struct JoinOnExit {  // a failed ASSERT below must not leave the thread joinable
    std::atomic<bool>& stop;
    std::thread& thread;
    ~JoinOnExit() {
      stop.store(true);
      if (thread.joinable()) thread.join();
    }
  } join_operator{stop, operator_thread};
  ASSERT_TRUE(waitForFrames(service, 50, 10s));  // warm-up: the session's encoder is made here
  ASSERT_GT(service.stats().frames_sent, 0u);

  uint64_t allocations = 0, frames = 0, sent = 0;
  {
    test::AllocationScope scope;
    const ServiceStats start = service.stats();
    EXPECT_TRUE(waitForFrames(service, start.frames_foveated + 300, 20s));
    const ServiceStats end = service.stats();
    frames = end.frames_foveated - start.frames_foveated;
    sent = end.frames_sent - start.frames_sent;
    allocations = scope.allocations();
  }
  stop.store(true);
  operator_thread.join();
  running.stop();
  std::printf("steady state streaming: %llu frames, %llu sent, %llu heap allocations\n",
              static_cast<unsigned long long>(frames), static_cast<unsigned long long>(sent),
              static_cast<unsigned long long>(allocations));
  EXPECT_GE(sent, 250u);
  EXPECT_EQ(allocations, 0u);
}

long residentPages() {
  std::ifstream statm("/proc/self/statm");
  long size = 0, resident = 0;
  statm >> size >> resident;
  return resident;
}

TEST(ServiceMemory, ResidentSetStaysFlatOverAThousandFrames) {
#ifdef FOVEA_THREAD_SANITIZER
  GTEST_SKIP() << "not under ThreadSanitizer: its shadow memory and tables grow with what the process touches "
                  "(firmware/sanitizer.h), and 1100 frames take minutes there";
#endif
  Service::Environment environment;
  environment.gpio = std::make_unique<hal::mock::MockGpio>(8);
  ServiceConfig config = allocConfig();
  config.gpio.lines.heartbeat_line = config.gpio.lines.streaming_line = config.gpio.lines.fault_line =
      StatusLinesConfig::kNoLine;
  config.camera.spec = "mock:living-room,size=160x120,realtime=on,fps=250";
  test::RunningService running;  // stops the service on every way out of the test
  const Status started = running.start(config, std::move(environment));
  ASSERT_TRUE(started.isOk()) << started.toString();
  Service& service = *running.service;
  ASSERT_TRUE(waitForFrames(service, 100, 10s));  // warm-up
  const long before = residentPages();
  ASSERT_TRUE(waitForFrames(service, 1100, 30s));
  const long after = residentPages();
  running.stop();
  const long page_kib = sysconf(_SC_PAGESIZE) / 1024;
  std::printf("resident set: %ld KiB after warm-up, %ld KiB after 1000 more frames\n", before * page_kib,
              after * page_kib);
  EXPECT_LE((after - before) * page_kib, 256) << "the resident set grew by more than 256 KiB";
}

}  // namespace
}  // namespace fovea::firmware
