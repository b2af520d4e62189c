// The status lines on the mock chip: exact heartbeat, streaming, fault and
// privacy sequences, with time passed in.
#include "firmware/status_lines.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "hal/gpio/mock/mock_gpio.h"

namespace fovea::firmware {
namespace {

using hal::mock::GpioEvent;
using hal::mock::MockGpio;

constexpr int64_t kMs = 1'000'000;
constexpr unsigned kHeartbeat = 0, kStreaming = 1, kFault = 2, kPrivacy = 3;

StatusLinesConfig fourLines() {
  StatusLinesConfig c;
  c.heartbeat_line = kHeartbeat;
  c.streaming_line = kStreaming;
  c.fault_line = kFault;
  c.privacy_line = kPrivacy;
  c.heartbeat_period_ns = 500 * kMs;
  c.consumer = "fovead-test";
  return c;
}

// Runs updates every step_ms from from_ms (inclusive) to to_ms (exclusive),
// stamping the mock's changes with the update's time.
void run(MockGpio& gpio, StatusLines& lines, const StatusInputs& in, int64_t from_ms, int64_t to_ms,
         int64_t step_ms = 100) {
  for (int64_t t = from_ms; t < to_ms; t += step_ms) {
    gpio.setNowNs(t * kMs);
    lines.update(in, t * kMs);
  }
}

StatusInputs healthy() {
  StatusInputs in;
  in.healthy = true;
  return in;
}

TEST(StatusLines, StartRequestsEveryLineLowWithTheConsumerName) {
  MockGpio gpio(8);
  StatusLines lines(gpio, fourLines());
  ASSERT_TRUE(lines.start().isOk());
  for (unsigned l : {kHeartbeat, kStreaming, kFault}) {
    EXPECT_TRUE(gpio.isOutput(l));
    EXPECT_FALSE(gpio.value(l));
    EXPECT_EQ(gpio.consumer(l), "fovead-test");
  }
  EXPECT_TRUE(gpio.isRequested(kPrivacy));
  EXPECT_FALSE(gpio.isOutput(kPrivacy));
  lines.stop();
  EXPECT_FALSE(gpio.isRequested(kHeartbeat));
  EXPECT_FALSE(gpio.isRequested(kPrivacy));
}

TEST(StatusLines, HeartbeatTogglesEveryPeriodWhileHealthyAndHoldsWhileNot) {
  MockGpio gpio(8);
  StatusLines lines(gpio, fourLines());
  ASSERT_TRUE(lines.start().isOk());
  gpio.clearEvents();
  run(gpio, lines, healthy(), 0, 2100);      // toggles at 0, 500, ..., 2000
  run(gpio, lines, StatusInputs{}, 2100, 3000);  // stalled: holds high
  run(gpio, lines, healthy(), 3000, 4100);   // healthy again: toggles at once
  const std::vector<GpioEvent> expected = {
      {0, kHeartbeat, true},          {500 * kMs, kHeartbeat, false},  {1000 * kMs, kHeartbeat, true},
      {1500 * kMs, kHeartbeat, false}, {2000 * kMs, kHeartbeat, true},  {3000 * kMs, kHeartbeat, false},
      {3500 * kMs, kHeartbeat, true},  {4000 * kMs, kHeartbeat, false},
  };
  EXPECT_EQ(gpio.events(), expected);
  EXPECT_EQ(lines.counters().heartbeat_toggles, 8u);
  EXPECT_EQ(gpio.counters().writes, 8u);  // a line is written only when it changes
}

TEST(StatusLines, HeartbeatKeepsItsPhaseWithJitterAndDoesNotBurstAfterAGap) {
  MockGpio gpio(8);
  StatusLines lines(gpio, fourLines());
  ASSERT_TRUE(lines.start().isOk());
  gpio.clearEvents();
  for (int64_t t_ms : {0, 330, 660, 990, 1320, 3000, 3400, 3500}) {
    gpio.setNowNs(t_ms * kMs);
    lines.update(healthy(), t_ms * kMs);
  }
  // Due at 500 (seen at 660), 1000 (1320): phase kept. Due at 1500, seen at 3000,
  // more than a period late: one toggle, phase restarts (next at 3500).
  const std::vector<GpioEvent> expected = {
      {0, kHeartbeat, true},           {660 * kMs, kHeartbeat, false}, {1320 * kMs, kHeartbeat, true},
      {3000 * kMs, kHeartbeat, false}, {3500 * kMs, kHeartbeat, true},
  };
  EXPECT_EQ(gpio.events(), expected);
}

TEST(StatusLines, StreamingWhileAnOperatorIsConnectedWithFreshGaze) {
  MockGpio gpio(8);
  StatusLines lines(gpio, fourLines());
  ASSERT_TRUE(lines.start().isOk());
  gpio.clearEvents();
  StatusInputs in;
  in.operator_connected = true;
  run(gpio, lines, in, 0, 200);  // connected, no gaze yet: off
  in.gaze_fresh = true;
  run(gpio, lines, in, 200, 500);  // on at 200
  in.gaze_fresh = false;
  run(gpio, lines, in, 500, 600);  // stale: off at 500
  in.gaze_fresh = true;
  run(gpio, lines, in, 600, 700);  // on at 600
  in.operator_connected = false;
  run(gpio, lines, in, 700, 800);  // gone: off at 700
  const std::vector<GpioEvent> expected = {
      {200 * kMs, kStreaming, true}, {500 * kMs, kStreaming, false},
      {600 * kMs, kStreaming, true}, {700 * kMs, kStreaming, false},
  };
  EXPECT_EQ(gpio.events(), expected);
}

TEST(StatusLines, FaultLineFollowsTheStandingFault) {
  MockGpio gpio(8);
  StatusLines lines(gpio, fourLines());
  ASSERT_TRUE(lines.start().isOk());
  gpio.clearEvents();
  StatusInputs in;
  run(gpio, lines, in, 0, 300);
  in.fault = true;
  run(gpio, lines, in, 300, 1000);
  in.fault = false;
  run(gpio, lines, in, 1000, 1200);
  EXPECT_EQ(gpio.events(), (std::vector<GpioEvent>{{300 * kMs, kFault, true}, {1000 * kMs, kFault, false}}));
}

TEST(StatusLines, PrivacyPausesStreamingWhileActive) {
  MockGpio gpio(8);
  StatusLines lines(gpio, fourLines());
  ASSERT_TRUE(lines.start().isOk());
  gpio.clearEvents();
  StatusInputs in;
  in.operator_connected = true;
  in.gaze_fresh = true;
  run(gpio, lines, in, 0, 300);
  EXPECT_TRUE(lines.state().stream_allowed);
  gpio.setInput(kPrivacy, true);
  run(gpio, lines, in, 300, 600);
  EXPECT_TRUE(lines.state().privacy_active);
  EXPECT_FALSE(lines.state().stream_allowed);
  EXPECT_FALSE(lines.state().streaming);
  gpio.setInput(kPrivacy, false);
  run(gpio, lines, in, 600, 700);
  EXPECT_TRUE(lines.state().stream_allowed);
  EXPECT_EQ(gpio.events(), (std::vector<GpioEvent>{{0, kStreaming, true}, {300 * kMs, kStreaming, false},
                                                   {600 * kMs, kStreaming, true}}));
  EXPECT_EQ(lines.counters().privacy_pauses, 1u);
}

TEST(StatusLines, PrivacyActiveLowAndAFailedReadFailSafe) {
  MockGpio gpio(8);
  StatusLinesConfig config = fourLines();
  config.privacy_active_low = true;
  gpio.setInput(kPrivacy, true);  // pulled up: switch off
  StatusLines lines(gpio, config);
  ASSERT_TRUE(lines.start().isOk());
  StatusInputs in;
  EXPECT_TRUE(lines.update(in, 0).stream_allowed);
  gpio.setInput(kPrivacy, false);  // switch to ground: on
  EXPECT_FALSE(lines.update(in, 1).stream_allowed);
  gpio.setInput(kPrivacy, true);
  EXPECT_TRUE(lines.update(in, 2).stream_allowed);
  gpio.failReads(true);
  EXPECT_FALSE(lines.update(in, 3).stream_allowed);
  EXPECT_EQ(lines.counters().read_errors, 1u);
  EXPECT_EQ(lines.counters().privacy_pauses, 2u);
}

TEST(StatusLines, AFailedWriteIsCountedAndRetried) {
  MockGpio gpio(8);
  StatusLines lines(gpio, fourLines());
  ASSERT_TRUE(lines.start().isOk());
  gpio.clearEvents();
  StatusInputs in;
  in.fault = true;
  gpio.failWrites(true);
  gpio.setNowNs(0);
  lines.update(in, 0);
  EXPECT_EQ(lines.counters().write_errors, 1u);
  EXPECT_TRUE(gpio.events().empty());
  gpio.failWrites(false);
  gpio.setNowNs(10 * kMs);
  lines.update(in, 10 * kMs);
  EXPECT_EQ(gpio.events(), (std::vector<GpioEvent>{{10 * kMs, kFault, true}}));
}

TEST(StatusLines, LinesCanBeLeftOut) {
  MockGpio gpio(2);
  StatusLinesConfig config;
  config.fault_line = 1;
  StatusLines lines(gpio, config);
  ASSERT_TRUE(lines.start().isOk());
  StatusInputs in = healthy();
  in.fault = true;
  lines.update(in, 0);
  EXPECT_TRUE(gpio.value(1));
  EXPECT_FALSE(gpio.isRequested(0));
  EXPECT_TRUE(lines.state().stream_allowed);
}

TEST(StatusLines, ConfigurationErrorsNameTheField) {
  MockGpio gpio(4);
  StatusLinesConfig config = fourLines();
  config.fault_line = 7;
  StatusLines bad_line(gpio, config);
  Status s = bad_line.start();
  EXPECT_EQ(s.code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "gpio.fault_line = 7: out of range, the chip has lines 0..3 (or -1 for none)");
  EXPECT_FALSE(gpio.isRequested(kHeartbeat));  // nothing left requested

  config = fourLines();
  config.privacy_line = kHeartbeat;
  EXPECT_EQ(config.validate(4).message(), "gpio.privacy_line = 0: the same line as gpio.heartbeat_line");
  config = fourLines();
  config.heartbeat_period_ns = 0;
  EXPECT_EQ(config.validate(4).message(), "gpio.heartbeat_period: must be positive, got 0 ns");
}

TEST(StatusLines, ALineTakenByAnotherConsumerFailsStartAndReleasesTheRest) {
  MockGpio gpio(8);
  ASSERT_TRUE(gpio.requestOutput(kFault, "someone-else", false).isOk());
  StatusLines lines(gpio, fourLines());
  Status s = lines.start();
  EXPECT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("line 2"), std::string::npos) << s.message();
  EXPECT_FALSE(gpio.isRequested(kHeartbeat));
}

// The heartbeat and fault sequence with each level read back from the chip
// after each update: on the mock here, and on real lines below.
void heartbeatAndFaultSequenceReadBack(hal::Gpio& gpio) {
  StatusLinesConfig config;
  config.heartbeat_line = 0;
  config.streaming_line = 1;
  config.fault_line = 2;
  config.heartbeat_period_ns = 500 * kMs;
  StatusLines lines(gpio, config);
  Status started = lines.start();
  ASSERT_TRUE(started.isOk()) << started.toString() << " on " << gpio.name();

  auto expectLines = [&](bool heartbeat, bool streaming, bool fault, int64_t t_ms) {
    bool level = false;
    ASSERT_TRUE(gpio.get(0, level));
    EXPECT_EQ(level, heartbeat) << "heartbeat at " << t_ms << " ms";
    ASSERT_TRUE(gpio.get(1, level));
    EXPECT_EQ(level, streaming) << "streaming at " << t_ms << " ms";
    ASSERT_TRUE(gpio.get(2, level));
    EXPECT_EQ(level, fault) << "fault at " << t_ms << " ms";
  };
  expectLines(false, false, false, -1);
  StatusInputs in;
  bool heartbeat = false;
  for (int64_t t_ms = 0; t_ms <= 3000; t_ms += 250) {
    in.fault = t_ms >= 1000 && t_ms < 2000;                // a fault stands from 1 s to 2 s
    in.healthy = !(t_ms >= 1000 && t_ms < 1500);           // and stalls the pipeline for 0.5 s
    in.operator_connected = in.gaze_fresh = t_ms >= 2500;  // an operator arrives at 2.5 s
    lines.update(in, t_ms * kMs);
    // Toggles at 0, 500, 1500 (healthy again: at once), 2000, 2500, 3000.
    if (t_ms == 0 || t_ms == 500 || t_ms == 1500 || t_ms == 2000 || t_ms == 2500 || t_ms == 3000) {
      heartbeat = !heartbeat;
    }
    expectLines(heartbeat, in.operator_connected, in.fault, t_ms);
  }
  EXPECT_EQ(lines.counters().write_errors, 0u);
  EXPECT_EQ(lines.counters().heartbeat_toggles, 6u);
  lines.stop();
  EXPECT_EQ(gpio.counters().write_errors, 0u);
}

TEST(StatusLines, HeartbeatAndFaultSequenceReadBackOnTheMock) {
  MockGpio gpio(8);
  heartbeatAndFaultSequenceReadBack(gpio);
}

bool anyGpioChip() {
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/dev", ec)) {
    if (entry.path().filename().string().rfind("gpiochip", 0) == 0) return true;
  }
  return false;
}

// Real lines: run by tests/vm/run-vm on the arm64 VM's PL061 (lines 0, 1, 2
// of gpiochip0; FOVEA_TEST_GPIO_CHIP names another chip), skipped without one.
TEST(StatusLinesOnRealGpio, HeartbeatAndFaultSequenceReadBack) {
#ifndef FOVEA_HAVE_GPIOD
  GTEST_SKIP() << "built without libgpiod";
#endif
  if (!anyGpioChip()) GTEST_SKIP() << "no /dev/gpiochip* on this machine";
  const char* chip_env = std::getenv("FOVEA_TEST_GPIO_CHIP");
  auto created = hal::createGpio(std::string("gpiod:") + (chip_env ? chip_env : "gpiochip0"));
  ASSERT_TRUE(created.isOk()) << created.status().toString();
  heartbeatAndFaultSequenceReadBack(**created);
}

}  // namespace
}  // namespace fovea::firmware
