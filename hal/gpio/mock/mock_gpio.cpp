#include "hal/gpio/mock/mock_gpio.h"

#include <charconv>

namespace fovea::hal::mock {

MockGpio::MockGpio(unsigned line_count)
    : name_("mock (" + std::to_string(line_count) + " lines)"), lines_(line_count) {
  events_.reserve(1024);
}

Result<std::unique_ptr<Gpio>> MockGpio::create(std::string_view args) {
  unsigned lines = 8;
  if (!args.empty()) {
    constexpr std::string_view kKey = "lines=";
    const bool keyed = args.substr(0, kKey.size()) == kKey;
    const std::string_view number = keyed ? args.substr(kKey.size()) : std::string_view();
    const auto [end, ec] = std::from_chars(number.data(), number.data() + number.size(), lines);
    if (!keyed || ec != std::errc() || end != number.data() + number.size() || lines == 0 || lines > 512) {
      return Result<std::unique_ptr<Gpio>>(
          ErrorCode::kInvalidArgument,
          "gpio: mock: bad option '" + std::string(args) + "'; accepted: lines=N (1..512)");
    }
  }
  return std::unique_ptr<Gpio>(new MockGpio(lines));
}

Status MockGpio::checkRequest(unsigned offset, std::string_view what) const {
  if (offset >= lines_.size()) {
    return {ErrorCode::kNotFound, "gpio: line " + std::to_string(offset) + " (" + std::string(what) +
                                      ") not on " + name_ + ": lines are 0.." +
                                      std::to_string(lines_.size() - 1)};
  }
  if (lines_[offset].mode != Mode::kFree) {
    return {ErrorCode::kInvalidArgument, "gpio: line " + std::to_string(offset) + " (" + std::string(what) +
                                             ") of " + name_ + " requested twice (already by '" +
                                             lines_[offset].consumer + "')"};
  }
  return Status::ok();
}

Status MockGpio::requestOutput(unsigned offset, std::string_view consumer, bool initial_value) {
  if (Status s = checkRequest(offset, consumer); !s) return s;
  Line& line = lines_[offset];
  line.mode = Mode::kOutput;
  line.value = initial_value;
  line.consumer = std::string(consumer);
  events_.push_back({now_ns_, offset, initial_value});
  return Status::ok();
}

Status MockGpio::requestInput(unsigned offset, std::string_view consumer) {
  if (Status s = checkRequest(offset, consumer); !s) return s;
  Line& line = lines_[offset];
  line.mode = Mode::kInput;
  line.consumer = std::string(consumer);
  return Status::ok();
}

bool MockGpio::set(unsigned offset, bool value) {
  if (fail_writes_ || offset >= lines_.size() || lines_[offset].mode != Mode::kOutput) {
    counters_.writeError();
    return false;
  }
  counters_.write();
  Line& line = lines_[offset];
  if (line.value != value) {
    line.value = value;
    events_.push_back({now_ns_, offset, value});
  }
  return true;
}

bool MockGpio::get(unsigned offset, bool& value) {
  if (fail_reads_ || offset >= lines_.size() || lines_[offset].mode == Mode::kFree) {
    counters_.readError();
    return false;
  }
  value = lines_[offset].value;
  return true;
}

void MockGpio::releaseAll() {
  for (Line& line : lines_) {
    line.mode = Mode::kFree;
    line.consumer.clear();
  }
}

void MockGpio::setInput(unsigned offset, bool value) {
  if (offset < lines_.size() && lines_[offset].mode != Mode::kOutput) lines_[offset].value = value;
}

std::vector<GpioEvent> MockGpio::eventsOf(unsigned offset) const {
  std::vector<GpioEvent> out;
  for (const GpioEvent& e : events_) {
    if (e.offset == offset) out.push_back(e);
  }
  return out;
}

bool MockGpio::isRequested(unsigned offset) const {
  return offset < lines_.size() && lines_[offset].mode != Mode::kFree;
}

bool MockGpio::isOutput(unsigned offset) const {
  return offset < lines_.size() && lines_[offset].mode == Mode::kOutput;
}

bool MockGpio::value(unsigned offset) const {
  return offset < lines_.size() && lines_[offset].mode != Mode::kFree && lines_[offset].value;
}

std::string MockGpio::consumer(unsigned offset) const {
  return offset < lines_.size() ? lines_[offset].consumer : std::string();
}

std::string mockGpioHelp() {
  return "mock[:lines=N]     in-memory GPIO chip (8 lines by default) that records every line change";
}

}  // namespace fovea::hal::mock
