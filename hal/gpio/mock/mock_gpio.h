// The mock GPIO chip: an ordinary backend ("mock[:lines=N]", 8 lines by
// default) that keeps every line's value in memory and records each change with
// a timestamp, so host tests can assert exact heartbeat, streaming, fault and
// privacy sequences. Tests set input values and the clock (setNowNs) themselves,
// and can make writes and reads fail. Requests enforce what a real chip does: a
// line the chip lacks, a line requested twice, set() on an input are errors.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "hal/gpio.h"

namespace fovea::hal::mock {

struct GpioEvent {
  int64_t stamp_ns = 0;
  unsigned offset = 0;
  bool value = false;
  bool operator==(const GpioEvent&) const = default;
};

class MockGpio final : public Gpio {
 public:
  explicit MockGpio(unsigned line_count = 8);

  // args: "" or "lines=N".
  static Result<std::unique_ptr<Gpio>> create(std::string_view args);

  const std::string& name() const override { return name_; }
  unsigned lineCount() const override { return static_cast<unsigned>(lines_.size()); }
  Status requestOutput(unsigned offset, std::string_view consumer, bool initial_value) override;
  Status requestInput(unsigned offset, std::string_view consumer) override;
  [[nodiscard]] bool set(unsigned offset, bool value) override;
  [[nodiscard]] bool get(unsigned offset, bool& value) override;
  void releaseAll() override;
  GpioCounters counters() const override { return counters_.snapshot(); }

  // ---- for tests ----
  // The time stamped on the following changes (0 until set).
  void setNowNs(int64_t now_ns) { now_ns_ = now_ns; }
  // The value an input line reads (any line; outputs ignore it).
  void setInput(unsigned offset, bool value);
  // Make every following set() / get() fail (as a disconnected expander would).
  void failWrites(bool fail) { fail_writes_ = fail; }
  void failReads(bool fail) { fail_reads_ = fail; }
  // Changes of output lines in order: the initial value when requested, then
  // each set() that changed the value (a set() to the same value is a write,
  // counted, but not a change).
  const std::vector<GpioEvent>& events() const { return events_; }
  std::vector<GpioEvent> eventsOf(unsigned offset) const;
  void clearEvents() { events_.clear(); }
  bool isRequested(unsigned offset) const;
  bool isOutput(unsigned offset) const;
  // The output's current value (false when not requested).
  bool value(unsigned offset) const;
  std::string consumer(unsigned offset) const;

 private:
  enum class Mode { kFree, kOutput, kInput };
  struct Line {
    Mode mode = Mode::kFree;
    bool value = false;  // output: driven; input: what setInput() gave
    std::string consumer;
  };
  Status checkRequest(unsigned offset, std::string_view what) const;

  std::string name_;
  std::vector<Line> lines_;
  std::vector<GpioEvent> events_;
  int64_t now_ns_ = 0;
  bool fail_writes_ = false;
  bool fail_reads_ = false;
  GpioCounterSet counters_;
};

std::string mockGpioHelp();

}  // namespace fovea::hal::mock
