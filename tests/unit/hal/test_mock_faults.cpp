// The mock camera's fault injection (fault=...): parsing, and what each fault
// does to acquire(), open() and start(), on a ManualClock so stalls take no time.
#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "hal/camera.h"
#include "hal/camera/mock/faults.h"
#include "hal/camera/mock/mock_camera.h"

namespace fovea::hal::mock {
namespace {

using std::chrono::milliseconds;

constexpr int64_t kMs = 1'000'000;

std::unique_ptr<MockCamera> makeStarted(const std::string& args, MockClock* clock) {
  Result<MockCameraOptions> options = parseMockCameraOptions(args);
  EXPECT_TRUE(options.isOk()) << options.status().toString();
  if (!options.isOk()) return nullptr;
  auto camera = std::make_unique<MockCamera>(std::move(options).value());
  camera->setClock(clock);
  EXPECT_TRUE(camera->open().isOk());
  EXPECT_TRUE(camera->start().isOk());
  return camera;
}

RgbdFrame makeSlot(const Camera& camera) {
  return RgbdFrame(camera.info().intrinsics.width, camera.info().intrinsics.height);
}

void expectInvalid(const std::string& fault, const std::vector<std::string>& mentions) {
  Result<MockCameraOptions> options = parseMockCameraOptions("living-room,fault=" + fault);
  ASSERT_FALSE(options.isOk()) << fault;
  EXPECT_EQ(options.status().code(), ErrorCode::kInvalidArgument);
  for (const std::string& word : mentions) {
    EXPECT_NE(options.status().message().find(word), std::string::npos)
        << fault << " -> " << options.status().message() << " should mention " << word;
  }
}

TEST(FaultSpec, ParsesEveryKind) {
  Result<std::vector<FaultSpec>> faults =
      parseFaults("stall:2s@30;disconnect:1.5s@60;wrong-size@90;garbage@120:3;stall:250ms@0");
  ASSERT_TRUE(faults.isOk()) << faults.status().toString();
  const std::vector<FaultSpec>& f = faults.value();
  ASSERT_EQ(f.size(), 5u);
  EXPECT_EQ(f[0].kind, FaultKind::kStall);
  EXPECT_EQ(f[0].at_frame, 30u);
  EXPECT_EQ(f[0].duration_ns, 2000 * kMs);
  EXPECT_EQ(f[1].kind, FaultKind::kDisconnect);
  EXPECT_EQ(f[1].at_frame, 60u);
  EXPECT_EQ(f[1].duration_ns, 1500 * kMs);
  EXPECT_EQ(f[2].kind, FaultKind::kWrongSize);
  EXPECT_EQ(f[2].at_frame, 90u);
  EXPECT_EQ(f[2].count, 1u);
  EXPECT_EQ(f[3].kind, FaultKind::kGarbage);
  EXPECT_EQ(f[3].at_frame, 120u);
  EXPECT_EQ(f[3].count, 3u);
  EXPECT_EQ(f[4].duration_ns, 250 * kMs);
  EXPECT_EQ(f[4].at_frame, 0u);

  Result<std::vector<FaultSpec>> none = parseFaults("none");
  ASSERT_TRUE(none.isOk());
  EXPECT_TRUE(none.value().empty());

  // Through the camera spec, with the other keys after it.
  Result<MockCameraOptions> options =
      parseMockCameraOptions("balloon,fault=garbage@5;wrong-size@7:2,seed=4");
  ASSERT_TRUE(options.isOk()) << options.status().toString();
  ASSERT_EQ(options.value().faults.size(), 2u);
  EXPECT_EQ(options.value().faults[1].count, 2u);
  EXPECT_EQ(options.value().seed, 4u);
  EXPECT_TRUE(parseMockCameraOptions("living-room").value().faults.empty());
}

TEST(FaultSpec, BadFaultsSayWhatIsWrong) {
  expectInvalid("stall@30", {"stall@30", "duration", "stall:2s@30"});
  expectInvalid("stall:2@30", {"duration"});
  expectInvalid("stall:0s@30", {"duration"});
  expectInvalid("stall:2s", {"@FRAME"});
  expectInvalid("stall:2s@x", {"FRAME"});
  expectInvalid("stall:2s@30:4", {"no frame count"});
  expectInvalid("garbage:2s@3", {"no duration"});
  expectInvalid("garbage@3:0", {"N", "1..1000000"});
  expectInvalid("melt@3", {"unknown kind 'melt'", "wrong-size"});
  expectInvalid("", {"empty"});
  expectInvalid("garbage@3;;stall:1s@4", {"empty"});
  expectInvalid("none;garbage@3", {"'none'", "@FRAME"});
  EXPECT_NE(mockCameraHelp().find("fault="), std::string::npos);
  EXPECT_NE(cameraSpecHelp().find("disconnect"), std::string::npos);
}

// A stall blocks each acquire() for its timeout and returns kUnavailable until
// the stall's end; the call that reaches the end waits for it and delivers.
TEST(MockFaults, StallDeliversNothingForItsDuration) {
  ManualClock clock(1000 * kMs);
  auto camera = makeStarted("living-room,size=64x48,fault=stall:250ms@2", &clock);
  RgbdFrame slot = makeSlot(*camera);
  ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());
  ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());
  EXPECT_EQ(clock.nowNs(), 1000 * kMs);  // no faults yet: no waiting
  for (int i = 1; i <= 2; ++i) {
    const Status s = camera->acquire(slot, milliseconds(100));
    EXPECT_EQ(s.code(), ErrorCode::kUnavailable);
    EXPECT_EQ(s.message(), "stalled");
    EXPECT_EQ(clock.nowNs(), (1000 + 100 * i) * kMs);
  }
  ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());  // waits the last 50 ms
  EXPECT_EQ(clock.nowNs(), 1250 * kMs);
  EXPECT_EQ(slot.sequence, 2u);  // nothing was skipped (realtime=off)
  ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());
  EXPECT_EQ(clock.nowNs(), 1250 * kMs);
  const CameraCounters c = camera->counters();
  EXPECT_EQ(c.stalls, 1u);
  EXPECT_EQ(c.timeouts, 2u);
  EXPECT_EQ(c.errors, 0u);
  EXPECT_EQ(c.frames_delivered, 4u);
}

// A disconnect holds until the camera is reopened after the outage.
TEST(MockFaults, DisconnectNeedsAReopenAfterTheOutage) {
  ManualClock clock(0);
  auto camera = makeStarted("living-room,size=64x48,fault=disconnect:1.5s@1", &clock);
  RgbdFrame slot = makeSlot(*camera);
  ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());
  clock.setNs(100 * kMs);
  Status s = camera->acquire(slot, milliseconds(100));
  EXPECT_EQ(s.code(), ErrorCode::kNotFound);
  EXPECT_EQ(s.message(), "disconnected");
  clock.setNs(2000 * kMs);  // the device is back, but this session is dead
  EXPECT_EQ(camera->acquire(slot, milliseconds(100)).code(), ErrorCode::kNotFound);

  ManualClock clock2(0);
  auto camera2 = makeStarted("living-room,size=64x48,fault=disconnect:1.5s@0", &clock2);
  EXPECT_EQ(camera2->acquire(slot, milliseconds(100)).code(), ErrorCode::kNotFound);
  camera2->stop();
  clock2.setNs(1499 * kMs);
  s = camera2->open();
  EXPECT_EQ(s.code(), ErrorCode::kNotFound);
  EXPECT_EQ(s.message(), "device gone");
  EXPECT_EQ(camera2->start().code(), ErrorCode::kNotFound);
  EXPECT_EQ(camera2->acquire(slot, milliseconds(100)).code(), ErrorCode::kUnavailable);  // stopped
  clock2.setNs(1500 * kMs);
  ASSERT_TRUE(camera2->open().isOk());
  ASSERT_TRUE(camera2->start().isOk());
  ASSERT_TRUE(camera2->acquire(slot, milliseconds(100)).isOk());
  EXPECT_EQ(slot.sequence, 0u);  // the frame the disconnect took was never delivered
  const CameraCounters c = camera2->counters();
  EXPECT_EQ(c.disconnects, 1u);
  EXPECT_EQ(c.errors, 2u);  // the disconnected acquire and the stopped one
  EXPECT_EQ(c.frames_delivered, 1u);
}

// The malformed frame is refused before anything is copied: the slot keeps the
// last good frame's pixels, and the next frame is fine.
TEST(MockFaults, WrongSizeIsRejectedWithoutTouchingTheSlot) {
  ManualClock clock;
  auto camera = makeStarted("living-room,size=64x48,fault=wrong-size@1:2", &clock);
  // A slot exactly the frame's size: a copy of the device's larger image would overflow.
  RgbdFrame slot(64, 48);
  ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());
  const std::vector<uint16_t> depth(slot.depth(), slot.depth() + slot.pixelCount());
  const std::vector<uint8_t> rgb(slot.rgb(), slot.rgb() + 3 * slot.pixelCount());
  for (int i = 0; i < 2; ++i) {
    const Status s = camera->acquire(slot, milliseconds(100));
    EXPECT_EQ(s.code(), ErrorCode::kInvalidInput);
    EXPECT_EQ(s.message(), "wrong size");
    EXPECT_EQ(std::memcmp(slot.depth(), depth.data(), depth.size() * 2), 0);
    EXPECT_EQ(std::memcmp(slot.rgb(), rgb.data(), rgb.size()), 0);
    EXPECT_EQ(slot.sequence, 0u);
  }
  ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());
  EXPECT_EQ(slot.sequence, 3u);  // frames 1 and 2 were the malformed ones
  const CameraCounters c = camera->counters();
  EXPECT_EQ(c.bad_frames, 2u);
  EXPECT_EQ(c.errors, 2u);
  EXPECT_EQ(c.frames_delivered, 2u);
}

TEST(MockFaults, GarbageIsValidSizedRandomDepthAndColour) {
  ManualClock clock;
  const std::string args = "living-room,size=160x120,seed=3,fault=garbage@1:2";
  auto camera = makeStarted(args, &clock);
  auto twin = makeStarted(args, &clock);
  RgbdFrame slot = makeSlot(*camera);
  RgbdFrame twin_slot = makeSlot(*twin);
  ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());
  const std::vector<uint16_t> clean(slot.depth(), slot.depth() + slot.pixelCount());
  std::vector<uint16_t> first_garbage;
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());
    EXPECT_EQ(slot.width(), 160);
    EXPECT_EQ(slot.intrinsics.width, 160);
    std::size_t zeros = 0, max = 0, differ = 0;
    for (std::size_t p = 0; p < slot.pixelCount(); ++p) {
      zeros += slot.depth()[p] == 0;
      max += slot.depth()[p] == 65535;
      differ += slot.depth()[p] != clean[p];
    }
    const double n = static_cast<double>(slot.pixelCount());
    EXPECT_NEAR(zeros / n, 0.125, 0.01);
    EXPECT_NEAR(max / n, 0.125, 0.01);
    EXPECT_GT(differ / n, 0.95);
    if (i == 0) {
      first_garbage.assign(slot.depth(), slot.depth() + slot.pixelCount());
    } else {
      EXPECT_NE(std::memcmp(first_garbage.data(), slot.depth(), first_garbage.size() * 2), 0);
    }
  }
  ASSERT_TRUE(camera->acquire(slot, milliseconds(100)).isOk());  // frame 3: clean again
  std::size_t valid = 0;
  for (std::size_t p = 0; p < slot.pixelCount(); ++p) valid += slot.depth()[p] != 0;
  EXPECT_GT(valid, slot.pixelCount() * 9 / 10);
  const CameraCounters c = camera->counters();
  EXPECT_EQ(c.injected_garbage, 2u);
  EXPECT_EQ(c.frames_delivered, 4u);
  // Deterministic: the same spec gives the same garbage.
  for (int i = 0; i < 2; ++i) ASSERT_TRUE(twin->acquire(twin_slot, milliseconds(100)).isOk());
  EXPECT_EQ(std::memcmp(first_garbage.data(), twin_slot.depth(), first_garbage.size() * 2), 0);
}

// Without a test clock the stall runs on the steady clock and really blocks
// (only a lower bound is checked: timing is never asserted upwards in tests).
TEST(MockFaults, StallOnTheSteadyClockBlocks) {
  auto camera = makeStarted("living-room,size=64x48,fault=stall:60ms@0", nullptr);
  RgbdFrame slot = makeSlot(*camera);
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(camera->acquire(slot, milliseconds(20)).code(), ErrorCode::kUnavailable);
  EXPECT_GE(std::chrono::steady_clock::now() - start, milliseconds(20));
  int timeouts = 1;
  Status s;
  while (!(s = camera->acquire(slot, milliseconds(20))).isOk() && timeouts < 100) ++timeouts;
  ASSERT_TRUE(s.isOk()) << s.toString();
  EXPECT_GE(std::chrono::steady_clock::now() - start, milliseconds(60));
  EXPECT_EQ(camera->counters().timeouts, static_cast<uint64_t>(timeouts));
  EXPECT_EQ(slot.sequence, 0u);
}

TEST(MockFaults, NoneChangesNothing) {
  ManualClock clock;
  auto plain = makeStarted("living-room,size=64x48", &clock);
  auto none = makeStarted("living-room,size=64x48,fault=none", &clock);
  RgbdFrame a = makeSlot(*plain);
  RgbdFrame b = makeSlot(*none);
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(plain->acquire(a, milliseconds(100)).isOk());
    ASSERT_TRUE(none->acquire(b, milliseconds(100)).isOk());
    EXPECT_EQ(std::memcmp(a.depth(), b.depth(), a.pixelCount() * 2), 0);
  }
}

}  // namespace
}  // namespace fovea::hal::mock
