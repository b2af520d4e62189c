// The service's status GPIO lines (issue 5), as logic driven by time passed in:
//  - heartbeat (output): toggles every heartbeat_period_ns while the pipeline is
//    healthy; holds its level (stops toggling) while it is not, so a stuck line
//    means a stuck pipeline whatever level it stuck at. The first healthy update
//    after start or after a stall toggles at once, then every period; an update
//    later than a whole period toggles once (no burst of catch-up toggles).
//  - streaming (output): on while an operator is connected with fresh gaze and
//    the privacy input is not active.
//  - fault (output): on while a fault stands.
//  - privacy (optional input, e.g. a switch): while active, streaming pauses
//    (update() says so, and the streaming line goes off). A failed read counts
//    as active: a privacy switch fails safe.
// Any line can be left out (kNoLine). A line is written only when its level
// changes; a failed write is counted and retried on the next update. update()
// never allocates.
#pragma once

#include <cstdint>
#include <string>

#include "core/result.h"
#include "hal/gpio.h"

namespace fovea::firmware {

struct StatusLinesConfig {
  static constexpr int kNoLine = -1;
  int heartbeat_line = kNoLine;
  int streaming_line = kNoLine;
  int fault_line = kNoLine;
  int privacy_line = kNoLine;       // input
  bool privacy_active_low = false;  // a switch to ground on a pulled-up line reads 0 when on
  int64_t heartbeat_period_ns = 500'000'000;
  std::string consumer = "fovead";  // shown by gpioinfo

  // Lines within 0..line_count-1 and distinct, period positive; the message
  // names the field.
  Status validate(unsigned line_count) const;
};

struct StatusInputs {
  bool healthy = false;             // the pipeline delivers frames (the supervisor decides)
  bool operator_connected = false;
  bool gaze_fresh = false;
  bool fault = false;               // a fault stands
};

struct StatusState {
  bool heartbeat = false;
  bool streaming = false;
  bool fault = false;
  bool privacy_active = false;
  bool stream_allowed = true;  // false while privacy is active: the send stage pauses
};

struct StatusLinesCounters {
  uint64_t write_errors = 0;
  uint64_t read_errors = 0;
  uint64_t heartbeat_toggles = 0;
  uint64_t privacy_pauses = 0;  // times privacy became active
};

class StatusLines {
 public:
  // Never fails; start() does the requests.
  StatusLines(hal::Gpio& gpio, StatusLinesConfig config);
  ~StatusLines();
  StatusLines(const StatusLines&) = delete;
  StatusLines& operator=(const StatusLines&) = delete;

  // Validates the configuration against the chip and requests the lines (all
  // outputs low). On error nothing stays requested.
  Status start();
  // Drives the lines for the state at now_ns. Call it often (each frame, or
  // every few milliseconds): the heartbeat is as precise as the calls.
  const StatusState& update(const StatusInputs& inputs, int64_t now_ns);
  // Drives the outputs low and gives the lines back (also the destructor's job).
  void stop();

  const StatusState& state() const { return state_; }
  StatusLinesCounters counters() const { return counters_; }

 private:
  enum Output { kHeartbeat, kStreaming, kFault, kOutputCount };
  void drive(Output output, bool level);

  hal::Gpio& gpio_;
  StatusLinesConfig config_;
  int lines_[kOutputCount];
  // What the line has (-1: unknown after a failed write, so it is written again).
  int written_[kOutputCount] = {-1, -1, -1};
  bool started_ = false;
  bool was_healthy_ = false;
  int64_t next_toggle_ns_ = 0;
  StatusState state_;
  StatusLinesCounters counters_;
};

}  // namespace fovea::firmware
