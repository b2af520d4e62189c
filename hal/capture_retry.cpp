#include "hal/capture_retry.h"

#include <algorithm>
#include <string>

namespace fovea::hal {

Status CaptureRetryConfig::validate() const {
  const auto bad = [](const char* what) {
    return Status(ErrorCode::kInvalidArgument, std::string("capture retry: ") + what);
  };
  if (acquire_timeout.count() < 0) return bad("acquire_timeout must not be negative");
  if (initial_backoff_ns <= 0) return bad("initial_backoff_ns must be positive");
  if (max_backoff_ns < initial_backoff_ns) {
    return bad("max_backoff_ns must be at least initial_backoff_ns");
  }
  if (reopen_after_failures < 1) return bad("reopen_after_failures must be at least 1");
  return Status::ok();
}

const char* captureActionName(CaptureAction action) {
  switch (action) {
    case CaptureAction::kFrame: return "frame";
    case CaptureAction::kWait: return "wait";
    case CaptureAction::kAcquireFailed: return "acquire-failed";
    case CaptureAction::kReopened: return "reopened";
    case CaptureAction::kReopenFailed: return "reopen-failed";
  }
  return "?";
}

const char* captureEventName(CaptureEvent event) {
  switch (event) {
    case CaptureEvent::kNone: return "none";
    case CaptureEvent::kFailing: return "failing";
    case CaptureEvent::kRecovered: return "recovered";
  }
  return "?";
}

CaptureRetry::CaptureRetry(Camera& camera, const CaptureRetryConfig& config)
    : camera_(camera), config_(config), backoff_ns_(config.initial_backoff_ns) {}

CaptureStep CaptureRetry::step(int64_t now_ns, RgbdFrame& slot) {
  if (now_ns < next_ns_) return {CaptureAction::kWait, CaptureEvent::kNone, ErrorCode::kOk, next_ns_};

  if (reopen_pending_) {
    ++stats_.reopen_attempts;
    camera_.stop();
    if (reset_pending_) {
      // Once per stall-triggered reopen, after stop(): open() then finds the
      // device fresh, or (kNotFound) re-enumerated, which it handles like a
      // reconnect. Whatever the reset says, the reopen goes ahead.
      reset_pending_ = false;
      ++stats_.reset_attempts;
      const Status reset = camera_.resetDevice();
      switch (reset.code()) {
        case ErrorCode::kOk: ++stats_.resets; break;
        case ErrorCode::kUnavailable: ++stats_.resets_unsupported; break;
        case ErrorCode::kNotFound: ++stats_.resets_vanished; break;
        default: ++stats_.reset_failures; break;
      }
    }
    ErrorCode error = ErrorCode::kOk;
    if (Status s = camera_.open(); !s) {
      error = s.code();
    } else if (Status t = camera_.start(); !t) {
      error = t.code();
    }
    if (error != ErrorCode::kOk) return fail(now_ns, CaptureAction::kReopenFailed, error);
    reopen_pending_ = false;
    consecutive_failures_ = 0;
    ++stats_.reopens;
    next_ns_ = now_ns;
    return {CaptureAction::kReopened, CaptureEvent::kNone, ErrorCode::kOk, now_ns};
  }

  const Status status = camera_.acquire(slot, config_.acquire_timeout);
  if (status.isOk()) {
    ++stats_.frames;
    consecutive_failures_ = 0;
    backoff_ns_ = config_.initial_backoff_ns;
    next_ns_ = now_ns;
    CaptureEvent event = CaptureEvent::kNone;
    if (state_ == CaptureState::kFailing) {
      state_ = CaptureState::kOk;
      ++stats_.recoveries;
      event = CaptureEvent::kRecovered;
    }
    return {CaptureAction::kFrame, event, ErrorCode::kOk, now_ns};
  }
  ++stats_.acquire_failures;
  switch (status.code()) {
    case ErrorCode::kUnavailable: ++stats_.timeouts; break;
    case ErrorCode::kInvalidInput: ++stats_.rejected_frames; break;
    case ErrorCode::kNotFound: ++stats_.disconnects; break;
    default: break;
  }
  ++consecutive_failures_;
  if (status.code() == ErrorCode::kNotFound) {
    reopen_pending_ = true;
    reset_pending_ = false;  // gone: nothing on the bus to reset
  } else if (consecutive_failures_ >= config_.reopen_after_failures) {
    reopen_pending_ = true;
    reset_pending_ = true;  // a stall
  }
  return fail(now_ns, CaptureAction::kAcquireFailed, status.code());
}

CaptureStep CaptureRetry::fail(int64_t now_ns, CaptureAction action, ErrorCode error) {
  CaptureEvent event = CaptureEvent::kNone;
  if (state_ == CaptureState::kOk) {
    state_ = CaptureState::kFailing;
    event = CaptureEvent::kFailing;
  }
  next_ns_ = now_ns + backoff_ns_;
  backoff_ns_ = backoff_ns_ > config_.max_backoff_ns / 2 ? config_.max_backoff_ns : backoff_ns_ * 2;
  return {action, event, error, next_ns_};
}

}  // namespace fovea::hal
