// The capture retry helper (hal/capture_retry.h) against the mock camera's
// injected faults, on a ManualClock shared by the camera and the test, so every
// time below is exact and a 2 s stall runs instantly. The allocator of this
// binary is the counting one (tests/support/alloc_counter.h).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "hal/camera.h"
#include "hal/camera/mock/faults.h"
#include "hal/camera/mock/mock_camera.h"
#include "hal/capture_retry.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "tests/support/alloc_counter.h"

namespace fovea::hal {
namespace {

constexpr int64_t kMs = 1'000'000;
constexpr int64_t kFramePeriodNs = 33 * kMs;  // the test's consumer takes a frame every 33 ms

// A camera, the helper and a slot on one ManualClock; run() plays the capture
// stage's loop: step, sleep until next_ns when told to wait, spend a frame
// period on each frame.
struct Rig {
  explicit Rig(const std::string& args, const CaptureRetryConfig& config) : config_(config) {
    Result<mock::MockCameraOptions> options = mock::parseMockCameraOptions(args);
    EXPECT_TRUE(options.isOk()) << options.status().toString();
    camera = std::make_unique<mock::MockCamera>(std::move(options).value());
    camera->setClock(&clock);
    EXPECT_TRUE(camera->open().isOk());
    EXPECT_TRUE(camera->start().isOk());
    slot = RgbdFrame(camera->info().intrinsics.width, camera->info().intrinsics.height);
    retry = std::make_unique<CaptureRetry>(*camera, config_);
  }

  struct Record {
    int64_t t_ns;
    CaptureStep step;
    uint64_t sequence;  // the slot's, after a frame
    bool faulted;
  };

  // Steps until `frames` frames have arrived (or max_steps); records what each
  // step did (not kWait) when `record`.
  void run(uint64_t frames, bool record = true, int max_steps = 100000) {
    const uint64_t target = retry->stats().frames + frames;
    for (int i = 0; i < max_steps && retry->stats().frames < target; ++i) {
      const int64_t now = clock.nowNs();
      const CaptureStep step = retry->step(now, slot);
      if (step.action == CaptureAction::kWait) {
        clock.setNs(step.next_ns);
        continue;
      }
      if (record) log.push_back({now, step, slot.sequence, retry->faulted()});
      if (step.action == CaptureAction::kFrame) clock.advanceNs(kFramePeriodNs);
    }
  }

  std::vector<Record> ofAction(CaptureAction action) const {
    std::vector<Record> out;
    for (const Record& r : log) {
      if (r.step.action == action) out.push_back(r);
    }
    return out;
  }
  std::vector<Record> ofEvent(CaptureEvent event) const {
    std::vector<Record> out;
    for (const Record& r : log) {
      if (r.step.event == event) out.push_back(r);
    }
    return out;
  }
  // The sequence numbers of the frames delivered, in order.
  std::vector<uint64_t> sequences() const {
    std::vector<uint64_t> out;
    for (const Record& r : ofAction(CaptureAction::kFrame)) out.push_back(r.sequence);
    return out;
  }

  CaptureRetryConfig config_;
  mock::ManualClock clock{0};
  std::unique_ptr<mock::MockCamera> camera;
  RgbdFrame slot;
  std::unique_ptr<CaptureRetry> retry;
  std::vector<Record> log;
};

std::vector<uint64_t> iota(uint64_t first, uint64_t end) {
  std::vector<uint64_t> out;
  for (uint64_t s = first; s < end; ++s) out.push_back(s);
  return out;
}

TEST(CaptureRetryConfig, ValidateNamesTheField) {
  EXPECT_TRUE(CaptureRetryConfig{}.validate().isOk());
  CaptureRetryConfig c;
  c.initial_backoff_ns = 0;
  EXPECT_NE(c.validate().message().find("initial_backoff_ns"), std::string::npos);
  c = {};
  c.max_backoff_ns = c.initial_backoff_ns - 1;
  EXPECT_NE(c.validate().message().find("max_backoff_ns"), std::string::npos);
  c = {};
  c.reopen_after_failures = 0;
  EXPECT_NE(c.validate().message().find("reopen_after_failures"), std::string::npos);
  c = {};
  c.acquire_timeout = std::chrono::nanoseconds(-1);
  EXPECT_EQ(c.validate().code(), ErrorCode::kInvalidArgument);
}

TEST(CaptureRetry, HealthyCameraDeliversEveryFrameWithoutEvents) {
  Rig rig("living-room,size=64x48", {});
  rig.run(10);
  EXPECT_EQ(rig.sequences(), iota(0, 10));
  EXPECT_TRUE(rig.ofEvent(CaptureEvent::kFailing).empty());
  EXPECT_FALSE(rig.retry->faulted());
  EXPECT_EQ(rig.clock.nowNs(), 10 * kFramePeriodNs);
}

// A 2 s stall from frame 30, acquire timeout 100 ms, backoff 10 ms doubling to
// 1 s, reopen after 5 failures. The stall starts at T = 30 x 33 ms; each failed
// acquire blocks 100 ms; the backoff counts from each failing step's start:
//   T      fail 1 (-> T+100), next T+10       T+560  reopen (the stall goes on)
//   T+100  fail 2, next T+120                 T+560  fail 1 (-> T+660), next T+880
//   T+200  fail 3, next T+240                 T+880  fail 2 (-> T+980), next T+1520
//   T+300  fail 4, next T+380                 T+1520 fail 3 (-> T+1620), next T+2520
//   T+400  fail 5 (-> T+500), next T+560      T+2520 frame 30: recovered
TEST(CaptureRetry, StallRaisesTheFaultFlagUntilFramesResumeWithoutAReopenStorm) {
  CaptureRetryConfig config;
  config.acquire_timeout = std::chrono::milliseconds(100);
  config.initial_backoff_ns = 10 * kMs;
  config.max_backoff_ns = 1000 * kMs;
  config.reopen_after_failures = 5;
  Rig rig("living-room,size=64x48,fault=stall:2s@30", config);
  rig.run(60);
  const int64_t t = 30 * kFramePeriodNs;

  EXPECT_EQ(rig.sequences(), iota(0, 60));  // nothing lost (realtime=off)
  const auto failing = rig.ofEvent(CaptureEvent::kFailing);
  const auto recovered = rig.ofEvent(CaptureEvent::kRecovered);
  ASSERT_EQ(failing.size(), 1u);
  ASSERT_EQ(recovered.size(), 1u);
  EXPECT_EQ(failing[0].t_ns, t);
  EXPECT_EQ(failing[0].step.error, ErrorCode::kUnavailable);
  EXPECT_EQ(recovered[0].t_ns, t + 2520 * kMs);
  EXPECT_EQ(recovered[0].sequence, 30u);

  std::vector<int64_t> failure_times;
  for (const auto& r : rig.ofAction(CaptureAction::kAcquireFailed)) failure_times.push_back(r.t_ns - t);
  const std::vector<int64_t> expected = {0, 100 * kMs, 200 * kMs, 300 * kMs, 400 * kMs,
                                         560 * kMs, 880 * kMs, 1520 * kMs};
  EXPECT_EQ(failure_times, expected);
  const auto reopens = rig.ofAction(CaptureAction::kReopened);
  ASSERT_EQ(reopens.size(), 1u);
  EXPECT_EQ(reopens[0].t_ns, t + 560 * kMs);

  // The fault flag: up exactly from the first failure to the recovery.
  for (const auto& r : rig.log) {
    const bool in_stall = r.t_ns >= t && r.t_ns < t + 2520 * kMs;
    EXPECT_EQ(r.faulted, in_stall) << "at " << r.t_ns;
  }
  EXPECT_FALSE(rig.retry->faulted());
  const CaptureRetryStats& s = rig.retry->stats();
  EXPECT_EQ(s.timeouts, 8u);
  EXPECT_EQ(s.reopen_attempts, 1u);
  EXPECT_EQ(s.recoveries, 1u);
  // The reopen after the stall tried a device reset first; the mock has none.
  EXPECT_EQ(s.reset_attempts, 1u);
  EXPECT_EQ(s.resets_unsupported, 1u);
  EXPECT_EQ(s.resets, 0u);
  const CameraCounters c = rig.camera->counters();
  EXPECT_EQ(c.stalls, 1u);
  EXPECT_EQ(c.timeouts, 8u);
  EXPECT_EQ(rig.retry->backoffNs(), config.initial_backoff_ns);  // reset by the frame
}

// Disconnected for 1.5 s from frame 60 (T = 60 x 33 ms): reopen attempts at
// T + 100, 300, 700 (backoff 100 ms doubling, capped at 800 ms) fail while the
// device is gone; the one at T + 1500 succeeds and frame 60 follows at once.
TEST(CaptureRetry, DisconnectReopensWithExactBackoffAndRecovers) {
  CaptureRetryConfig config;
  config.initial_backoff_ns = 100 * kMs;
  config.max_backoff_ns = 800 * kMs;
  config.reopen_after_failures = 5;
  Rig rig("living-room,size=64x48,fault=disconnect:1.5s@60", config);
  rig.run(90);
  const int64_t t = 60 * kFramePeriodNs;

  EXPECT_EQ(rig.sequences(), iota(0, 90));
  const auto failed = rig.ofAction(CaptureAction::kAcquireFailed);
  ASSERT_EQ(failed.size(), 1u);
  EXPECT_EQ(failed[0].t_ns, t);
  EXPECT_EQ(failed[0].step.error, ErrorCode::kNotFound);
  EXPECT_EQ(failed[0].step.event, CaptureEvent::kFailing);
  EXPECT_EQ(failed[0].step.next_ns, t + 100 * kMs);

  std::vector<int64_t> attempts;
  for (const auto& r : rig.log) {
    if (r.step.action == CaptureAction::kReopenFailed || r.step.action == CaptureAction::kReopened) {
      attempts.push_back(r.t_ns - t);
    }
  }
  EXPECT_EQ(attempts, (std::vector<int64_t>{100 * kMs, 300 * kMs, 700 * kMs, 1500 * kMs}));
  for (const auto& r : rig.ofAction(CaptureAction::kReopenFailed)) {
    EXPECT_EQ(r.step.error, ErrorCode::kNotFound);
    EXPECT_TRUE(r.faulted);
  }
  const auto recovered = rig.ofEvent(CaptureEvent::kRecovered);
  ASSERT_EQ(recovered.size(), 1u);
  EXPECT_EQ(recovered[0].t_ns, t + 1500 * kMs);
  EXPECT_EQ(recovered[0].sequence, 60u);

  const CaptureRetryStats& s = rig.retry->stats();
  EXPECT_EQ(s.disconnects, 1u);
  EXPECT_EQ(s.reopen_attempts, 4u);
  EXPECT_EQ(s.reopens, 1u);
  EXPECT_FALSE(rig.retry->faulted());
  EXPECT_EQ(rig.camera->counters().disconnects, 1u);
}

// One malformed frame: rejected, counted, the fault flag up for one backoff
// delay, the next frame fine.
TEST(CaptureRetry, WrongSizeFrameIsRejectedAndTheNextOneIsFine) {
  CaptureRetryConfig config;
  config.initial_backoff_ns = 10 * kMs;
  Rig rig("living-room,size=64x48,fault=wrong-size@90", config);
  rig.run(99);
  std::vector<uint64_t> expected = iota(0, 90);
  for (uint64_t s = 91; s < 100; ++s) expected.push_back(s);
  EXPECT_EQ(rig.sequences(), expected);
  const auto failed = rig.ofAction(CaptureAction::kAcquireFailed);
  ASSERT_EQ(failed.size(), 1u);
  EXPECT_EQ(failed[0].step.error, ErrorCode::kInvalidInput);
  EXPECT_EQ(failed[0].step.event, CaptureEvent::kFailing);
  const auto recovered = rig.ofEvent(CaptureEvent::kRecovered);
  ASSERT_EQ(recovered.size(), 1u);
  EXPECT_EQ(recovered[0].t_ns, failed[0].t_ns + 10 * kMs);
  EXPECT_EQ(recovered[0].sequence, 91u);
  EXPECT_EQ(rig.retry->stats().rejected_frames, 1u);
  EXPECT_EQ(rig.retry->stats().reopen_attempts, 0u);
  EXPECT_EQ(rig.camera->counters().bad_frames, 1u);
}

// Garbage frames are delivered (they are valid-sized); the pipeline copes:
// back-projection's range filter drops 0 and the far values, foveation gives a
// finite, non-empty cloud.
TEST(CaptureRetry, GarbageFramesPassThroughThePipeline) {
  Rig rig("living-room,size=160x120,fault=garbage@2:3", {});
  const CameraIntrinsics& k = rig.camera->info().intrinsics;
  const std::size_t pixels = static_cast<std::size_t>(k.width) * k.height;
  pipeline::PointCloud cloud(pixels);
  pipeline::FoveatedCloud out(pixels);
  Result<pipeline::Foveator> foveator = pipeline::Foveator::create({pixels, pixels}, {});
  ASSERT_TRUE(foveator.isOk()) << foveator.status().toString();
  pipeline::Backprojector backprojector;
  const pipeline::DepthRange range;  // 0.1 .. 10 m

  for (int frame = 0; frame < 7; ++frame) {
    rig.run(1);
    ASSERT_EQ(rig.log.back().step.action, CaptureAction::kFrame);
    const bool garbage = rig.slot.sequence >= 2 && rig.slot.sequence < 5;
    ASSERT_TRUE(pipeline::validateFrame(rig.slot).isOk());
    pipeline::BackprojectCounts counts;
    const Status bp = backprojector.run(rig.slot, range, cloud, counts);
    ASSERT_TRUE(bp.isOk()) << bp.toString();
    EXPECT_EQ(counts.valid + counts.no_depth + counts.out_of_range, pixels);
    EXPECT_EQ(cloud.size(), counts.valid);
    if (garbage) {
      // An eighth 0, an eighth 65535, the rest uniform: about 3/4 x 9901/65536 in range.
      EXPECT_NEAR(static_cast<double>(counts.no_depth) / pixels, 0.125, 0.02);
      EXPECT_NEAR(static_cast<double>(counts.valid) / pixels, 0.75 * 9901.0 / 65536.0, 0.02);
    }
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const double r = std::sqrt(double(cloud.x()[i]) * cloud.x()[i] + double(cloud.y()[i]) * cloud.y()[i] +
                                 double(cloud.z()[i]) * cloud.z()[i]);
      ASSERT_TRUE(std::isfinite(r));
      ASSERT_LE(r, 10.0 * 1.5);  // within the range's depth, at most the corner rays' length
    }
    pipeline::Gaze gaze;
    gaze.origin_m = rig.slot.T_world_cam.t_world_cam;
    gaze.direction = rig.slot.T_world_cam.R_world_cam.col(2);
    pipeline::FoveationStats stats;
    const Status fs = foveator.value().foveate(cloud, gaze, out, stats);
    ASSERT_TRUE(fs.isOk()) << fs.toString();
    EXPECT_EQ(stats.points_in, cloud.size());
    EXPECT_EQ(stats.dropped_nonfinite, 0u);
    EXPECT_GT(out.size(), 0u);
    EXPECT_LE(out.size(), cloud.size());
    uint64_t weight = 0;
    for (std::size_t i = 0; i < out.size(); ++i) {
      ASSERT_TRUE(std::isfinite(out.points.x()[i]) && std::isfinite(out.points.y()[i]) &&
                  std::isfinite(out.points.z()[i]));
      weight += out.weight[i];
    }
    EXPECT_EQ(weight, cloud.size());  // every input point is represented once
  }
  EXPECT_EQ(rig.camera->counters().injected_garbage, 3u);
  EXPECT_EQ(rig.retry->stats().acquire_failures, 0u);
  EXPECT_TRUE(rig.ofEvent(CaptureEvent::kFailing).empty());
}

// Eight disconnect/reconnect cycles: after the first, the camera, the helper
// and the frames allocate nothing at all (zero per reopen: the mock keeps its
// buffers across stop/open/start and its error messages fit std::string's
// small buffer).
TEST(CaptureRetry, RepeatedDisconnectsAllocateNothingAfterTheFirst) {
  std::string faults;
  constexpr int kCycles = 8;
  for (int i = 1; i <= kCycles; ++i) {
    faults += (i > 1 ? ";" : "") + std::string("disconnect:200ms@") + std::to_string(5 * i);
  }
  CaptureRetryConfig config;
  config.initial_backoff_ns = 20 * kMs;
  config.max_backoff_ns = 80 * kMs;
  Rig rig("living-room,size=64x48,fault=" + faults, config);
  rig.log.reserve(1000);
  rig.run(10);  // frames 0..9: the first cycle (disconnect at frame 5), the warm-up
  ASSERT_EQ(rig.retry->stats().reopens, 1u);

  uint64_t allocations = 0;
  {
    test::AllocationScope scope;
    rig.run(5 * kCycles - 10, /*record=*/false);
    allocations = scope.allocations();
  }
  EXPECT_EQ(allocations, 0u);
  const CaptureRetryStats& s = rig.retry->stats();
  EXPECT_EQ(s.frames, 5u * kCycles);
  EXPECT_EQ(s.disconnects, static_cast<uint64_t>(kCycles - 1));  // the last fires at frame 40
  EXPECT_EQ(s.reopens, static_cast<uint64_t>(kCycles - 1));
  EXPECT_EQ(s.recoveries, static_cast<uint64_t>(kCycles - 1));
  EXPECT_GT(s.reopen_attempts, s.reopens);  // 200 ms outages outlast the first attempts
  EXPECT_EQ(rig.camera->counters().disconnects, static_cast<uint64_t>(kCycles - 1));
}

// The issue's example, every fault in one run with the default policy: three
// failing/recovered pairs (the garbage is delivered, so no fault), one frame lost.
TEST(CaptureRetry, EveryFaultInOneRun) {
  Rig rig("living-room,size=64x48,fault=stall:2s@30;disconnect:1.5s@60;wrong-size@90;garbage@120:3",
          {});
  rig.run(149);
  std::vector<uint64_t> expected = iota(0, 90);
  for (uint64_t s = 91; s < 150; ++s) expected.push_back(s);
  EXPECT_EQ(rig.sequences(), expected);
  std::vector<CaptureEvent> events;
  std::vector<ErrorCode> causes;
  for (const auto& r : rig.log) {
    if (r.step.event != CaptureEvent::kNone) events.push_back(r.step.event);
    if (r.step.event == CaptureEvent::kFailing) causes.push_back(r.step.error);
  }
  const std::vector<CaptureEvent> pairs = {CaptureEvent::kFailing, CaptureEvent::kRecovered,
                                           CaptureEvent::kFailing, CaptureEvent::kRecovered,
                                           CaptureEvent::kFailing, CaptureEvent::kRecovered};
  EXPECT_EQ(events, pairs);
  EXPECT_EQ(causes, (std::vector<ErrorCode>{ErrorCode::kUnavailable, ErrorCode::kNotFound,
                                            ErrorCode::kInvalidInput}));
  EXPECT_FALSE(rig.retry->faulted());
  const CameraCounters c = rig.camera->counters();
  EXPECT_EQ(c.stalls, 1u);
  EXPECT_EQ(c.disconnects, 1u);
  EXPECT_EQ(c.bad_frames, 1u);
  EXPECT_EQ(c.injected_garbage, 3u);
  EXPECT_EQ(c.frames_delivered, 149u);
  EXPECT_EQ(rig.retry->stats().recoveries, 3u);
}

// ---- Device reset before the reopen that follows a stall ----

// A camera double that plays a script of acquire() results and records every
// call with the ManualClock's time. A failed acquire blocks for the timeout
// (the clock advances by it), as a real camera's would.
class ScriptedCamera final : public Camera {
 public:
  struct Call {
    std::string what;  // "acquire", "stop", "reset", "open", "start"
    int64_t t_ns;
  };

  ScriptedCamera(mock::ManualClock& clock, std::vector<ErrorCode> acquires) : clock_(clock), acquires_(std::move(acquires)) {
    info_.name = "scripted";
  }

  Status open() override { return record("open", next(open_results_)); }
  Status start() override { return record("start", ErrorCode::kOk); }
  void stop() override { (void)record("stop", ErrorCode::kOk); }
  Status resetDevice() override { return record("reset", reset_result_); }
  Status acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) override {
    const ErrorCode code = acquired_ < acquires_.size() ? acquires_[acquired_] : ErrorCode::kOk;
    ++acquired_;
    const Status s = record("acquire", code);
    if (code == ErrorCode::kOk) {
      slot.sequence = frames_++;
    } else {
      clock_.advanceNs(timeout.count());
    }
    return s;
  }
  const CameraInfo& info() const override { return info_; }
  CameraCounters counters() const override { return {}; }

  std::vector<std::string> calls() const {
    std::vector<std::string> out;
    for (const Call& c : calls_) out.push_back(c.what);
    return out;
  }
  // The time of the n-th call named `what` (-1 when there is none).
  int64_t timeOf(const std::string& what, int n = 0) const {
    for (const Call& c : calls_) {
      if (c.what == what && n-- == 0) return c.t_ns;
    }
    return -1;
  }

  ErrorCode reset_result_ = ErrorCode::kOk;
  std::vector<ErrorCode> open_results_;  // consumed one per open(); then kOk

 private:
  static ErrorCode next(std::vector<ErrorCode>& results) {
    if (results.empty()) return ErrorCode::kOk;
    const ErrorCode code = results.front();
    results.erase(results.begin());
    return code;
  }
  Status record(const char* what, ErrorCode code) {
    calls_.push_back({what, clock_.nowNs()});
    if (code == ErrorCode::kOk) return Status::ok();
    return {code, what};
  }

  mock::ManualClock& clock_;
  std::vector<ErrorCode> acquires_;
  std::size_t acquired_ = 0;
  uint64_t frames_ = 0;
  CameraInfo info_;
  std::vector<Call> calls_;
};

// Steps the helper like the capture stage until `frames` frames arrived: sleep
// until next_ns when told to wait, spend 33 ms on each frame.
void runScripted(CaptureRetry& retry, mock::ManualClock& clock, uint64_t frames) {
  RgbdFrame slot(4, 3);
  const uint64_t target = retry.stats().frames + frames;
  for (int i = 0; i < 10000 && retry.stats().frames < target; ++i) {
    const CaptureStep step = retry.step(clock.nowNs(), slot);
    if (step.action == CaptureAction::kWait) {
      clock.setNs(step.next_ns);
    } else if (step.action == CaptureAction::kFrame) {
      clock.advanceNs(kFramePeriodNs);
    }
  }
}

CaptureRetryConfig resetConfig() {
  CaptureRetryConfig config;
  config.acquire_timeout = std::chrono::milliseconds(100);
  config.initial_backoff_ns = 10 * kMs;
  config.max_backoff_ns = 1000 * kMs;
  config.reopen_after_failures = 3;
  return config;
}

constexpr ErrorCode kOk = ErrorCode::kOk;
constexpr ErrorCode kTimeout = ErrorCode::kUnavailable;
constexpr ErrorCode kGone = ErrorCode::kNotFound;

// Frames at 0 and 33 ms; timeouts at 66, 166 and 266 ms (each blocks 100 ms;
// backoff 10, 20, 40 ms from each failing step); the third makes a stall, so
// at 366 ms: stop, reset, open, start, and the next frame at once.
TEST(CaptureRetryReset, AStallResetsTheDeviceBetweenStopAndTheReopen) {
  mock::ManualClock clock(0);
  ScriptedCamera camera(clock, {kOk, kOk, kTimeout, kTimeout, kTimeout});
  CaptureRetry retry(camera, resetConfig());
  runScripted(retry, clock, 3);

  const std::vector<std::string> expected = {"acquire", "acquire", "acquire", "acquire", "acquire",
                                             "stop",    "reset",   "open",    "start",   "acquire"};
  EXPECT_EQ(camera.calls(), expected);
  EXPECT_EQ(camera.timeOf("acquire", 2), 66 * kMs);
  EXPECT_EQ(camera.timeOf("acquire", 4), 266 * kMs);
  EXPECT_EQ(camera.timeOf("stop"), 366 * kMs);
  EXPECT_EQ(camera.timeOf("reset"), 366 * kMs);
  EXPECT_EQ(camera.timeOf("open"), 366 * kMs);
  EXPECT_EQ(camera.timeOf("acquire", 5), 366 * kMs);
  const CaptureRetryStats& s = retry.stats();
  EXPECT_EQ(s.reset_attempts, 1u);
  EXPECT_EQ(s.resets, 1u);
  EXPECT_EQ(s.resets_unsupported + s.resets_vanished + s.reset_failures, 0u);
  EXPECT_EQ(s.reopens, 1u);
  EXPECT_EQ(s.recoveries, 1u);
  EXPECT_FALSE(retry.resetPending());
}

// A disconnect (kNotFound) reopens at once after the backoff, with no reset:
// there is nothing on the bus to reset. The first reopen fails (still gone).
TEST(CaptureRetryReset, ADisconnectReopensWithoutAReset) {
  mock::ManualClock clock(0);
  ScriptedCamera camera(clock, {kOk, kGone});
  camera.open_results_ = {kGone};
  CaptureRetry retry(camera, resetConfig());
  runScripted(retry, clock, 2);

  const std::vector<std::string> expected = {"acquire", "acquire", "stop", "open", "stop", "open", "start", "acquire"};
  EXPECT_EQ(camera.calls(), expected);
  EXPECT_EQ(camera.timeOf("reset"), -1);
  // acquire at 33 ms fails (blocks to 133); reopen at 33 + 10, already past: 133;
  // it fails, the next at 133 + 20 = 153.
  EXPECT_EQ(camera.timeOf("open", 0), 133 * kMs);
  EXPECT_EQ(camera.timeOf("open", 1), 153 * kMs);
  const CaptureRetryStats& s = retry.stats();
  EXPECT_EQ(s.reset_attempts, 0u);
  EXPECT_EQ(s.disconnects, 1u);
  EXPECT_EQ(s.reopens, 1u);
}

// A camera without a reset (Camera's default, kUnavailable): counted as
// unsupported, and the reopen happens exactly as with a reset.
TEST(CaptureRetryReset, AnUnsupportedResetStillReopens) {
  mock::ManualClock clock(0);
  ScriptedCamera camera(clock, {kOk, kOk, kTimeout, kTimeout, kTimeout});
  camera.reset_result_ = ErrorCode::kUnavailable;
  CaptureRetry retry(camera, resetConfig());
  runScripted(retry, clock, 3);

  const std::vector<std::string> expected = {"acquire", "acquire", "acquire", "acquire", "acquire",
                                             "stop",    "reset",   "open",    "start",   "acquire"};
  EXPECT_EQ(camera.calls(), expected);
  EXPECT_EQ(camera.timeOf("open"), 366 * kMs);
  const CaptureRetryStats& s = retry.stats();
  EXPECT_EQ(s.reset_attempts, 1u);
  EXPECT_EQ(s.resets_unsupported, 1u);
  EXPECT_EQ(s.resets, 0u);
  EXPECT_EQ(s.reopens, 1u);
  EXPECT_EQ(s.frames, 3u);
}

// A reset that fails (an I/O error) or makes the device re-enumerate
// (kNotFound) does not stop the reopen; each is counted by kind.
TEST(CaptureRetryReset, AFailedOrVanishingResetStillReopens) {
  for (const ErrorCode reset : {ErrorCode::kIoError, ErrorCode::kNotFound}) {
    mock::ManualClock clock(0);
    ScriptedCamera camera(clock, {kTimeout, kTimeout, kTimeout});
    camera.reset_result_ = reset;
    CaptureRetry retry(camera, resetConfig());
    runScripted(retry, clock, 1);
    const std::vector<std::string> expected = {"acquire", "acquire", "acquire", "stop",
                                               "reset",   "open",    "start",   "acquire"};
    EXPECT_EQ(camera.calls(), expected) << errorCodeName(reset);
    const CaptureRetryStats& s = retry.stats();
    EXPECT_EQ(s.reset_failures, reset == ErrorCode::kIoError ? 1u : 0u);
    EXPECT_EQ(s.resets_vanished, reset == ErrorCode::kNotFound ? 1u : 0u);
    EXPECT_EQ(s.reopens, 1u);
    EXPECT_EQ(s.frames, 1u);
  }
}

// After a stall, a reopen that fails is retried without resetting again; a
// second stall after the recovery resets again.
TEST(CaptureRetryReset, OneResetPerStallNotPerReopenAttempt) {
  mock::ManualClock clock(0);
  ScriptedCamera camera(clock, {kTimeout, kTimeout, kTimeout, kOk, kTimeout, kTimeout, kTimeout, kOk});
  camera.open_results_ = {ErrorCode::kIoError};
  CaptureRetry retry(camera, resetConfig());
  runScripted(retry, clock, 2);

  const std::vector<std::string> expected = {
      "acquire", "acquire", "acquire", "stop", "reset", "open",  // first reopen fails
      "stop",    "open",    "start",   "acquire",                // retried without a reset; frame
      "acquire", "acquire", "acquire", "stop", "reset", "open", "start", "acquire"};  // second stall
  EXPECT_EQ(camera.calls(), expected);
  const CaptureRetryStats& s = retry.stats();
  EXPECT_EQ(s.reset_attempts, 2u);
  EXPECT_EQ(s.resets, 2u);
  EXPECT_EQ(s.reopen_attempts, 3u);
  EXPECT_EQ(s.reopens, 2u);
}

TEST(CaptureRetry, ActionAndEventNames) {
  EXPECT_STREQ(captureActionName(CaptureAction::kReopenFailed), "reopen-failed");
  EXPECT_STREQ(captureEventName(CaptureEvent::kRecovered), "recovered");
}

}  // namespace
}  // namespace fovea::hal
