#include "firmware/status_lines.h"

#include <string>
#include <utility>

namespace fovea::firmware {

Status StatusLinesConfig::validate(unsigned line_count) const {
  const std::pair<const char*, int> lines[] = {
      {"heartbeat_line", heartbeat_line},
      {"streaming_line", streaming_line},
      {"fault_line", fault_line},
      {"privacy_line", privacy_line},
  };
  for (std::size_t i = 0; i < std::size(lines); ++i) {
    const auto& [field, line] = lines[i];
    if (line == kNoLine) continue;
    if (line < 0 || static_cast<unsigned>(line) >= line_count) {
      return {ErrorCode::kInvalidArgument, std::string("gpio.") + field + " = " + std::to_string(line) +
                                               ": out of range, the chip has lines 0.." +
                                               std::to_string(line_count == 0 ? 0 : line_count - 1) + " (or -1 for none)"};
    }
    for (std::size_t j = 0; j < i; ++j) {
      if (lines[j].second == line) {
        return {ErrorCode::kInvalidArgument, std::string("gpio.") + field + " = " + std::to_string(line) +
                                                 ": the same line as gpio." + lines[j].first};
      }
    }
  }
  if (heartbeat_period_ns <= 0) {
    return {ErrorCode::kInvalidArgument, "gpio.heartbeat_period: must be positive, got " +
                                             std::to_string(heartbeat_period_ns) + " ns"};
  }
  return Status::ok();
}

StatusLines::StatusLines(hal::Gpio& gpio, StatusLinesConfig config)
    : gpio_(gpio),
      config_(std::move(config)),
      lines_{config_.heartbeat_line, config_.streaming_line, config_.fault_line} {}

StatusLines::~StatusLines() { stop(); }

Status StatusLines::start() {
  if (Status s = config_.validate(gpio_.lineCount()); !s) return s;
  for (int i = 0; i < kOutputCount; ++i) {
    if (lines_[i] == StatusLinesConfig::kNoLine) continue;
    if (Status s = gpio_.requestOutput(static_cast<unsigned>(lines_[i]), config_.consumer, false); !s) {
      gpio_.releaseAll();
      return s;
    }
    written_[i] = 0;
  }
  if (config_.privacy_line != StatusLinesConfig::kNoLine) {
    if (Status s = gpio_.requestInput(static_cast<unsigned>(config_.privacy_line), config_.consumer); !s) {
      gpio_.releaseAll();
      return s;
    }
  }
  started_ = true;
  was_healthy_ = false;
  state_ = StatusState{};
  return Status::ok();
}

void StatusLines::drive(Output output, bool level) {
  if (lines_[output] == StatusLinesConfig::kNoLine || written_[output] == static_cast<int>(level)) return;
  if (gpio_.set(static_cast<unsigned>(lines_[output]), level)) {
    written_[output] = level ? 1 : 0;
  } else {
    written_[output] = -1;
    ++counters_.write_errors;
  }
}

const StatusState& StatusLines::update(const StatusInputs& inputs, int64_t now_ns) {
  if (!started_) return state_;

  // Privacy first: it decides the streaming line.
  bool privacy = false;
  if (config_.privacy_line != StatusLinesConfig::kNoLine) {
    bool level = false;
    if (gpio_.get(static_cast<unsigned>(config_.privacy_line), level)) {
      privacy = level != config_.privacy_active_low;
    } else {
      ++counters_.read_errors;
      privacy = true;  // fail safe
    }
  }
  if (privacy && !state_.privacy_active) ++counters_.privacy_pauses;
  state_.privacy_active = privacy;
  state_.stream_allowed = !privacy;

  if (inputs.healthy) {
    if (!was_healthy_ || now_ns >= next_toggle_ns_) {
      // On time: keep the phase. Late by a whole period or more, or just
      // healthy again: restart the phase from now.
      const bool on_time = was_healthy_ && now_ns - next_toggle_ns_ < config_.heartbeat_period_ns;
      next_toggle_ns_ = (on_time ? next_toggle_ns_ : now_ns) + config_.heartbeat_period_ns;
      state_.heartbeat = !state_.heartbeat;
      ++counters_.heartbeat_toggles;
    }
  }
  was_healthy_ = inputs.healthy;

  state_.streaming = inputs.operator_connected && inputs.gaze_fresh && !privacy;
  state_.fault = inputs.fault;

  drive(kHeartbeat, state_.heartbeat);
  drive(kStreaming, state_.streaming);
  drive(kFault, state_.fault);
  return state_;
}

void StatusLines::stop() {
  if (!started_) return;
  state_.heartbeat = state_.streaming = state_.fault = false;
  drive(kHeartbeat, false);
  drive(kStreaming, false);
  drive(kFault, false);
  gpio_.releaseAll();
  started_ = false;
}

}  // namespace fovea::firmware
