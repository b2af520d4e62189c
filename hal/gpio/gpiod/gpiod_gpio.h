// GPIO lines through libgpiod's v1 C API (Debian 12: 1.6.3), spec "gpiod:CHIP".
// probe() opens the chip and says clearly when it is absent (naming the chip and
// the GPIO character devices that do exist); requests name the chip and line.
#pragma once

#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "hal/gpio.h"

struct gpiod_chip;
struct gpiod_line;

namespace fovea::hal::gpiod {

class GpiodGpio final : public Gpio {
 public:
  // Opens the chip; kNotFound with the chip's name when it is missing.
  static Result<std::unique_ptr<Gpio>> probe(std::string_view chip);
  // args: the spec after "gpiod:".
  static Result<std::unique_ptr<Gpio>> create(std::string_view args) { return probe(args); }
  ~GpiodGpio() override;

  const std::string& name() const override { return name_; }
  unsigned lineCount() const override { return static_cast<unsigned>(lines_.size()); }
  Status requestOutput(unsigned offset, std::string_view consumer, bool initial_value) override;
  Status requestInput(unsigned offset, std::string_view consumer) override;
  [[nodiscard]] bool set(unsigned offset, bool value) override;
  [[nodiscard]] bool get(unsigned offset, bool& value) override;
  void releaseAll() override;
  GpioCounters counters() const override { return counters_.snapshot(); }

 private:
  enum class Mode { kFree, kOutput, kInput };
  struct Line {
    gpiod_line* handle = nullptr;
    Mode mode = Mode::kFree;
  };
  GpiodGpio(gpiod_chip* chip, std::string chip_name, std::string name, unsigned line_count);
  Status request(unsigned offset, std::string_view consumer, Mode mode, bool initial_value);

  gpiod_chip* chip_;
  std::string chip_name_;  // as the user gave it, for messages
  std::string name_;
  std::vector<Line> lines_;
  GpioCounterSet counters_;
};

std::string gpiodGpioHelp();

// The GPIO character devices present ("/dev/gpiochip0 /dev/gpiochip1"), or "".
std::string listGpioChips();

}  // namespace fovea::hal::gpiod
