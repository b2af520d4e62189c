// The service in-process: stage threads on the mock camera, status lines on a
// mock GPIO chip (heartbeat, fault, streaming, privacy pause), an in-test
// operator over loopback, reloads, and systemd notifications on a fake
// NOTIFY_SOCKET (READY, WATCHDOG, and no WATCHDOG while the camera stalls).
#include "firmware/service.h"
#include "hal/usb/usb_devices.h"

#include <stdlib.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/sanitizer.h"
#include "firmware/config.h"
#include "net/operator_link.h"
#include "net/udp_socket.h"
#include "tests/support/process.h"
#include "tests/support/service_doubles.h"
#include "tests/support/test_time.h"
#include "tests/unit/firmware/log_sinks.h"

namespace fovea::firmware {
namespace {

using namespace std::chrono_literals;

using test::RunningService;
using test::waitUntil;  // its timeouts scale under emulators and sanitizers (tests/support/test_time.h)

void startService(RunningService& running, const ServiceConfig& config, Service::Environment environment) {
  const Status started = running.start(config, std::move(environment));
  ASSERT_TRUE(started.isOk()) << started.toString();
}

using test::RecordingSink;

TEST(Service, RefusedThreadPlacementIsLoggedAndTheServiceRunsOn) {
  RecordingSink sink;
  Logger logger(sink);
  ServiceConfig config = test::smallServiceConfig();
  config.runtime.capture_thread.core = 4095;  // no such core
  Service::Environment environment;
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_foveated >= 5; }, 5000ms));
  EXPECT_TRUE(sink.contains("fovea-capture: pinning to core 4095 refused")) << "no warning logged";
  EXPECT_TRUE(sink.contains("memory: "));
}

// The USB hot-plug monitor: the service says at start whether it watches the
// known RGB-D cameras (on this host: libusb with hot-plug, no camera), and its
// status line carries the counts.
TEST(Service, UsbHotplugIsWatchedAndCountedInTheStatusLine) {
  RecordingSink sink;
  Logger logger(sink);
  ServiceConfig config = test::smallServiceConfig();
  config.runtime.status_interval_ms = 50;
  Service::Environment environment;
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return sink.contains("status: fps in "); }, 5000ms));
  const hal::usb::UsbMonitorCounters usb = running.service->stats().usb;
  if (hal::usb::usbHotplugSupported().isOk() && usb.available) {
    EXPECT_TRUE(sink.contains("usb: watching arrivals and removals of "));
    EXPECT_TRUE(sink.contains("| usb arrived ")) << "status line without the usb counts";
  } else {
    EXPECT_TRUE(sink.contains("usb: hot-plug of RGB-D cameras not watched: "));
    EXPECT_TRUE(sink.contains("| usb off"));
  }
  running.stop();
  EXPECT_FALSE(running.service->stats().usb.available);  // stopped with the service
}

TEST(Service, MemoryBudgetCountsEveryPool) {
  ServiceConfig config = test::smallServiceConfig();
  config.runtime.ring_depth = 3;
  Result<std::unique_ptr<Service>> created = Service::create(config, {});
  ASSERT_TRUE(created.isOk()) << created.status().toString();
  const MemoryBudget& memory = created.value()->memory();
  EXPECT_GE(memory.pools.size(), 5u);
  // ring_depth + 2 frame slots, each at least the RGB-D frame's pixels.
  EXPECT_EQ(memory.pools[1].count, 5u);
  EXPECT_GE(memory.pools[1].bytes, 5u * 160 * 120 * 5);
  EXPECT_NE(memory.summary().find("memory: "), std::string::npos);
  EXPECT_NE(memory.summary().find(" MiB in "), std::string::npos);
  EXPECT_NE(memory.breakdown().find("frame slots"), std::string::npos);
}

// The service with the most pools (the map with bricks, tracking, a stream and
// a timing log) lists every one of them, the last ones too (a table of 12 once
// dropped the streamer's and the status lines' without a word), and its total
// is what the heap grew by while the service was made, less the little that
// is no pool's (the configuration's copies, the logger's strings).
TEST(Service, MemoryBudgetListsEveryPoolAndTheHeapsGrowth) {
  ServiceConfig config = test::smallServiceConfig(30.0);
  config.map.source = FoveationSource::kMap;
  config.map.map.max_surfels = 1u << 16;
  config.camera.pose.source = "track";
  config.stream.link.listen = "127.0.0.1:0";
  config.stream.link.insecure = true;
  const test::TempDir dir;
  config.runtime.timing_log = dir.file("timing.tsv");
  ASSERT_TRUE(validate(config).isOk()) << validate(config).toString();
  const std::size_t before = heapInUse();
  Result<std::unique_ptr<Service>> created = Service::create(config, {});
  const std::size_t grown = heapGrowthSince(before);
  ASSERT_TRUE(created.isOk()) << created.status().toString();
  const MemoryBudget& memory = created.value()->memory();
  const std::string breakdown = memory.breakdown();
  for (const char* name : {"camera backend", "frame slots", "foveated cloud slots", "map: a frame's bricks",
                           "map: surfel pool", "map: tracker", "map: bricks the operator holds", "point cloud", "foveator",
                           "streamer", "status, latency histograms", "timing log buffer"}) {
    EXPECT_NE(breakdown.find(name), std::string::npos) << "no pool named " << name << " in\n" << breakdown;
  }
  EXPECT_GT(memory.pools.size(), 12u);
  EXPECT_NE(memory.summary().find(" in " + std::to_string(memory.pools.size()) + " pools"), std::string::npos);
  EXPECT_LE(memory.totalBytes(), grown + grown / 50) << breakdown;
  EXPECT_GE(memory.totalBytes(), grown - grown / 20) << "heap grew by " << grown << " bytes; the pools:\n" << breakdown;
}

// pipeline.max_output_points sizes the foveated slots (not the pixels), and a
// frame that needs more voxels than pipeline.max_voxels, even after
// pipeline.max_coarsenings doublings of its voxels (none here), is dropped and
// counted, never a crash; the status line says how many.
TEST(Service, OutputCapacityIsConfiguredAndAnOverflowIsCountedNotACrash) {
  RecordingSink sink;
  Logger logger(sink);
  ServiceConfig config = test::smallServiceConfig();
  config.runtime.status_interval_ms = 50;
  config.max_output_points = 4000;
  config.pipeline.max_voxels = 10;  // the mock room at 160x120 takes hundreds
  config.pipeline.max_coarsenings = 0;
  Service::Environment environment;
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  const MemoryBudget& memory = running.service->memory();
  // Pool 2: the foveated cloud slots, 4000 points of 21 bytes each (not 160x120).
  EXPECT_NE(std::string(memory.pools[2].name).find("foveated cloud slots"), std::string::npos);
  EXPECT_LT(memory.pools[2].bytes, memory.pools[2].count * 4000u * 32u);
  EXPECT_GE(memory.pools[2].bytes, memory.pools[2].count * 4000u * 16u);
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_over_capacity >= 3; }, 5000ms));
  ASSERT_TRUE(waitUntil([&] { return sink.contains(" over capacity "); }, 5000ms)) << "status line without the count";
  EXPECT_TRUE(waitUntil([&] { return sink.contains("pipeline.max_voxels 10"); }, 5000ms))
      << "no warning (the foveation thread warns after it counts)";
  running.stop();
  const ServiceStats end = running.service->stats();
  EXPECT_EQ(end.frames_foveated, 0u);
  EXPECT_EQ(end.frames_over_capacity, end.foveate_errors);
}

// With its default pipeline.max_coarsenings, a frame over max_voxels goes out
// with its periphery's voxels doubled until it fits: counted, not dropped.
TEST(Service, AFrameOverTheVoxelsIsFoveatedCoarserAndCounted) {
  RecordingSink sink;
  Logger logger(sink);
  ServiceConfig config = test::smallServiceConfig();
  config.runtime.status_interval_ms = 50;
  // The mock room at 160x120 takes more than 2000 at the fallback's 5 cm voxels
  // (no operator here); 400 fit once they are doubled.
  config.pipeline.max_voxels = 400;
  Service::Environment environment;
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_coarsened >= 3; }, 5000ms))
      << running.service->stats().frames_foveated << " foveated, " << running.service->stats().frames_over_capacity
      << " over capacity";
  ASSERT_TRUE(waitUntil([&] { return sink.contains(" coarsened "); }, 5000ms)) << "status line without the count";
  running.stop();
  const ServiceStats end = running.service->stats();
  EXPECT_EQ(end.frames_over_capacity, 0u);
  EXPECT_EQ(end.foveate_errors, 0u);
  EXPECT_EQ(end.frames_coarsened, end.frames_foveated) << "every frame of the static room needs it";
}

// With the map's bricks a frame carries the points the map does not explain
// yet, so map.max_live_points caps both the foveated slots' points and the
// sampler's voxels (below pipeline.max_output_points and max_voxels); a frame
// over it (the map's first frames explain nothing) is dropped and counted, and
// the warning says which key sized it. 0 is an eighth of the pixels.
TEST(Service, TheMapsLivePointsCapTheFramesCapacityAndTheWarningNamesIt) {
  EXPECT_EQ(liveFramePoints(0, 640u * 480u), 38400u);
  EXPECT_EQ(liveFramePoints(1234, 640u * 480u), 1234u);
  EXPECT_EQ(liveFramePoints(0, 3), 1u);
  RecordingSink sink;
  Logger logger(sink);
  ServiceConfig config = test::smallServiceConfig(30.0);
  config.map.source = FoveationSource::kMap;
  config.map.map.max_surfels = 1u << 14;
  config.max_output_points = 4000;
  config.pipeline.max_voxels = 3000;
  config.map.max_live_points = 300;  // the room at 160x120 takes thousands of voxels while the map is new
  config.pipeline.max_coarsenings = 0;
  ASSERT_TRUE(validate(config).isOk()) << validate(config).toString();
  config.runtime.status_interval_ms = 50;
  Service::Environment environment;
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_over_capacity >= 1; }, 5000ms));
  ASSERT_TRUE(waitUntil([&] { return sink.contains(" over capacity "); }, 5000ms)) << "status line without the count";
  // The foveation thread warns after it counts: the status line may say so first.
  EXPECT_TRUE(waitUntil([&] {
    return sink.contains("pipeline.max_voxels 300, pipeline.max_output_points 300, both at most "
                         "map.max_live_points with the map's bricks");
  }, 5000ms));
  running.stop();
}

// With the map's bricks the cloud before foveation holds twice the live
// points (kLiveCandidatesPerOutput), not the pixels: the map's first frames,
// which it explains nothing of, are thinned outside the eye's cone to fit,
// counted and said in the stop line, and foveated, not dropped.
TEST(Service, TheMapsFirstFramesAreThinnedIntoTheirCloudNotDropped) {
  RecordingSink sink;
  Logger logger(sink);
  ServiceConfig config = test::smallServiceConfig(30.0);
  config.map.source = FoveationSource::kMap;
  config.map.map.max_surfels = 1u << 14;
  ASSERT_TRUE(validate(config).isOk()) << validate(config).toString();
  Service::Environment environment;
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_foveated >= 5; }, 5000ms));
  running.stop();
  const ServiceStats end = running.service->stats();
  EXPECT_GT(end.map.live_thinned, 0u) << "160x120 has 19 200 pixels, the cloud 4 800 points";
  EXPECT_EQ(end.frames_over_capacity, 0u);
  EXPECT_TRUE(sink.matches("map: [1-9][0-9]* frames' live points thinned to fit their cloud"));
}

// A full brick table drops the new surfels outside its bricks: counted in the
// status line and the stop line, and said once as a warning (the map no longer
// grows into new places), never a crash.
TEST(Service, AFullBrickTableIsCountedAndSaidOnce) {
  RecordingSink sink;
  Logger logger(sink);
  ServiceConfig config = test::smallServiceConfig(30.0);
  config.map.source = FoveationSource::kMap;
  config.map.map.max_surfels = 1u << 14;
  config.map.map.max_bricks = 2;
  config.map.map.brick_size_m = 0.1;  // the room's view spans hundreds
  ASSERT_TRUE(validate(config).isOk()) << validate(config).toString();
  config.runtime.status_interval_ms = 50;  // below what validate() allows, as the other tests here
  Service::Environment environment;
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().map.frames_fused >= 3; }, 5000ms));
  ASSERT_TRUE(waitUntil([&] { return sink.matches("evicted [0-9]+, dropped [1-9][0-9]*, refused"); }, 5000ms))
      << "status line without the dropped surfels";
  running.stop();
  const ServiceStats end = running.service->stats();
  EXPECT_GT(end.map.dropped_no_brick, 0u);
  EXPECT_EQ(end.map.dropped_no_brick, end.map.dropped) << "the pool had room";
  EXPECT_EQ(sink.countOf("map: the brick table is full (map.max_bricks = 2)"), 1u);
  EXPECT_TRUE(sink.matches("new surfels dropped \\([1-9][0-9]* for want of a brick\\)"));
}

TEST(Service, RejectsABadConfigurationNamingTheField) {
  ServiceConfig config = test::smallServiceConfig();
  config.runtime.ring_depth = 0;
  Result<std::unique_ptr<Service>> created = Service::create(config, {});
  ASSERT_FALSE(created.isOk());
  EXPECT_NE(created.status().message().find("runtime.ring_depth"), std::string::npos);
  config = test::smallServiceConfig();
  config.pipeline.max_points = 100;
  created = Service::create(config, {});
  ASSERT_FALSE(created.isOk());
  EXPECT_NE(created.status().message().find("raise pipeline.max_points"), std::string::npos);
}

TEST(Service, FramesFlowThroughTheStagesAndTheHeartbeatToggles) {
  auto gpio = std::make_unique<test::LockedGpio>();
  test::LockedGpio& chip = *gpio;
  Service::Environment environment;
  environment.gpio = std::move(gpio);
  RunningService running;
  startService(running, test::smallServiceConfig(), std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_foveated >= 20; }, 5000ms));
  ASSERT_TRUE(waitUntil([&] { return chip.changesOf(0) >= 6; }, 2000ms));  // heartbeat: a toggle every 50 ms
  const ServiceStats stats = running.service->stats();
  EXPECT_GE(stats.heartbeat_toggles, 5u);
  EXPECT_FALSE(stats.fault_line);
  EXPECT_FALSE(chip.value(2));  // fault line off
  EXPECT_EQ(stats.frames_sent, 0u);
  EXPECT_GT(stats.frames_unsent, 0u);  // not streaming: the send stage takes and returns them
  running.stop();
  EXPECT_FALSE(chip.value(0));  // stop() drives the lines low
  // The stop drained the rings: every frame captured was foveated or dropped
  // (counted), every frame foveated reached the send stage or was dropped.
  const ServiceStats end = running.service->stats();
  EXPECT_EQ(end.frames_foveated + end.capture_ring.dropped + end.foveate_errors, end.frames_captured);
  EXPECT_EQ(end.frames_sent + end.frames_withheld + end.frames_unsent + end.foveation_ring.dropped,
            end.frames_foveated);
}

TEST(Service, CameraStallRaisesTheFaultAndStopsTheHeartbeat) {
  auto gpio = std::make_unique<test::LockedGpio>();
  test::LockedGpio& chip = *gpio;
  auto camera = std::make_unique<test::StallableCamera>(hal::createCamera("mock:living-room,size=160x120,realtime=on,fps=60").value());
  test::StallableCamera& cam = *camera;
  Service::Environment environment;
  environment.gpio = std::move(gpio);
  environment.camera = std::move(camera);
  RunningService running;
  startService(running, test::smallServiceConfig(), std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_foveated >= 10; }, 5000ms));
  const uint64_t errors_before = running.service->stats().capture_errors;
  cam.stall(true);
  // The fault this stall raises: a failed acquire, not a frame that came late
  // (under TSan the mock's frames sometimes do, raising and clearing the fault
  // by themselves: CI saw the heartbeat toggle once more after such a fault
  // cleared). Then a few supervisor rounds (5 ms each), so that none that read
  // the camera as healthy is still in flight.
  ASSERT_TRUE(waitUntil([&] {
    const ServiceStats s = running.service->stats();
    return s.capture_errors > errors_before && s.fault_line;
  }, 2000ms));
  std::this_thread::sleep_for(test::scaled(std::chrono::milliseconds(20)));
  EXPECT_TRUE(chip.value(2));
  const std::size_t toggles = chip.changesOf(0);
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(chip.changesOf(0), toggles);  // the heartbeat holds while stalled
  cam.stall(false);
  ASSERT_TRUE(waitUntil([&] { return !running.service->stats().fault_line; }, 2000ms));
  ASSERT_TRUE(waitUntil([&] { return chip.changesOf(0) > toggles + 2; }, 2000ms));
  EXPECT_GT(running.service->stats().capture_errors, 0u);
}

// Every injected camera fault of the mock (hal/camera/mock/faults.h), through the
// service: the fault line and the log say what happened, the capture stage
// retries with backoff and reopens the camera after the disconnect, frames flow
// again after each fault, and the service runs on.
TEST(Service, SurvivesEveryInjectedCameraFault) {
  RecordingSink sink;
  Logger logger(sink);
  auto gpio = std::make_unique<test::LockedGpio>();
  test::LockedGpio& chip = *gpio;
  ServiceConfig config = test::smallServiceConfig();
  config.camera.spec += ",fault=wrong-size@20;garbage@30:3;disconnect:400ms@45;stall:400ms@80";
  config.camera.retry_initial_ms = 20;
  config.camera.retry_max_ms = 200;
  Service::Environment environment;
  environment.gpio = std::move(gpio);
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  // 60 fps: every fault is behind us after frame 80 and the outages; 40 frames more.
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_foveated >= 120; }, 20000ms))
      << running.service->stats().frames_foveated << " frames foveated";
  const ServiceStats stats = running.service->stats();
  EXPECT_GT(stats.capture_errors, 0u);
  EXPECT_TRUE(sink.contains("capture: failing (invalid-input)")) << "the wrong-size frame";
  EXPECT_TRUE(sink.contains("capture: failing (not-found)")) << "the disconnect";
  EXPECT_TRUE(sink.contains("capture: camera reopened"));
  EXPECT_TRUE(sink.contains("capture: recovered"));
  EXPECT_TRUE(sink.contains("fault: "));
  ASSERT_TRUE(waitUntil([&] { return !running.service->stats().fault_line; }, 2000ms));
  // Logged by the supervisor just after it lowers the line.
  EXPECT_TRUE(waitUntil([&] { return sink.contains("fault cleared"); }, 1000ms));
  EXPECT_GE(chip.changesOf(2), 2u);  // the fault line rose and fell
  EXPECT_FALSE(chip.value(2));
  // Garbage frames went through the pipeline like any other.
  EXPECT_EQ(stats.foveate_errors, 0u);
}

// An operator on loopback that sends gaze at 100 Hz and drains what comes back.
struct TestOperator {
  std::unique_ptr<net::OperatorLink> link;
  std::atomic<bool> stop{false};
  std::atomic<bool> send_gaze{true};  // false: the gaze stream stops
  std::atomic<bool> silent{false};    // true: the operator vanishes (no gaze, no Bye, nothing read)
  std::atomic<float> confidence{1.0f};  // 0: a station that does not know where the eye is
  std::mutex status_mu;
  std::optional<net::StatusReport> status;  // the newest the robot sent (under status_mu)
  std::optional<net::StatusReport> lastStatus() {
    std::lock_guard lock(status_mu);
    return status;
  }
  std::atomic<uint64_t> datagrams{0};
  std::thread thread;

  bool connect(const net::Endpoint& robot) {
    net::OperatorLinkConfig config;
    config.insecure = true;
    config.connect_timeout_ms = 3000;
    Result<std::unique_ptr<net::OperatorLink>> connected = net::OperatorLink::connect(robot.toString(), config);
    if (!connected) return false;
    link = std::move(connected.value());
    thread = std::thread([this] {
      auto next = std::chrono::steady_clock::now();
      while (!stop.load()) {
        if (silent.load()) {
          std::this_thread::sleep_for(5ms);
          continue;
        }
        if (send_gaze.load() && std::chrono::steady_clock::now() >= next) {
          net::GazeSample g;
          g.gaze_origin_m = {3.0, 0.35, 1.55};
          g.gaze_direction = {0.6, 0.8, 0.0};  // unit length
          g.confidence = confidence.load();
          (void)link->sendGaze(g);
          next += 10ms;
        }
        if (const auto r = link->receive(2)) {
          datagrams.fetch_add(1);
          if (r->type == net::MessageType::kStatus) {
            std::lock_guard lock(status_mu);
            status = link->lastStatus();
          }
        }
      }
    });
    return true;
  }
  ~TestOperator() {
    stop.store(true);
    if (thread.joinable()) thread.join();
  }
};

// Resident set in KiB (/proc/self/statm's second field, in pages).
long residentKiB() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return -1;
  long size = 0, resident = 0;
  const int n = std::fscanf(f, "%ld %ld", &size, &resident);
  std::fclose(f);
  return n == 2 ? resident * (sysconf(_SC_PAGESIZE) / 1024) : -1;
}

ServiceConfig streamingConfig() {
  ServiceConfig config = test::smallServiceConfig(30.0);
  config.stream.link.listen = "127.0.0.1:0";
  config.stream.link.insecure = true;
  return config;
}

// A gaze of confidence 0 (a viewer before its first cursor sample) keeps the
// session and the stream but does not steer the fovea: the robot falls back as
// without gaze, and reports no gaze of its own; a real sample then takes over.
TEST(Service, AGazeWithoutAnEyeKeepsTheSessionButNotTheFovea) {
  RecordingSink sink;
  Logger logger(sink);
  ServiceConfig config = streamingConfig();
  // Scaled: under TSan on a loaded machine the operator's thread can be starved
  // of the 100 Hz it sends at for half a second, which would end the session.
  config.stream.link.session_timeout_ns = std::chrono::nanoseconds(test::scaled(500ms)).count();
  Service::Environment environment;
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  TestOperator op;
  op.confidence.store(0.0f);
  ASSERT_TRUE(op.connect(running.service->localEndpoint()));
  // Several session timeouts long: the session holds on confidence-0 samples.
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_sent >= 30; }, 5000ms));
  EXPECT_TRUE(running.service->stats().operator_connected);
  EXPECT_FALSE(sink.contains("gaze: operator"));
  ASSERT_TRUE(waitUntil([&] { return op.lastStatus().has_value(); }, 3000ms));
  EXPECT_FALSE(op.lastStatus()->gaze_origin_m.has_value());
  op.confidence.store(1.0f);
  ASSERT_TRUE(waitUntil([&] { return sink.contains("gaze: operator"); }, 3000ms));
  ASSERT_TRUE(waitUntil([&] { return op.lastStatus() && op.lastStatus()->gaze_direction.has_value(); }, 3000ms));
  EXPECT_EQ(op.lastStatus()->gaze_direction->y, 0.8);
  running.stop();
}

// The network side of the faults: a gaze stream that stops (the fallback takes
// over, logged once), a flood of garbage datagrams (counted, dropped), an
// operator that vanishes without a Bye (the session times out): the service
// keeps foveating and its resident set stays flat.
TEST(Service, StoppedGazeFloodAndAVanishedOperatorLeaveItRunningWithFlatMemory) {
  RecordingSink sink;
  Logger logger(sink);
  ServiceConfig config = streamingConfig();
  // Scaled as above: the service reads 20 000 junk datagrams before the gaze behind them.
  config.stream.link.session_timeout_ns = std::chrono::nanoseconds(test::scaled(500ms)).count();
  Service::Environment environment;
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  TestOperator op;
  ASSERT_TRUE(op.connect(running.service->localEndpoint()));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_sent >= 10; }, 5000ms));
  EXPECT_TRUE(sink.contains("gaze: operator"));
  const long rss_before = residentKiB();

  op.send_gaze.store(false);
  ASSERT_TRUE(waitUntil([&] { return sink.contains("gaze: stale gaze (fallback)"); }, 3000ms));

  // 20 000 datagrams of random bytes and lengths at the service's port.
  {
    const net::Endpoint robot = running.service->localEndpoint();
    Result<net::UdpSocket> flooder = net::UdpSocket::forPeer(robot);
    ASSERT_TRUE(flooder.isOk()) << flooder.status().message();
    std::mt19937 rng(5);
    std::vector<uint8_t> junk(1500);
    for (int i = 0; i < 20000; ++i) {
      const std::size_t n = std::uniform_int_distribution<std::size_t>(0, junk.size())(rng);
      for (std::size_t k = 0; k < n; ++k) junk[k] = static_cast<uint8_t>(rng());
      if (n >= 4 && i % 2 == 0) junk[0] = 'F', junk[1] = 'V', junk[2] = 1;  // half of them pass the magic
      (void)flooder->sendTo(std::span<const uint8_t>(junk.data(), n), robot);
    }
  }
  const uint64_t foveated = running.service->stats().frames_foveated;
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_foveated >= foveated + 10; }, 3000ms));

  op.silent.store(true);
  ASSERT_TRUE(waitUntil([&] { return !running.service->stats().operator_connected; }, 3000ms));
  const uint64_t after = running.service->stats().frames_foveated;
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_foveated >= after + 10; }, 3000ms));
  const long rss_after = residentKiB();
#ifdef FOVEA_THREAD_SANITIZER
  std::printf("resident set NOT checked under ThreadSanitizer (%ld KiB before, %ld KiB after): its shadow memory "
              "and tables grow with what the process touches (core/sanitizer.h)\n", rss_before, rss_after);
#else
  // Under qemu-user the resident set is qemu's, and its cache of translated
  // code grows by the paths the flood and the timeout run for the first time
  // (2 072 to 2 080 KiB there, against 8 KiB natively): twice the allowance
  // there. A leak of 100 bytes a datagram (2 MB over the flood) still shows
  // natively and under ASan.
#ifdef FOVEA_TESTS_IN_QEMU_USER
  constexpr long kFlatKiB = 4096;
#else
  constexpr long kFlatKiB = 2048;
#endif
  EXPECT_LT(rss_after - rss_before, kFlatKiB) << rss_before << " KiB before, " << rss_after << " KiB after";
#endif
  // A new operator is served after the silent one timed out.
  TestOperator next;
  ASSERT_TRUE(next.connect(running.service->localEndpoint()));
  const uint64_t sent = running.service->stats().frames_sent;
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_sent >= sent + 5; }, 5000ms));
}

TEST(Service, StreamsToAnOperatorAndThePrivacyInputPausesIt) {
  auto gpio = std::make_unique<test::LockedGpio>();
  test::LockedGpio& chip = *gpio;
  Service::Environment environment;
  environment.gpio = std::move(gpio);
  RunningService running;
  startService(running, streamingConfig(), std::move(environment));
  TestOperator op;
  ASSERT_TRUE(op.connect(running.service->localEndpoint()));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_sent >= 5; }, 5000ms));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().streaming_line; }, 2000ms));
  EXPECT_TRUE(chip.value(1));

  chip.setInput(3, true);  // privacy on
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().privacy_active; }, 1000ms));
  std::this_thread::sleep_for(test::scaled(100ms));  // a frame in flight may still go out
  const ServiceStats paused = running.service->stats();
  // Frames keep being captured and are withheld: waited for, not a fixed window,
  // since under qemu on a loaded machine 400 ms may hold fewer than the count.
  ASSERT_TRUE(waitUntil([&] {
    const ServiceStats s = running.service->stats();
    return s.frames_captured > paused.frames_captured + 5 && s.frames_withheld > paused.frames_withheld + 2;
  }, 2000ms));
  const ServiceStats later = running.service->stats();
  EXPECT_EQ(later.frames_sent, paused.frames_sent);  // nothing sent
  EXPECT_FALSE(later.streaming_line);
  EXPECT_FALSE(chip.value(1));

  chip.setInput(3, false);
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_sent > later.frames_sent + 3; }, 3000ms));
  EXPECT_GT(op.datagrams.load(), 0u);
}

TEST(Service, ReloadAppliesANewPresetBetweenFrames) {
  ServiceConfig config = test::smallServiceConfig();
  std::atomic<int> reloads{0};
  Service::Environment environment;
  environment.reloader = [&]() -> Result<ServiceConfig> {
    ++reloads;
    ServiceConfig next = test::smallServiceConfig();
    next.foveation.acuity.preset = pipeline::Preset::kF3;
    return next;
  };
  RunningService running;
  startService(running, config, std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_foveated >= 5; }, 5000ms));
  running.service->requestReload();
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().reloads_applied == 1; }, 2000ms));
  EXPECT_EQ(reloads.load(), 1);
  const uint64_t foveated = running.service->stats().frames_foveated;
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_foveated > foveated + 5; }, 2000ms));
  EXPECT_EQ(running.service->stats().foveate_errors, 0u);
}

TEST(Service, ReloadCapsTheBudgetOfTheSessionInProgress) {
  // The cap the reload brings: a quarter of what the uncapped stream carried
  // here, so that it bites at any machine's pace (under qemu on a loaded CI
  // machine the uncapped stream carried 0.29 MB/s, below a fixed 0.3 MB/s bar).
  std::atomic<uint64_t> cap_bytes_per_s{0};
  Service::Environment environment;
  environment.reloader = [&cap_bytes_per_s]() -> Result<ServiceConfig> {
    ServiceConfig next = streamingConfig();
    next.stream.link.max_budget_bytes_per_s = cap_bytes_per_s.load();
    return next;
  };
  RunningService running;
  startService(running, streamingConfig(), std::move(environment));
  TestOperator op;
  ASSERT_TRUE(op.connect(running.service->localEndpoint()));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().frames_sent >= 10; }, 5000ms));
  // Over a window long enough that a frame's burst is a small part of it (the
  // window's own length measured, as a loaded machine oversleeps).
  auto bytesPerSecond = [&] {
    const uint64_t b0 = running.service->stats().wire_bytes;
    const auto t0 = std::chrono::steady_clock::now();
    std::this_thread::sleep_for(1000ms);
    const uint64_t b1 = running.service->stats().wire_bytes;
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return static_cast<double>(b1 - b0) / seconds;
  };
  const double before = bytesPerSecond();
  ASSERT_GT(before, 40'000.0) << "the uncapped stream carried almost nothing";
  const double cap = before / 4;
  cap_bytes_per_s = static_cast<uint64_t>(cap);
  running.service->requestReload();
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().reloads_applied == 1; }, 2000ms));
  std::this_thread::sleep_for(test::scaled(200ms));  // what was paced before the cap drains
  const double after = bytesPerSecond();
  EXPECT_LT(after, 1.5 * cap) << "before " << before << " B/s, capped at " << cap << " B/s";
}

TEST(Service, ReloadFailureKeepsTheRunningConfiguration) {
  Service::Environment environment;
  environment.reloader = []() -> Result<ServiceConfig> {
    return Result<ServiceConfig>(ErrorCode::kInvalidArgument, "config.toml:3: foveation.m: must be positive");
  };
  RunningService running;
  startService(running, test::smallServiceConfig(), std::move(environment));
  running.service->requestReload();
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().reload_failures == 1; }, 2000ms));
  EXPECT_EQ(running.service->stats().reloads_applied, 0u);
}

// systemd: READY=1 after start-up, WATCHDOG=1 at half of WATCHDOG_USEC while
// frames flow, none while the camera stalls, again when it recovers.
TEST(Service, SystemdNotifyReadyWatchdogAndStall) {
  test::TempDir dir;
  test::FakeNotifySocket systemd(dir.file("notify"));
  ASSERT_TRUE(systemd.bound());
  setenv("NOTIFY_SOCKET", systemd.path().c_str(), 1);
  setenv("WATCHDOG_USEC", "200000", 1);  // keep-alives every 100 ms
  unsetenv("WATCHDOG_PID");
  auto camera = std::make_unique<test::StallableCamera>(hal::createCamera("mock:living-room,size=160x120,realtime=on,fps=60").value());
  test::StallableCamera& cam = *camera;
  Service::Environment environment;
  environment.camera = std::move(camera);
  RunningService running;
  // libsystemd's sd_notify reads NOTIFY_SOCKET at each call: it stays set until the service stops.
  startService(running, test::smallServiceConfig(), std::move(environment));

  auto count = [](const std::vector<std::string>& messages, auto is) {
    std::size_t n = 0;
    for (const std::string& m : messages) n += is(m);
    return n;
  };
  auto isWatchdog = [](const std::string& m) { return m == "WATCHDOG=1"; };
  auto isStatus = [](const std::string& m) { return m.rfind("STATUS=status: fps in ", 0) == 0; };
  std::vector<std::string> messages = systemd.receiveUntil([&](const std::vector<std::string>& got) {
    return count(got, isWatchdog) >= 3 && count(got, isStatus) >= 1;
  }, 600ms);
  ASSERT_FALSE(messages.empty());
  EXPECT_EQ(messages.front(), "READY=1");
  EXPECT_GE(count(messages, isWatchdog), 3u);
  EXPECT_GE(count(messages, isStatus), 1u);

  cam.stall(true);
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().fault_line; }, 2000ms));
  (void)systemd.receive(10);  // what was sent before the stall was seen
  messages = systemd.receive(500);  // a window: none may come in it
  EXPECT_EQ(count(messages, isWatchdog), 0u) << "keep-alives must stop while the pipeline stalls";

  cam.stall(false);
  messages = systemd.receiveUntil([&](const std::vector<std::string>& got) { return count(got, isWatchdog) >= 2; },
                                  600ms);
  EXPECT_GE(count(messages, isWatchdog), 2u);

  running.stop();
  unsetenv("NOTIFY_SOCKET");
  unsetenv("WATCHDOG_USEC");
  messages = systemd.receive(50);
  bool stopping = false;
  for (const std::string& m : messages) stopping = stopping || m == "STOPPING=1";
  EXPECT_TRUE(stopping);
}

// A pose datagram to the service's pose socket (docs/pose.md), as a robot would.
void sendPose(const std::string& path, int64_t stamp_ns, double x) {
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un to{};
  to.sun_family = AF_UNIX;
  std::snprintf(to.sun_path, sizeof to.sun_path, "%s", path.c_str());
  char text[96];
  const int n = std::snprintf(text, sizeof text, "%lld %.3f 0 0 0 0 0 1\n", static_cast<long long>(stamp_ns), x);
  EXPECT_EQ(::sendto(fd, text, static_cast<std::size_t>(n), MSG_DONTWAIT, reinterpret_cast<const sockaddr*>(&to),
                     sizeof to),
            n)
      << std::strerror(errno);
  ::close(fd);
}

// The pose socket through the service: frames posed while poses cover their
// stamps (the mock's clock starts at 0), a stale pose raises the fault line and
// says so in the log and the status line, fresh poses clear it; the watchdog
// (healthy) is not what a stale pose stops.
TEST(Service, PoseSocketPosesFramesAndAStalePoseRaisesTheFault) {
  test::TempDir dir;
  RecordingSink sink;
  Logger logger(sink);
  auto gpio = std::make_unique<test::LockedGpio>();
  test::LockedGpio& chip = *gpio;
  ServiceConfig config = test::smallServiceConfig();
  config.camera.pose.source = "socket";
  config.camera.pose.socket = dir.file("pose.sock");
  config.camera.pose.max_age_ms = 100;
  Service::Environment environment;
  environment.gpio = std::move(gpio);
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  EXPECT_TRUE(sink.contains("pose: socket " + config.camera.pose.socket));
  // No pose yet: stale.
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().fault_line; }, 3000ms));
  EXPECT_TRUE(chip.value(2));
  // The supervisor logs the transition just after it stores the line's state.
  EXPECT_TRUE(waitUntil([&] { return sink.contains("fault: the pose is stale"); }, 1000ms));
  // Poses spanning every stamp the mock will give in this test: fresh.
  sendPose(config.camera.pose.socket, 0, 0.0);
  sendPose(config.camera.pose.socket, 1'000'000'000'000, 1000.0);
  ASSERT_TRUE(waitUntil([&] { return !running.service->stats().fault_line; }, 3000ms));
  EXPECT_TRUE(waitUntil([&] { return sink.contains("pose fresh again"); }, 1000ms));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().pose.frames_fresh >= 5; }, 3000ms));
  ASSERT_TRUE(waitUntil([&] { return sink.contains("| pose fresh, "); }, 3000ms));
  const ServiceStats stats = running.service->stats();
  EXPECT_EQ(stats.pose.received, 2u);
  EXPECT_GT(stats.pose.frames_stale, 0u);
  EXPECT_FALSE(stats.pose_stale);
  running.stop();
}

// camera.pose.source = track: the map tracks the camera with no outside pose;
// a covered lens (no valid depth) loses the track: frames are not fused, the
// status line says "pose LOST", the fault line rises; the view's return is
// tracked again against the map and the fault clears.
TEST(Service, TrackedPoseLostOnACoveredLensRaisesTheFaultAndRecovers) {
  RecordingSink sink;
  Logger logger(sink);
  auto gpio = std::make_unique<test::LockedGpio>();
  test::LockedGpio& chip = *gpio;
  // Natively only: under qemu and the sanitizers the stage takes too few of the
  // real-time frames (CI under qemu beside three other stages: fewer than 10
  // tracked in 150 s). The tracker itself runs there in test_tracker,
  // test_tracker_hard_cases and test_zero_alloc; this is the service's wiring.
  if (test::timeScale() > 1.0) GTEST_SKIP() << "the service tracking a camera: natively only (too slow here)";
  const std::string spec = "mock:living-room,size=160x120,realtime=on,fps=30,path=orbit";
  auto camera = std::make_unique<test::StallableCamera>(hal::createCamera(spec).value());
  test::StallableCamera& cam = *camera;
  ServiceConfig config = test::smallServiceConfig(30.0);
  config.camera.spec = spec;
  config.map.source = FoveationSource::kMap;
  config.map.delta = false;
  config.map.map.max_surfels = 1u << 16;
  config.camera.pose.source = "track";
  ASSERT_TRUE(validate(config).isOk()) << validate(config).toString();
  Service::Environment environment;
  environment.gpio = std::move(gpio);
  environment.camera = std::move(camera);
  environment.logger = &logger;
  RunningService running;
  startService(running, config, std::move(environment));
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().tracking.tracked >= 10; }, 5000ms));
  // Fusion, on its own thread, may be a frame or two behind on a loaded machine.
  EXPECT_TRUE(waitUntil([&] { return running.service->stats().map.frames_fused >= 9; }, 3000ms));
  ServiceStats stats = running.service->stats();
  EXPECT_TRUE(stats.tracking.enabled);
  EXPECT_EQ(stats.tracking.lost_frames, 0u);
  ASSERT_TRUE(waitUntil([&] { return sink.contains("| pose tracked, track "); }, 3000ms));
  // The model's build after a fused frame, beside it (not zero: frames were fused).
  // ... and the share of pixels found moving: next to none in the static room.
  EXPECT_TRUE(sink.matches(" ms, model (0\\.[1-9]|[1-9][0-9]*\\.[0-9]) ms, moving 0\\.[0-9] %, lost "));
  EXPECT_LT(stats.tracking.moving_share, 0.01);
  EXPECT_FALSE(chip.value(2));

  cam.blind(true);
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().fault_line; }, 3000ms));
  EXPECT_TRUE(waitUntil([&] { return sink.contains("fault: pose LOST (tracking: "); }, 1000ms));
  ASSERT_TRUE(waitUntil([&] { return sink.contains("| pose LOST,"); }, 3000ms));
  stats = running.service->stats();
  EXPECT_TRUE(stats.tracking.lost);
  EXPECT_GT(stats.tracking.lost_frames, 0u);
  EXPECT_TRUE(chip.value(2));
  const uint64_t fused = stats.map.frames_fused;
  const uint64_t lost = stats.tracking.lost_frames;
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().tracking.lost_frames >= lost + 3; }, 3000ms));
  EXPECT_LE(running.service->stats().map.frames_fused, fused + 1);  // a frame in flight at most: lost ones are not fused

  cam.blind(false);
  ASSERT_TRUE(waitUntil([&] { return !running.service->stats().tracking.lost; }, 3000ms));
  ASSERT_TRUE(waitUntil([&] { return !running.service->stats().fault_line; }, 3000ms));
  EXPECT_TRUE(waitUntil([&] { return sink.contains("pose tracked again"); }, 1000ms));
  EXPECT_GT(running.service->stats().tracking.relocalised, 0u);
  const uint64_t fused_again = running.service->stats().map.frames_fused;
  ASSERT_TRUE(waitUntil([&] { return running.service->stats().map.frames_fused >= fused_again + 5; }, 3000ms));
  running.stop();
}

// The nice value of the thread named `name` in this process; nullopt if none.
std::optional<int> threadNice(const std::string& name) {
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream comm(task.path() / "comm");
    std::string line;
    if (!std::getline(comm, line) || line != name) continue;
    errno = 0;
    const int nice = ::getpriority(PRIO_PROCESS, static_cast<id_t>(std::stoi(task.path().filename().string())));
    if (errno == 0) return nice;
  }
  return std::nullopt;
}

// runtime.*_thread.nice is added to the process's for that thread: the map's
// fusion yields a busy core to the stages (the host profile's 10), the stages
// keep the process's.
TEST(Service, AThreadsNiceValueIsAddedToTheProcesss) {
  errno = 0;
  const int base = ::getpriority(PRIO_PROCESS, 0);
  ASSERT_EQ(errno, 0);
  if (base > 12) GTEST_SKIP() << "the test runs at nice " << base << ": no room for 7 more";
  ServiceConfig config = test::smallServiceConfig(30.0);
  config.map.source = FoveationSource::kMap;
  config.map.map.max_surfels = 1u << 14;
  config.runtime.map_thread.nice = 7;
  ASSERT_TRUE(config.map.fusion_thread);
  RunningService running;
  startService(running, config, {});
  ASSERT_TRUE(waitUntil([&] { return threadNice("fovea-map").has_value(); }, 5000ms)) << "no fovea-map thread";
  // A thread names itself first and sets its nice value next: wait for both.
  EXPECT_TRUE(waitUntil([&] { return threadNice("fovea-map") == base + 7; }, 2000ms)) << *threadNice("fovea-map");
  for (const char* stage : {"fovea-capture", "fovea-foveate", "fovea-send"}) {
    ASSERT_TRUE(waitUntil([&] { return threadNice(stage).has_value(); }, 2000ms)) << stage;
    EXPECT_EQ(threadNice(stage), base) << stage;
  }
  running.stop();

  config.runtime.map_thread.nice = 20;
  EXPECT_FALSE(Service::create(config, {}).isOk());
}

// Tracking needs the map: a configuration that asks for it without says so.
TEST(Service, TrackingWithoutTheMapIsAConfigurationError) {
  ServiceConfig config = test::smallServiceConfig();
  config.camera.pose.source = "track";
  const Status s = validate(config);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("foveation.source = \"map\""), std::string::npos) << s.message();
  config.camera.pose.source = "track+socket";
  config.map.source = FoveationSource::kMap;
  config.camera.pose.socket.clear();
  EXPECT_NE(validate(config).message().find("camera.pose.socket"), std::string::npos) << validate(config).message();
  config.camera.pose.source = "track+gps";
  EXPECT_NE(validate(config).message().find("track+socket"), std::string::npos) << validate(config).message();
}

TEST(Service, ACameraThatTakesNoCalibrationWithOneConfiguredIsAStartUpError) {
  test::TempDir dir;
  const std::string path = dir.file("cal.yaml");
  std::FILE* f = std::fopen(path.c_str(), "w");
  std::fputs("colour: {image_width: 160, image_height: 120, camera_matrix: [100, 0, 80, 0, 100, 60, 0, 0, 1]}\n", f);
  std::fclose(f);
  ServiceConfig config = test::smallServiceConfig();
  config.camera.calibration_file = path;
  Result<std::unique_ptr<Service>> created = Service::create(config, {});
  ASSERT_FALSE(created.isOk());
  EXPECT_NE(created.status().message().find("takes no external calibration (from " + path + ")"), std::string::npos)
      << created.status().message();
  config.camera.calibration_file = dir.file("missing.yaml");
  created = Service::create(config, {});
  ASSERT_FALSE(created.isOk());
  EXPECT_EQ(created.status().code(), ErrorCode::kNotFound);
  EXPECT_NE(created.status().message().find("camera.calibration_file: calibration file"), std::string::npos);
}

}  // namespace
}  // namespace fovea::firmware
