// Capture with retries: what the capture stage does when the camera stops
// delivering. No threads and no clock inside: the caller passes the time to
// step(), so tests drive it with a fake clock and run instantly.
//
// Each step() does at most one thing:
//  - before the time the last failure scheduled: nothing (kWait, next_ns says when);
//  - a reopen is pending: stop(), open(), start() (kReopened, or kReopenFailed);
//  - otherwise: acquire() into the caller's slot (kFrame, or kAcquireFailed).
// Every failure (acquire or reopen) schedules the next attempt at now_ns +
// backoff, the backoff starting at initial_backoff_ns and doubling up to
// max_backoff_ns; a frame resets it. A reopen becomes pending on kNotFound (the
// device went away) or after reopen_after_failures consecutive failed acquires
// (timeouts, malformed frames); a successful reopen restarts that count but not
// the backoff, so a camera that stays silent is reopened ever less often.
// A reopen that follows a stall (consecutive failed acquires, not a kNotFound
// disconnect) first resets the device on its bus, between stop() and open():
// camera.resetDevice() (a USB port reset for USB cameras), once per reopen a
// stall triggers (retries of a failed reopen do not reset again); a reset that
// fails or is unsupported is counted and the reopen goes ahead.
// Delays count from the now_ns of the step that failed (acquire() may itself
// block up to acquire_timeout).
//
// State: kOk until an attempt fails, then kFailing (the fault flag) until a frame
// arrives; each step reports the change it made (kFailing, kRecovered) for the
// log. step() never allocates (the camera's own error paths aside).
#pragma once

#include <chrono>
#include <cstdint>

#include "core/result.h"
#include "hal/camera.h"
#include "hal/frame.h"

namespace fovea::hal {

struct CaptureRetryConfig {
  std::chrono::nanoseconds acquire_timeout = std::chrono::milliseconds(100);
  int64_t initial_backoff_ns = 10'000'000;   // 10 ms
  int64_t max_backoff_ns = 1'000'000'000;    // 1 s
  int reopen_after_failures = 10;            // consecutive failed acquires
  // kInvalidArgument naming the field when a value is out of range.
  Status validate() const;
};

enum class CaptureAction : uint8_t {
  kFrame,          // acquire() filled the slot
  kWait,           // nothing done before next_ns
  kAcquireFailed,  // acquire() failed with `error`; next attempt at next_ns
  kReopened,       // stop + open + start succeeded; the next step acquires
  kReopenFailed,   // open() or start() failed with `error`; next attempt at next_ns
};

enum class CaptureState : uint8_t { kOk, kFailing };

enum class CaptureEvent : uint8_t {
  kNone,
  kFailing,    // ok -> failing: the first failure after frames (or at start)
  kRecovered,  // failing -> ok: a frame after failures
};

const char* captureActionName(CaptureAction action);
const char* captureEventName(CaptureEvent event);

struct CaptureStep {
  CaptureAction action = CaptureAction::kWait;
  CaptureEvent event = CaptureEvent::kNone;
  ErrorCode error = ErrorCode::kOk;  // kAcquireFailed, kReopenFailed
  int64_t next_ns = 0;               // step() does nothing before this
};

struct CaptureRetryStats {
  uint64_t frames = 0;
  uint64_t acquire_failures = 0;  // all failed acquires, of which:
  uint64_t timeouts = 0;          //   kUnavailable
  uint64_t rejected_frames = 0;   //   kInvalidInput (malformed frame)
  uint64_t disconnects = 0;       //   kNotFound
  uint64_t reopen_attempts = 0;
  uint64_t reopens = 0;           // attempts that succeeded
  uint64_t reset_attempts = 0;    // resetDevice() before a reopen after a stall, of which:
  uint64_t resets = 0;            //   succeeded
  uint64_t resets_unsupported = 0;  //   kUnavailable: the camera has no reset
  uint64_t resets_vanished = 0;   //   kNotFound: the device re-enumerated or went away
  uint64_t reset_failures = 0;    //   any other error
  uint64_t recoveries = 0;        // failing -> ok
};

class CaptureRetry {
 public:
  // The camera is the caller's, already opened and started (or not: the first
  // failures then lead to a reopen). config should have passed validate().
  explicit CaptureRetry(Camera& camera, const CaptureRetryConfig& config = {});

  CaptureStep step(int64_t now_ns, RgbdFrame& slot);

  // The fault flag: up from the first failure until a frame arrives.
  bool faulted() const { return state_ == CaptureState::kFailing; }
  CaptureState state() const { return state_; }
  int consecutiveFailures() const { return consecutive_failures_; }
  bool reopenPending() const { return reopen_pending_; }
  // The pending reopen follows a stall: it resets the device first.
  bool resetPending() const { return reset_pending_; }
  // The delay the next failure will schedule.
  int64_t backoffNs() const { return backoff_ns_; }
  int64_t nextNs() const { return next_ns_; }
  const CaptureRetryStats& stats() const { return stats_; }
  const CaptureRetryConfig& config() const { return config_; }

 private:
  CaptureStep fail(int64_t now_ns, CaptureAction action, ErrorCode error);

  Camera& camera_;
  CaptureRetryConfig config_;
  CaptureState state_ = CaptureState::kOk;
  int consecutive_failures_ = 0;
  bool reopen_pending_ = false;
  bool reset_pending_ = false;
  int64_t backoff_ns_;
  int64_t next_ns_ = INT64_MIN;
  CaptureRetryStats stats_;
};

}  // namespace fovea::hal
