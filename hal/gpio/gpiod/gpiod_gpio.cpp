#include "hal/gpio/gpiod/gpiod_gpio.h"

#include <gpiod.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>

namespace fovea::hal::gpiod {

std::string listGpioChips() {
  std::vector<std::string> chips;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/dev", ec)) {
    const std::string file = entry.path().filename().string();
    if (file.rfind("gpiochip", 0) == 0) chips.push_back(entry.path().string());
  }
  std::sort(chips.begin(), chips.end());
  std::string list;
  for (const std::string& chip : chips) {
    if (!list.empty()) list += ' ';
    list += chip;
  }
  return list;
}

Result<std::unique_ptr<Gpio>> GpiodGpio::probe(std::string_view chip_name) {
  if (chip_name.empty()) {
    return Result<std::unique_ptr<Gpio>>(ErrorCode::kInvalidArgument,
                                         "gpio: gpiod: no chip given; use gpiod:CHIP, e.g. gpiod:gpiochip0");
  }
  const std::string chip_string(chip_name);
  errno = 0;
  gpiod_chip* chip = gpiod_chip_open_lookup(chip_string.c_str());
  if (chip == nullptr) {
    const int error = errno != 0 ? errno : ENOENT;
    const std::string present = listGpioChips();
    return Result<std::unique_ptr<Gpio>>(
        ErrorCode::kNotFound,
        "gpio: cannot open GPIO chip '" + chip_string + "' (" + std::strerror(error) + "); " +
            (present.empty() ? std::string("this machine has no GPIO character device (/dev/gpiochip*)")
                             : "present: " + present) +
            "; set the board profile's gpio chip, or use the mock backend (spec 'mock')");
  }
  const unsigned count = gpiod_chip_num_lines(chip);
  const char* label = gpiod_chip_label(chip);
  const char* kernel_name = gpiod_chip_name(chip);
  std::string name = "gpiod:" + std::string(kernel_name ? kernel_name : chip_string.c_str()) + " (" +
                     (label ? label : "?") + ", " + std::to_string(count) + " lines)";
  return std::unique_ptr<Gpio>(new GpiodGpio(chip, chip_string, std::move(name), count));
}

GpiodGpio::GpiodGpio(gpiod_chip* chip, std::string chip_name, std::string name, unsigned line_count)
    : chip_(chip), chip_name_(std::move(chip_name)), name_(std::move(name)), lines_(line_count) {}

GpiodGpio::~GpiodGpio() {
  releaseAll();
  gpiod_chip_close(chip_);
}

Status GpiodGpio::request(unsigned offset, std::string_view consumer, Mode mode, bool initial_value) {
  const std::string where = "gpio: line " + std::to_string(offset) + " of " + name_;
  if (offset >= lines_.size()) {
    return {ErrorCode::kNotFound, where + ": no such line (lines are 0.." +
                                      std::to_string(lines_.empty() ? 0 : lines_.size() - 1) +
                                      "); check the board profile's line numbers"};
  }
  Line& line = lines_[offset];
  if (line.mode != Mode::kFree) {
    return {ErrorCode::kInvalidArgument, where + ": requested twice (for '" + std::string(consumer) + "')"};
  }
  gpiod_line* handle = gpiod_chip_get_line(chip_, offset);
  if (handle == nullptr) {
    return {ErrorCode::kNotFound, where + ": " + std::strerror(errno)};
  }
  const std::string consumer_string(consumer);
  const int rc = mode == Mode::kOutput
                     ? gpiod_line_request_output(handle, consumer_string.c_str(), initial_value ? 1 : 0)
                     : gpiod_line_request_input(handle, consumer_string.c_str());
  if (rc < 0) {
    const int error = errno;
    if (error == EBUSY) {
      gpiod_line_update(handle);
      const char* owner = gpiod_line_consumer(handle);
      return {ErrorCode::kUnavailable,
              where + ": busy, already used by '" + std::string(owner ? owner : "another process") + "'"};
    }
    return {ErrorCode::kIoError, where + ": cannot request it as " +
                                     (mode == Mode::kOutput ? "output" : "input") + " for '" + consumer_string +
                                     "': " + std::strerror(error)};
  }
  line.handle = handle;
  line.mode = mode;
  return Status::ok();
}

Status GpiodGpio::requestOutput(unsigned offset, std::string_view consumer, bool initial_value) {
  return request(offset, consumer, Mode::kOutput, initial_value);
}

Status GpiodGpio::requestInput(unsigned offset, std::string_view consumer) {
  return request(offset, consumer, Mode::kInput, false);
}

bool GpiodGpio::set(unsigned offset, bool value) {
  if (offset >= lines_.size() || lines_[offset].mode != Mode::kOutput ||
      gpiod_line_set_value(lines_[offset].handle, value ? 1 : 0) < 0) {
    counters_.writeError();
    return false;
  }
  counters_.write();
  return true;
}

bool GpiodGpio::get(unsigned offset, bool& value) {
  if (offset >= lines_.size() || lines_[offset].mode == Mode::kFree) {
    counters_.readError();
    return false;
  }
  const int v = gpiod_line_get_value(lines_[offset].handle);
  if (v < 0) {
    counters_.readError();
    return false;
  }
  value = v != 0;
  return true;
}

void GpiodGpio::releaseAll() {
  for (Line& line : lines_) {
    if (line.mode != Mode::kFree) gpiod_line_release(line.handle);
    line = Line{};
  }
}

std::string gpiodGpioHelp() {
  return "gpiod:CHIP         a GPIO chip through libgpiod v1 (CHIP: gpiochip0, /dev/gpiochip0, a label or a number)";
}

}  // namespace fovea::hal::gpiod
