// The status-GPIO interface: a few output lines (heartbeat, streaming, fault)
// and optional input lines (a privacy switch) on one GPIO chip, by line offset.
// Backends: "mock" (records every change, for host tests) and "gpiod:CHIP"
// (libgpiod v1, when built with FOVEA_HAVE_GPIOD). Requests happen at start-up
// and return a Status naming the chip and line; set() and get() run on the
// service's status path, return false on failure (counted) and never allocate.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"

namespace fovea::hal {

struct GpioCounters {
  uint64_t writes = 0;        // set() calls that reached the line
  uint64_t write_errors = 0;  // set() calls that failed
  uint64_t read_errors = 0;   // get() calls that failed
};

// Bumped on the thread that drives the lines, read by the supervisor.
class GpioCounterSet {
 public:
  void write() { writes_.fetch_add(1, std::memory_order_relaxed); }
  void writeError() { write_errors_.fetch_add(1, std::memory_order_relaxed); }
  void readError() { read_errors_.fetch_add(1, std::memory_order_relaxed); }
  GpioCounters snapshot() const {
    GpioCounters c;
    c.writes = writes_.load(std::memory_order_relaxed);
    c.write_errors = write_errors_.load(std::memory_order_relaxed);
    c.read_errors = read_errors_.load(std::memory_order_relaxed);
    return c;
  }

 private:
  std::atomic<uint64_t> writes_{0};
  std::atomic<uint64_t> write_errors_{0};
  std::atomic<uint64_t> read_errors_{0};
};

class Gpio {
 public:
  virtual ~Gpio() = default;

  // e.g. "gpiod:gpiochip0 (pl061, 8 lines)" or "mock (8 lines)".
  virtual const std::string& name() const = 0;
  virtual unsigned lineCount() const = 0;

  // Start-up, may allocate. The consumer name shows in `gpioinfo`. Errors name
  // the chip and the line: kNotFound for a line the chip lacks, kUnavailable
  // for a line already in use, kInvalidArgument for a line requested twice.
  virtual Status requestOutput(unsigned offset, std::string_view consumer, bool initial_value) = 0;
  virtual Status requestInput(unsigned offset, std::string_view consumer) = 0;

  // Drives a requested output line. False (counted) when the line is not a
  // requested output or the write failed.
  [[nodiscard]] virtual bool set(unsigned offset, bool value) = 0;
  // Reads a requested line (an output reads back its value). False (counted)
  // when the line is not requested or the read failed.
  [[nodiscard]] virtual bool get(unsigned offset, bool& value) = 0;

  // Gives every requested line back (also done by the destructor).
  virtual void releaseAll() = 0;

  virtual GpioCounters counters() const = 0;
};

// Creates a GPIO chip from a spec: "mock[:lines=N]" or "gpiod:CHIP" (CHIP as
// gpiod_chip_open_lookup() takes it: "gpiochip0", "/dev/gpiochip0", a label or
// a number). The backends compiled in are listed in one table in gpio.cpp.
Result<std::unique_ptr<Gpio>> createGpio(std::string_view spec);

// One line per backend, for --help.
std::string gpioSpecHelp();

// The names of the backends compiled in ("mock", "gpiod"), in table order.
std::vector<std::string_view> gpioBackendNames();

}  // namespace fovea::hal
