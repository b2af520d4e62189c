// The GPIO backends: the mock chip's bookkeeping and errors, the backend table,
// and libgpiod's clear error without a chip (this host) or real lines (the arm64
// virtual machine of tests/vm, or a board; skipped without /dev/gpiochip*).
#include "hal/gpio.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "hal/gpio/mock/mock_gpio.h"
#ifdef FOVEA_HAVE_GPIOD
#include "hal/gpio/gpiod/gpiod_gpio.h"
#endif

namespace fovea::hal {
namespace {

using mock::GpioEvent;
using mock::MockGpio;
using testing::HasSubstr;

TEST(GpioTable, MockFromSpecAndUnknownBackendNamesTheAccepted) {
  auto gpio = createGpio("mock");
  ASSERT_TRUE(gpio.isOk()) << gpio.status().toString();
  EXPECT_EQ((*gpio)->lineCount(), 8u);
  EXPECT_EQ((*gpio)->name(), "mock (8 lines)");
  auto sixteen = createGpio("mock:lines=16");
  ASSERT_TRUE(sixteen.isOk());
  EXPECT_EQ((*sixteen)->lineCount(), 16u);

  auto bad = createGpio("mock:lines=0");
  ASSERT_FALSE(bad.isOk());
  EXPECT_EQ(bad.status().message(), "gpio: mock: bad option 'lines=0'; accepted: lines=N (1..512)");
  auto unknown = createGpio("sysfs:gpiochip0");
  ASSERT_FALSE(unknown.isOk());
  EXPECT_EQ(unknown.status().code(), ErrorCode::kInvalidArgument);
  EXPECT_THAT(unknown.status().message(), HasSubstr("unknown backend 'sysfs' in 'sysfs:gpiochip0'; accepted: mock"));
  EXPECT_THAT(gpioSpecHelp(), HasSubstr("mock[:lines=N]"));
}

TEST(MockGpio, RecordsChangesWithTimestampsNotRepeatedWrites) {
  MockGpio gpio(4);
  gpio.setNowNs(100);
  ASSERT_TRUE(gpio.requestOutput(1, "fovea-heartbeat", false).isOk());
  ASSERT_TRUE(gpio.requestOutput(2, "fovea-fault", true).isOk());
  EXPECT_EQ(gpio.consumer(1), "fovea-heartbeat");
  gpio.setNowNs(200);
  EXPECT_TRUE(gpio.set(1, true));
  EXPECT_TRUE(gpio.set(1, true));  // a write, not a change
  gpio.setNowNs(300);
  EXPECT_TRUE(gpio.set(2, false));
  EXPECT_TRUE(gpio.set(1, false));
  const std::vector<GpioEvent> expected = {{100, 1, false}, {100, 2, true}, {200, 1, true}, {300, 2, false}, {300, 1, false}};
  EXPECT_EQ(gpio.events(), expected);
  EXPECT_EQ(gpio.eventsOf(2), (std::vector<GpioEvent>{{100, 2, true}, {300, 2, false}}));
  bool v = true;
  ASSERT_TRUE(gpio.get(1, v));
  EXPECT_FALSE(v);
  EXPECT_EQ(gpio.counters().writes, 4u);
  EXPECT_EQ(gpio.counters().write_errors, 0u);
}

TEST(MockGpio, InputsReadWhatTheTestSets) {
  MockGpio gpio;
  ASSERT_TRUE(gpio.requestInput(5, "fovea-privacy").isOk());
  bool v = true;
  ASSERT_TRUE(gpio.get(5, v));
  EXPECT_FALSE(v);
  gpio.setInput(5, true);
  ASSERT_TRUE(gpio.get(5, v));
  EXPECT_TRUE(v);
  EXPECT_FALSE(gpio.set(5, false));  // an input cannot be driven
  EXPECT_EQ(gpio.counters().write_errors, 1u);
  EXPECT_TRUE(gpio.events().empty());
}

TEST(MockGpio, RequestErrorsNameTheChipAndTheLine) {
  MockGpio gpio(8);
  Status missing = gpio.requestOutput(8, "fovea-fault", false);
  EXPECT_EQ(missing.code(), ErrorCode::kNotFound);
  EXPECT_EQ(missing.message(), "gpio: line 8 (fovea-fault) not on mock (8 lines): lines are 0..7");
  ASSERT_TRUE(gpio.requestOutput(3, "fovea-heartbeat", false).isOk());
  Status twice = gpio.requestInput(3, "fovea-privacy");
  EXPECT_EQ(twice.code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(twice.message(), "gpio: line 3 (fovea-privacy) of mock (8 lines) requested twice (already by 'fovea-heartbeat')");
  bool v = false;
  EXPECT_FALSE(gpio.get(4, v));  // not requested
  EXPECT_FALSE(gpio.set(4, true));
  EXPECT_EQ(gpio.counters().read_errors, 1u);
  EXPECT_EQ(gpio.counters().write_errors, 1u);
  gpio.releaseAll();
  EXPECT_FALSE(gpio.isRequested(3));
  EXPECT_TRUE(gpio.requestInput(3, "fovea-privacy").isOk());
}

TEST(MockGpio, InjectedFailuresAreCounted) {
  MockGpio gpio;
  ASSERT_TRUE(gpio.requestOutput(0, "x", false).isOk());
  gpio.failWrites(true);
  EXPECT_FALSE(gpio.set(0, true));
  EXPECT_FALSE(gpio.value(0));
  gpio.failWrites(false);
  gpio.failReads(true);
  bool v = false;
  EXPECT_FALSE(gpio.get(0, v));
  EXPECT_EQ(gpio.counters().write_errors, 1u);
  EXPECT_EQ(gpio.counters().read_errors, 1u);
}

#ifdef FOVEA_HAVE_GPIOD

TEST(GpiodGpio, AMissingChipGivesAClearErrorNamingIt) {
  // gpiochip97 exists nowhere: on this host (no GPIO at all) and on a board.
  auto gpio = createGpio("gpiod:gpiochip97");
  ASSERT_FALSE(gpio.isOk());
  EXPECT_EQ(gpio.status().code(), ErrorCode::kNotFound);
  const std::string& m = gpio.status().message();
  EXPECT_THAT(m, HasSubstr("gpio: cannot open GPIO chip 'gpiochip97' ("));
  if (gpiod::listGpioChips().empty()) {
    EXPECT_THAT(m, HasSubstr("this machine has no GPIO character device (/dev/gpiochip*)"));
  } else {
    EXPECT_THAT(m, HasSubstr("present: /dev/gpiochip"));
  }
  EXPECT_THAT(m, HasSubstr("set the board profile's gpio chip, or use the mock backend"));
  auto empty = createGpio("gpiod:");
  ASSERT_FALSE(empty.isOk());
  EXPECT_EQ(empty.status().message(), "gpio: gpiod: no chip given; use gpiod:CHIP, e.g. gpiod:gpiochip0");
}

// On real lines: FOVEA_TEST_GPIO_CHIP (default gpiochip0) and FOVEA_TEST_GPIO_LINE
// (default 0) must be a free line that can be driven (the PL061's in the VM).
TEST(GpiodGpio, RealLineRequestSetAndReadBack) {
  if (gpiod::listGpioChips().empty()) GTEST_SKIP() << "no /dev/gpiochip* on this machine";
  const char* chip_env = std::getenv("FOVEA_TEST_GPIO_CHIP");
  const char* line_env = std::getenv("FOVEA_TEST_GPIO_LINE");
  const std::string chip = chip_env ? chip_env : "gpiochip0";
  const unsigned line = line_env ? static_cast<unsigned>(std::atoi(line_env)) : 0u;
  auto created = createGpio("gpiod:" + chip);
  ASSERT_TRUE(created.isOk()) << created.status().toString();
  Gpio& gpio = **created;
  ASSERT_LT(line, gpio.lineCount()) << gpio.name();
  Status requested = gpio.requestOutput(line, "fovea-test", false);
  ASSERT_TRUE(requested.isOk()) << requested.toString();
  for (bool value : {true, false, true, false}) {
    ASSERT_TRUE(gpio.set(line, value));
    bool read = !value;
    ASSERT_TRUE(gpio.get(line, read));
    EXPECT_EQ(read, value);
  }
  Status twice = gpio.requestOutput(line, "fovea-test-2", false);
  EXPECT_EQ(twice.code(), ErrorCode::kInvalidArgument);
  Status missing = gpio.requestOutput(gpio.lineCount(), "fovea-test", false);
  EXPECT_EQ(missing.code(), ErrorCode::kNotFound);
  EXPECT_THAT(missing.message(), HasSubstr("gpio: line " + std::to_string(gpio.lineCount()) + " of gpiod:"));
  EXPECT_THAT(missing.message(), HasSubstr("no such line"));
  gpio.releaseAll();
  EXPECT_EQ(gpio.counters().write_errors, 0u);
}

// FOVEA_TEST_GPIO_BUSY_LINE: a line another driver holds (in the VM, line 3,
// which gpio-keys takes for the power button): the error says who has it.
TEST(GpiodGpio, ABusyLineSaysWhoHoldsIt) {
  const char* busy_env = std::getenv("FOVEA_TEST_GPIO_BUSY_LINE");
  if (gpiod::listGpioChips().empty() || busy_env == nullptr) {
    GTEST_SKIP() << "needs a chip and FOVEA_TEST_GPIO_BUSY_LINE";
  }
  const char* chip_env = std::getenv("FOVEA_TEST_GPIO_CHIP");
  auto created = createGpio(std::string("gpiod:") + (chip_env ? chip_env : "gpiochip0"));
  ASSERT_TRUE(created.isOk()) << created.status().toString();
  const unsigned line = static_cast<unsigned>(std::atoi(busy_env));
  Status busy = (*created)->requestOutput(line, "fovea-test", false);
  EXPECT_EQ(busy.code(), ErrorCode::kUnavailable) << busy.toString();
  EXPECT_THAT(busy.message(), HasSubstr("gpio: line " + std::to_string(line) + " of gpiod:"));
  EXPECT_THAT(busy.message(), HasSubstr(": busy, already used by '"));
  std::printf("busy line: %s\n", busy.message().c_str());
}

#endif  // FOVEA_HAVE_GPIOD

}  // namespace
}  // namespace fovea::hal
